"""The FMUs' own fmi2Get/SetReal and fmi2Get/SetInteger (PantohilSlave) read and write what pythonfmu's
accessors do, value for value and error for error, on the virtual HIL's three FMU classes mid-run."""
from __future__ import annotations

import pytest
from pythonfmu import Fmi2Slave, Integer, Real

from pantohil.models.case import load_case
from pantohil.orchestrator.run_topology import delay_plan
from pantohil.orchestrator.inprocess import create_slaves


def _refs(slave, kind) -> list[int]:
    return [vr for vr, var in slave.vars.items() if isinstance(var, kind)]


def _vr(slave, name: str) -> int:
    return next(vr for vr, var in slave.vars.items() if var.name == name)


@pytest.fixture(scope="module")
def slaves_mid_run():
    """The three FMU classes of the default case after 500 Jacobi steps through their own accessors."""
    case = load_case(None, [])
    slaves = create_slaves(case, {"catenary": {"delay_steps": delay_plan(case)["delay_steps"]}})
    cat, rig, pan = slaves["catenary"], slaves["rig"], slaves["pantograph"]
    wires = [(cat, "contact_force", rig, "measured_force"), (rig, "height_command", cat, "height_command"),
             (rig, "true_force", pan, "contact_force"), (pan, "height", rig, "actuator_height")]
    for k in range(500):
        values = [src.get_real([_vr(src, out)])[0] for _, _, src, out in wires]
        for (dst, name, _, _), value in zip(wires, values, strict=True):
            dst.set_real([_vr(dst, name)], [value])
        for slave in slaves.values():
            assert slave.do_step(k * case.dt_s, case.dt_s)
    return slaves


@pytest.mark.parametrize("name", ["catenary", "rig", "pantograph"])
def test_every_output_reads_as_pythonfmu_reads_it(slaves_mid_run, name):
    slave = slaves_mid_run[name]
    reals, ints = _refs(slave, Real), _refs(slave, Integer)
    got = slave.get_real(reals)
    assert got == Fmi2Slave.get_real(slave, reals)
    assert all(type(v) is float for v in got)
    assert slave.get_integer(ints) == Fmi2Slave.get_integer(slave, ints)
    assert any(v != 0.0 for v in got)  # mid-run: something to compare
    reversed_refs = reals[::-1]  # another list of references: its own reader, the same values
    assert slave.get_real(reversed_refs) == got[::-1]
    assert slave.get_real([]) == []


@pytest.mark.parametrize("name", ["catenary", "rig", "pantograph"])
def test_a_reference_of_another_type_is_refused_as_pythonfmu_refuses_it(slaves_mid_run, name):
    slave = slaves_mid_run[name]
    real, integer = _refs(slave, Real)[0], _refs(slave, Integer)[0]
    for call, args in ((slave.get_real, ([integer],)), (slave.set_real, ([integer], [1.0]))):
        with pytest.raises(TypeError, match=f"valueReference={integer} is not of type Real"):
            call(*args)
    with pytest.raises(TypeError, match=f"valueReference={real} is not of type Integer"):
        slave.get_integer([real])
    with pytest.raises(KeyError):
        slave.get_real([10_000])


def test_a_set_input_reads_back_through_both_accessors(slaves_mid_run):
    rig = slaves_mid_run["rig"]
    refs = [_vr(rig, "height_command"), _vr(rig, "true_force")]
    rig.set_real(refs, [0.0123, 98.5])
    assert rig.get_real(refs) == Fmi2Slave.get_real(rig, refs) == [0.0123, 98.5]
