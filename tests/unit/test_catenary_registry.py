"""The catenary models' registry (models/catenary/interface.py): the contract every registered model keeps,
the choices and codes that come from it, and no switch on a catenary model's name elsewhere."""
from __future__ import annotations

import dataclasses
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
from conftest import package_lines_matching

from pantohil.models.case import CaseError, load_case
from pantohil.models.catenary.grid import SpanGrid
from pantohil.models.catenary.interface import CATENARIES, catenary_model
from pantohil.models.catenary.receptance import reduce_harmonics
from pantohil.models.errors import InputError
from pantohil.models.hil.loop import HilSettings
from pantohil.models.parameters import CatenarySection, fmu_values

# a shipped case of each built-in model (linear: the PFEM's droppers held); another package's model runs
# on the default case
CASES = {"asm": ("asm_250", []), "pfem": ("pfem_benchmark_250", ["pfem.droppers=false"])}


def _case(name: str):
    file, overrides = CASES.get(name, ("asm_250", [f'catenary.model="{name}"']))
    return load_case(file, overrides)


def _one_span(case, force: np.ndarray) -> np.ndarray:
    """The height change after one span of span-by-span updating at relaxation 1 from rest: I_cc f
    (Paper D eq. A.8), from the iteration the model builds out of a staged folder."""
    model = catenary_model(case)
    with tempfile.TemporaryDirectory() as folder:
        model.stage(case, Path(folder), link=True)
        hil, z0 = model.iteration(SpanGrid.of_case(case), fmu_values("catenary", case.values), Path(folder),
                                  HilSettings(update="span", relaxation=1.0, delay_steps=0), None)
    assert len(z0) == case.samples_per_span and np.all(np.isfinite(z0))
    start = hil.z.copy()
    for f in force:
        hil.step(float(f))
    return hil.z - start


def _apply(kernel, i_cc, force: np.ndarray) -> np.ndarray:
    n = len(force)
    if kernel is not None:
        return np.array([kernel[(i - np.arange(n)) % n] @ force for i in range(n)])
    return i_cc @ force


@pytest.mark.parametrize("name", CATENARIES.names())
def test_the_stability_maps_analyse_the_operator_each_model_steps(name):
    """The operator `stability_operator` gives is the one the iteration applies: one span of a smooth force
    moves the iterate by it, to rounding (1e-12 of the largest height change; measured 2e-15)."""
    case = _case(name)
    x = np.arange(case.samples_per_span) / case.samples_per_span
    force = 120.0 + 20.0 * np.sin(2 * np.pi * 3 * x) + 7.0 * np.cos(2 * np.pi * 11 * x + 0.3)
    stepped = reduce_harmonics(_one_span(case, force), case.n_harmonics)
    expected = _apply(*catenary_model(case).stability_operator(case, case.n_harmonics), force)
    assert np.abs(expected).max() > 0
    assert np.abs(stepped - expected).max() < 1e-12 * np.abs(expected).max()


@pytest.mark.parametrize("name", CATENARIES.names())
def test_each_models_static_compliance_is_a_positive_height_per_force(name):
    case = _case(name)
    assert 0 < catenary_model(case).static_compliance_m_N(case) < 1.0


def test_the_strings_static_compliance_is_its_operators_mean_response():
    """ASM2: H11(0) is the operator's zero harmonic exactly (the pantograph's reference height uses it)."""
    case = _case("asm")
    kernel, _ = catenary_model(case).stability_operator(case, case.n_harmonics)
    assert kernel.sum() == pytest.approx(catenary_model(case).static_compliance_m_N(case), rel=1e-12)


def test_the_case_choices_and_the_fmu_codes_come_from_the_registry():
    choices = next(f for f in dataclasses.fields(CatenarySection) if f.name == "model").metadata["param"].choices
    assert choices == CATENARIES.names()
    assert CATENARIES.builtin_names() == ("asm", "pfem") == CATENARIES.names()[:2]
    assert [CATENARIES.name_of(CATENARIES.code(n)) for n in CATENARIES.names()] == list(CATENARIES.names())


def test_an_unknown_model_is_one_line_naming_the_key():
    with pytest.raises(CaseError, match="catenary.model: must be"):
        load_case(None, ['catenary.model="beam"'])
    with pytest.raises(InputError, match="catenary.model: 'beam' is not a catenary model") as err:
        CATENARIES.get("beam", "catenary.model")
    assert err.value.key == "catenary.model"


def test_a_pfem_case_without_its_catenary_file_names_the_key():
    with pytest.raises(CaseError, match="catenary.definition_file: required") as err:
        load_case(None, ['catenary.model="pfem"'])
    assert err.value.key == "catenary.definition_file"


def test_no_switch_on_a_catenary_models_name_outside_the_registry():
    switch = re.compile(r"""(==|!=|\bin)\s*\(?\s*["'](asm|pfem)["']|catenary_model\s*(==|!=)\s*\d""")
    found = package_lines_matching(switch, Path("models", "catenary", "interface.py"))
    assert not found, found
