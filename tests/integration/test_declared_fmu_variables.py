"""One declaration per parameter: every case key that reaches an FMU has, in the built FMU's
modelDescription.xml, the name, unit, range and description of its one declaration
(models/parameters.py), and the case's value as its start value."""
from __future__ import annotations

import zipfile

import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from pantohil.builder.build_fmus import build_case_fmus, fmu_parameters
from pantohil.models.case import load_case
from pantohil.models.parameters import fmu_keys, fmu_variable_names

FMUS = ("catenary", "rig", "pantograph", "adapter")
OVERRIDES = ["rig.servo_bandwidth_hz=40.0", "rig.noise_std_N=2.5", "pantograph.contact_stiffness_N_m=60000.0",
             "link.receive_timeout_s=0.0005", "actuator.stroke_max_m=0.1"]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    case = load_case(None, OVERRIDES)
    fmus = build_case_fmus(case, tmp_path_factory.mktemp("fmus"), 8, FMUS)
    return case, fmus


@pytest.mark.slow
@pytest.mark.parametrize("fmu", FMUS)
def test_declared_keys_in_the_model_description(built, fmu):
    case, fmus = built
    assert validate_fmu(str(fmus[fmu])) == []
    md = read_model_description(str(fmus[fmu]))
    variables = {v.name: v for v in md.modelVariables}
    units = {u.name for u in md.unitDefinitions}
    start = fmu_parameters(case, 8)[fmu]
    checked = 0
    for key in fmu_keys(fmu):
        for name in fmu_variable_names(key):
            v = variables[name]
            assert v.causality == "parameter", name
            assert v.description.startswith(key.param.description), (name, v.description)
            if v.type == "Real":
                assert v.unit == key.param.unit and v.unit in units, (name, v.unit)
                assert (None if v.min is None else float(v.min)) == key.param.low, (name, v.min)
                assert (None if v.max is None else float(v.max)) == key.param.high, (name, v.max)
                assert float(v.start) == pytest.approx(start[name], rel=1e-12), name
            else:
                assert int(v.start) == int(start[name]), name
            checked += 1
    assert checked == sum(len(fmu_variable_names(k)) for k in fmu_keys(fmu)) > 0


@pytest.mark.slow
def test_overridden_case_values_are_the_built_start_values(built):
    _, fmus = built
    md = {f: {v.name: v for v in read_model_description(str(p)).modelVariables} for f, p in fmus.items()}
    assert float(md["rig"]["servo_bandwidth_hz"].start) == 40.0
    assert float(md["rig"]["noise_std_N"].start) == 2.5
    assert float(md["pantograph"]["contact_stiffness_N_m"].start) == 60000.0
    assert float(md["adapter"]["receive_timeout_s"].start) == 0.0005
    assert float(md["adapter"]["stroke_max_m"].start) == 0.1
    with zipfile.ZipFile(fmus["rig"]) as z:
        assert b'"servo_bandwidth_hz": 40.0' in z.read("resources/parameters.json")
