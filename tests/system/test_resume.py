"""pantohil run --resume: a run interrupted by SIGINT continues from its last saved span (every FMU's
serialized state, deserialized in a new process) and converges to the span of an uninterrupted run."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from mcap.reader import make_reader

from conftest import default_sigint, load_run, pantohil


def _start_run(out):
    return subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--out", str(out), "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_sigint)


def _saved_span(out) -> int:
    try:
        return json.loads((out / "state" / "checkpoint.json").read_text())["span"]
    except (FileNotFoundError, json.JSONDecodeError):
        return -1


@pytest.mark.slow
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


def test_resume_takes_no_case_or_overrides(tmp_path):
    proc = pantohil("run", "--resume", str(tmp_path), "--set", "run.max_spans=3")
    assert proc.returncode == 2 and "remove --set" in proc.stderr
