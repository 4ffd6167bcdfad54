"""The pantograph models' registry (models/pantograph/interface.py): the contract every registered model
keeps, the choices and codes that come from it, and no switch on a pantograph model's name elsewhere."""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import package_lines_matching

from pantohil.models.errors import InputError
from pantohil.models.pantograph.interface import PANTOGRAPHS, SteppedPantograph, pantograph_model
from pantohil.models.pantograph.lumped import PantographParameters
from pantohil.models.parameters import PantographSection, pantograph_parameters

DT_S = 0.001


def _params(name: str) -> PantographParameters:
    if PANTOGRAPHS.get(name).fixed_to_actuator:
        return pantograph_parameters(PantographSection(model=name, masses_kg=(5.29,), stiffnesses_N_m=(0.0,),
                                                       dampings_Ns_m=(0.0,), gravity_m_s2=9.81), 130.0)
    return pantograph_parameters(PantographSection(model=name), 130.0)


@pytest.mark.parametrize("name", PANTOGRAPHS.names())
def test_each_models_linear_map_reproduces_its_own_steps_in_contact(name):
    """The stepped model is affine while in contact, so the difference of two trajectories whose heights
    differ by d(k) is exactly the linear map's response to d(k) from rest (Paper D eq. A.3); the bound,
    1e-9 of the largest force, is rounding over 400 steps (about 1e-16 x 400 x the conditioning)."""
    params, model = _params(name), pantograph_model(_params(name))
    a, b = model.build(params, DT_S, 0.0), model.build(params, DT_S, 0.0)
    assert isinstance(a, SteppedPantograph)
    a.settle(0.0)
    b.settle(0.0)
    k = np.arange(400)
    z = 1e-3 * np.sin(2 * np.pi * 1.5 * k * DT_S)  # slow, 1 mm: the head stays on the wire
    d = 1e-4 * np.sin(2 * np.pi * 7.0 * k * DT_S) * np.exp(-k / 300)
    lin = model.linear(params, DT_S)
    x, f_lin, diffs, lins, largest = np.zeros(lin.size), 0.0, [], [], 0.0
    for zk, dk in zip(z, d, strict=True):
        fa, fb = a.step(zk), b.step(zk + dk)
        assert fa > 0 or model.fixed_to_actuator, "the head left the wire: the test's heights are too large"
        x = lin.Pp @ x + lin.pz * dk + lin.pf * f_lin
        f_lin = float(lin.c @ x + lin.cz * dk)
        diffs.append(fb - fa)
        largest = max(largest, abs(fa), abs(fb))
        lins.append(f_lin)
    assert np.abs(diffs).max() > 1e-3 * largest  # the perturbation is seen in the force
    assert np.abs(np.array(diffs) - np.array(lins)).max() < 1e-9 * largest


@pytest.mark.parametrize("name", PANTOGRAPHS.names())
def test_each_models_receptance_is_finite_above_zero_frequency(name):
    params = _params(name)
    h = pantograph_model(params).receptance(params, np.array([1.0, 10.0, 100.0]))
    assert h.shape == (3,) and np.all(np.isfinite(h))


def test_the_case_choices_and_the_fmu_codes_come_from_the_registry():
    choices = next(f for f in dataclasses.fields(PantographSection) if f.name == "model").metadata["param"].choices
    assert choices == PANTOGRAPHS.names()
    assert PANTOGRAPHS.builtin_names() == ("chain", "rigid_mass") == PANTOGRAPHS.names()[:2]
    assert [PANTOGRAPHS.name_of(PANTOGRAPHS.code(n)) for n in PANTOGRAPHS.names()] == list(PANTOGRAPHS.names())


def test_an_unknown_model_or_code_is_an_input_error_naming_the_key():
    with pytest.raises(InputError, match="pantograph.model: 'spring' is not a pantograph model") as err:
        pantograph_model(dataclasses.replace(_params("chain"), model="spring"))
    assert err.value.key == "pantograph.model"
    with pytest.raises(InputError, match="code 99"):
        PANTOGRAPHS.name_of(99, "pantograph_model")


def test_no_switch_on_a_pantograph_models_name_outside_the_registry():
    switch = re.compile(r"""(==|!=|\bin)\s*\(?\s*["'](chain|rigid_mass)["']|pantograph_model\s*(==|!=)\s*\d""")
    found = package_lines_matching(switch, Path("models", "pantograph", "interface.py"))
    assert not found, found
