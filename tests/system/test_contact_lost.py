"""A pantograph that never touches the wire is not a converged test."""
from __future__ import annotations

import json

import pytest
from conftest import pantohil


@pytest.mark.slow
def test_a_span_without_contact_is_contact_lost(tmp_path):
    out = tmp_path / "run"
    # an uplift force of 1 mN: the head cannot follow the wire up and down the span
    proc = pantohil("run", "--set", "pantograph.uplift_force_N=0.001", "--set", "run.max_spans=20", "--out", str(out),
                    "--quiet", "--engine", "inprocess")  # the run's stop rule, the same for both engines
    s = json.loads((out / "summary.json").read_text())
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert s["status"] == "contact_lost" and not s["converged"] and not s["diverged"]
    assert s["spans"] < 20 and f"span {s['spans'] - 1}" in s["message"]
    assert s["contact_force"]["max_N"] == 0.0
