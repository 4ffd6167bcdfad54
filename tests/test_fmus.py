"""The three FMUs: clean fmpy validation, units on every real variable, and the same run in libcosim
(issue 2 acceptance 3)."""
import zipfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from fmpy.validation import validate_fmu

from conftest import load_run, pantohil
from pantohil.builder.system import CONNECTIONS


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmus")
    proc = pantohil("build", "--out", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return {p.stem: p for p in out.glob("*.fmu")}


def test_three_fmus_validate_clean(built):
    assert set(built) == {"catenary", "rig", "pantograph"}
    for path in built.values():
        assert validate_fmu(str(path)) == []


def test_every_real_variable_has_a_unit_and_a_description(built):
    for path in built.values():
        with zipfile.ZipFile(path) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
            assert "documentation/index.html" in z.namelist()
        units = {u.get("name") for u in root.iter("Unit")}
        for sv in root.iter("ScalarVariable"):
            assert sv.get("description")
            real = sv.find("Real")
            if real is not None:
                assert real.get("unit") in units, sv.get("name")


def test_libcosim_reproduces_the_fmpy_master(default_run):
    from pantohil.orchestrator.libcosim_master import run_libcosim

    summary, span = load_run(default_run)
    fmus = {Path(p).stem: Path(p) for p in summary["fmus"]}
    n = summary["samples_per_span"]
    out = run_libcosim(fmus, CONNECTIONS, summary["dt_s"], summary["spans"] * n,
                       {"catenary": {"delay_steps": summary["hil"]["delay_steps"]}},
                       [("catenary", "contact_force")], record_last=n)
    f_cosim = out[("catenary", "contact_force")]
    assert np.max(np.abs(f_cosim - span[:, 3])) <= 1e-6
