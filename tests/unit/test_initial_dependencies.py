"""The inputs each FMU output depends on at initialisation (`Var.initial_inputs`, the InitialUnknowns
dependencies of the model descriptions) are all it depends on: an input set to another value before
exitInitializationMode changes no output that does not declare it (FMI 2.0 sec. 2.2.8; a master that trusts
the declaration orders its initialisation by it, and finds no algebraic loop where there is none)."""
import importlib
import math

import pytest

from pantohil.builder.build_fmus import CLASS_NAMES
from pantohil.builder.fmu_parameters import fmu_parameters
from pantohil.builder.staging import stage_case_data
from pantohil.models.case import load_case

VALUES = (0.003, 150.0)  # a height in the wire's range, and a force


def _initialised(name: str, inputs: dict, tmp_path):
    """The FMU class initialised as a master initialises its FMU, with `inputs` set before; its variables."""
    case = load_case(None)
    values = fmu_parameters(case, 8)[name]
    stage = tmp_path / f"{name}_{len(list(tmp_path.iterdir()))}"
    stage.mkdir()
    stage_case_data(name, values, case, stage, link=True)
    module = importlib.import_module(f"pantohil.fmus.pantohil_{name}")
    slave = getattr(module, CLASS_NAMES[name])(instance_name=name, resources=str(stage))
    slave.setup_experiment(0.0, None, None)
    by_name = {v.name: v for v in slave.vars.values()}
    for var, value in inputs.items():
        by_name[var].setter(value)
    slave.enter_initialization_mode()
    slave.exit_initialization_mode()
    return slave, module, by_name


def _same(a, b) -> bool:
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


@pytest.mark.parametrize("name", ["catenary", "rig", "pantograph"])
def test_an_output_depends_at_initialisation_only_on_the_inputs_it_declares(name, tmp_path):
    _, module, variables = _initialised(name, {}, tmp_path)
    declared = {v.name: v.initial_inputs for v in module.VARIABLES if v.causality == "output"}
    inputs = [v.name for v in module.VARIABLES if v.causality == "input" and v.kind == "real"]
    before = {n: variables[n].getter() for n in declared}
    moved = set()
    for var in inputs:
        for value in VALUES:
            _, _, after = _initialised(name, {var: value}, tmp_path)
            for output in declared:
                if not _same(after[output].getter(), before[output]):
                    assert var in declared[output], f"{name}.{output} moves with {var} at initialisation"
                    moved.add((output, var))
    # and the declarations are not empty words: each declared input does move its output
    assert moved == {(o, i) for o, names in declared.items() for i in (names or ())}
