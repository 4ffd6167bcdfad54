"""A case's typed sections (`Case.sections`, models/parameters.py `CaseSections`): every validated key as
an attribute of its frozen section, and no dictionary read of a case's values in the package."""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest
from conftest import package_lines_matching

from pantohil.models.case import load_case
from pantohil.models.parameters import SECTIONS


def test_every_key_of_every_section_is_an_attribute_of_its_typed_section():
    case = load_case("pfem_benchmark_250", ["run.max_spans=7", "second_pantograph.spacing_m=90"])
    for name, cls in SECTIONS.items():
        section = getattr(case.sections, name)
        assert isinstance(section, cls)
        for f in dataclasses.fields(cls):
            value = case.values[name][f.name]
            assert getattr(section, f.name) == (tuple(value) if isinstance(value, list) else value)
    assert case.sections.run.max_spans == 7
    assert load_case().sections.second_pantograph is None  # an optional section, absent
    with pytest.raises(dataclasses.FrozenInstanceError):
        case.sections.run.max_spans = 8


def test_the_package_reads_no_case_value_by_section_name():
    reads = re.compile(r"""\bcase\.values\[["']""")
    found = package_lines_matching(reads, Path("models", "parameters.py"))
    assert not found, found
