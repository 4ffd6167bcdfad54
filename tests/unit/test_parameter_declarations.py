"""One declaration per parameter: the FMU tables and the builder's mapping are derived from the case
keys' declarations (models/parameters.py), without building an FMU (the built model descriptions are
checked in tests/integration/test_declared_fmu_variables.py)."""
from __future__ import annotations

import importlib

import pytest

from pantohil.builder.fmu_parameters import fmu_parameters
from pantohil.models.case import SCHEMA, load_case
from pantohil.models.parameters import all_keys, fmu_keys, fmu_variable_names

FMUS = ("catenary", "pantograph", "rig", "adapter")


def _table(fmu: str) -> dict:
    return {v.name: v for v in importlib.import_module(f"pantohil.fmus.pantohil_{fmu}").VARIABLES}


@pytest.mark.parametrize("fmu", FMUS)
def test_every_declared_key_is_an_fmu_variable_of_its_unit_and_range(fmu):
    table = _table(fmu)
    for key in fmu_keys(fmu):
        for name in fmu_variable_names(key):
            var = table[name]
            assert var.causality == "parameter", name
            if var.kind == "real":
                assert (var.unit, var.min, var.max) == (key.param.unit, key.param.low, key.param.high), name
            assert var.description.startswith(key.param.description), name


@pytest.mark.parametrize("fmu", FMUS)
def test_the_builder_sets_exactly_the_fmu_parameters(fmu):
    params = fmu_parameters(load_case(None), 8)[fmu]
    assert set(params) == {n for n, v in _table(fmu).items() if v.causality == "parameter"}


def test_case_values_reach_the_fmus_by_name():
    case = load_case(None, ["rig.servo_bandwidth_hz=40", "hil.update=\"span\"", "pantograph.model=\"rigid_mass\"",
                            "pantograph.masses_kg=[5.29]", "pantograph.gravity_m_s2=9.81"])
    p = fmu_parameters(case, 8)
    assert p["rig"]["servo_bandwidth_hz"] == 40.0
    assert p["catenary"]["hil_update"] == 1 and p["catenary"]["delay_steps"] == 8
    assert p["pantograph"]["pantograph_model"] == 1 and p["pantograph"]["masses_kg_1"] == 5.29
    assert p["pantograph"]["masses_kg_2"] == 0.0 and p["pantograph"]["gravity_m_s2"] == 9.81
    assert p["pantograph"]["uplift_force_N"] == pytest.approx(0.00097 * 250**2 + 70)


def test_schema_is_the_declarations():
    assert [k.dotted for s in SCHEMA.values() for k in s.values()] == [k.dotted for k in all_keys()]
