"""FMU state: roll-back of every FMU is bit-identical; a run interrupted by SIGINT and resumed from its
last saved span (serialized FMU states, deserialized in a new process) converges to the span of an
uninterrupted run."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from mcap.reader import make_reader

from conftest import load_run, pantohil

ROLL_BACK = """
import os, sys
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
os._exit(0)  # no interpreter teardown with pythonfmu's library loaded
"""


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmus")
    proc = pantohil("build", "--out", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return {p.stem: p for p in out.glob("*.fmu")}


def test_roll_back_is_bit_identical_for_every_fmu(built):
    assert set(built) == {"catenary", "rig", "pantograph", "adapter"}
    for name, path in built.items():
        proc = subprocess.run([sys.executable, "-c", ROLL_BACK, str(path)], capture_output=True, text=True, timeout=900)
        assert "identical True" in proc.stdout, (name, proc.stdout, proc.stderr)
        if name != "adapter":  # alone, the adapter has no rig: its link is in fault and its outputs hold
            assert "changing True" in proc.stdout, (name, proc.stdout)


def _start_run(out):
    # SIGINT as a terminal's Ctrl-C would send it, also when the tests themselves run with SIGINT ignored
    return subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--out", str(out), "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _saved_span(out) -> int:
    try:
        return json.loads((out / "state" / "checkpoint.json").read_text())["span"]
    except (FileNotFoundError, json.JSONDecodeError):
        return -1


def test_resume_after_sigint_at_span_30_equals_an_uninterrupted_run(default_run, tmp_path):
    out = tmp_path / "interrupted"
    proc = _start_run(out)
    while _saved_span(out) < 29:  # the 30th span saved
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=900)
    interrupted = json.loads((out / "summary.json").read_text())
    assert interrupted["status"] == "interrupted", stdout + stderr
    saved = _saved_span(out)
    assert saved >= 29

    resumed = pantohil("run", "--resume", str(out), "--quiet", timeout=3600)
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    summary, span = load_run(out)
    reference, reference_span = load_run(default_run)
    assert summary["resumed_from_span"] == saved + 1
    assert summary["status"] == "converged" and summary["spans"] == reference["spans"]
    # steady_span.csv holds 13 significant digits: 1e-10 N at 130 N
    assert np.max(np.abs(span[:, 3] - reference_span[:, 3])) <= 1e-9
    for log in (out / "run.mcap", out / f"run_from_span_{saved + 1:04d}.mcap"):  # both logs readable
        with open(log, "rb") as f:
            assert sum(1 for _ in make_reader(f).iter_messages()) > 0


def test_resume_of_a_folder_without_a_checkpoint_is_one_line(tmp_path):
    proc = pantohil("run", "--resume", str(tmp_path))
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "no checkpoint" in proc.stderr


def test_resume_takes_no_case_or_overrides(default_run):
    proc = pantohil("run", "--resume", str(default_run), "--set", "run.max_spans=3")
    assert proc.returncode == 2 and "remove --set" in proc.stderr
