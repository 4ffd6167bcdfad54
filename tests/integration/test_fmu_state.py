"""FMU state: get state, 100 steps, set state, the same 100 steps again: bit-identical outputs, for
every FMU (fmi2GetFMUstate/fmi2SetFMUstate through fmpy). Serialized states are checked by the resume
test in tests/system/test_resume.py (deserialized in a new process)."""
from __future__ import annotations

import subprocess
import sys

import pytest

from conftest import pantohil

ROLL_BACK = """
import sys
from pathlib import Path
import numpy as np
from pantohil.orchestrator.fmu_runtime import FmuInstance

inst = FmuInstance("x", Path(sys.argv[1]))
inst.setup(0.0, {})
dt = float(inst.description.defaultExperiment.stepSize)
names = {kind: [v.name for v in inst.description.modelVariables if v.causality == "output" and v.type == kind]
         for kind in ("Real", "Integer")}
ports = [inst.port(v) for v in names.values() if v]
inputs = [v for v in inst.description.modelVariables if v.causality == "input" and v.type == "Real"]
drive = inst.port([v.name for v in inputs])

def run(first, steps):
    rows = []
    for k in range(first, first + steps):  # inputs that move: a force around 130 N, a height around 0
        drive.write([130.0 + 20.0 * np.sin(0.05 * k) if v.unit == "N" else 0.01 * np.sin(0.05 * k) for v in inputs])
        inst.do_step(k * dt, dt)
        rows.append([x for p in ports for x in p.read()])
    return np.array(rows, dtype=float)

run(0, 1500)  # past the ramp: the iteration is busy
state = inst.slave.getFMUstate()
a = run(1500, 100)
inst.slave.setFMUstate(state)
b = run(1500, 100)
print("identical", a.tobytes() == b.tobytes(), "changing", bool(np.ptp(a, axis=0).max() > 0), flush=True)
"""


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmus")
    proc = pantohil("build", "--out", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return {p.stem: p for p in out.glob("*.fmu")}


@pytest.mark.slow
def test_roll_back_is_bit_identical_for_every_fmu(built):
    assert set(built) == {"catenary", "rig", "pantograph", "adapter"}
    for name, path in built.items():
        proc = subprocess.run([sys.executable, "-c", ROLL_BACK, str(path)], capture_output=True, text=True, timeout=900)
        assert "identical True" in proc.stdout and proc.returncode == 0, (name, proc.stdout, proc.stderr)
        if name != "adapter":  # alone, the adapter has no rig: its link is in fault and its outputs hold
            assert "changing True" in proc.stdout, (name, proc.stdout)


@pytest.mark.slow
def test_roll_back_is_bit_identical_for_a_pfem_pair_catenary(tmp_path):
    """The catenary FMU of two pantographs on the PFEM (models/hil/pfem_pair.py): its state holds both points'
    iterations, the operators kept by reference."""
    from conftest import CASES_DIR

    proc = pantohil("build", str(CASES_DIR / "pfem_benchmark_pair_250.toml"), "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    proc = subprocess.run([sys.executable, "-c", ROLL_BACK, str(tmp_path / "catenary.fmu")], capture_output=True,
                          text=True, timeout=900)
    assert "identical True" in proc.stdout and "changing True" in proc.stdout, (proc.stdout, proc.stderr)
