"""The masters' registry (orchestrator/masters.py): the built-in masters and their capabilities, the
command line's choices from it, an unknown name refused naming the key, and no switch on a master's name
outside it."""
from __future__ import annotations

import re
from pathlib import Path

import pytest
from conftest import package_lines_matching

from pantohil.models.errors import InputError
from pantohil.orchestrator.masters import DEFAULT_MASTER, MASTERS


def test_the_built_in_masters_and_what_they_can_do():
    assert MASTERS.builtin_names() == ("fmpy", "libcosim") and DEFAULT_MASTER == "fmpy"
    fmpy, libcosim = MASTERS.get("fmpy"), MASTERS.get("libcosim")
    assert fmpy.checkpoints and fmpy.model_paced_hardware and fmpy.replaced_by_inprocess and fmpy.requires is None
    assert not (libcosim.checkpoints or libcosim.model_paced_hardware or libcosim.replaced_by_inprocess)
    assert libcosim.requires == ("libcosimpy", "libcosim")


def test_an_unknown_master_is_refused_naming_the_key():
    with pytest.raises(InputError, match="master: 'gauss' is not a master") as err:
        MASTERS.get("gauss", "master")
    assert err.value.key == "master"


def test_no_switch_on_a_masters_name_outside_the_registry():
    switch = re.compile(r"""(==|!=|\bin)\s*\(?\s*["'](fmpy|libcosim)["']""")
    found = package_lines_matching(switch, Path("orchestrator", "masters.py"))
    assert not found, found
