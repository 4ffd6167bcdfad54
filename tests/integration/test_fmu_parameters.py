"""Parameters a built FMU depends on are structural: a master that sets the speed, the span or the time step
of a built catenary FMU (or a value outside a parameter's range) gets a failed initialisation (fmi2Error) with a
logged message naming the parameter, instead of a run with wrong physics."""
from __future__ import annotations

import subprocess
import sys

import pytest

from conftest import pantohil

SET_AND_INIT = """
import sys
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
path, name, value = sys.argv[1], sys.argv[2], float(sys.argv[3])
md = read_model_description(path)
vr = {v.name: v for v in md.modelVariables}[name]
slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="x", fmiCallLogger=None)
slave.instantiate(loggingOn=True)
slave.setupExperiment(startTime=0.0)
if vr.type == "Integer":
    slave.setInteger([vr.valueReference], [int(value)])
else:
    slave.setReal([vr.valueReference], [value])
slave.enterInitializationMode()
try:
    slave.exitInitializationMode()
    print("initialised", flush=True)
except Exception as exc:
    print("refused", type(exc).__name__, "status", getattr(exc, "status", None), flush=True)
"""


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    out = tmp_path_factory.mktemp("structural")
    proc = pantohil("build", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.mark.slow
@pytest.mark.parametrize("fmu,name,value,words", [
    ("catenary", "speed", 50.0, "parameter speed = 50.0 differs from the 69.44"),
    ("catenary", "span_m", 60.0, "parameter span_m = 60.0 differs"),
    ("catenary", "time_step", 0.002, "parameter time_step = 0.002 differs"),
    ("catenary", "relaxation", 2.0, "parameter relaxation = 2.0 is outside its range"),
    ("rig", "time_step", 0.002, "parameter time_step = 0.002 differs"),
    ("pantograph", "contact_stiffness_N_m", -5.0, "parameter contact_stiffness_N_m = -5.0 is outside its range"),
    ("catenary", "relaxation", 0.5, None),  # a setting of the iteration: a master may change it
])
def test_a_master_setting_a_structural_or_out_of_range_parameter_is_refused(fmus, fmu, name, value, words):
    proc = subprocess.run([sys.executable, "-c", SET_AND_INIT, str(fmus / f"{fmu}.fmu"), name, repr(value)],
                          capture_output=True, text=True, timeout=600)
    if words is None:
        assert "initialised" in proc.stdout, proc.stdout + proc.stderr
    else:
        assert "refused" in proc.stdout and words in proc.stdout + proc.stderr, proc.stdout + proc.stderr
        # fmi2Error (3), not fmi2Fatal (4): the instance can be reset or freed, the others go on (FMI 2.0 sec. 2.1.3)
        assert "status 3" in proc.stdout, proc.stdout
