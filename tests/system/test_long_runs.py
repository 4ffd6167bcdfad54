"""Long runs keep a bounded record: the master's rings hold the last spans only."""

import numpy as np

from conftest import load_run, pantohil
from pantohil.orchestrator.mcap_follow import read_log


def mcap_rows(path, topic: str) -> list[dict]:
    return [m for _, _, m in read_log(path, (topic,))]


def test_the_master_keeps_a_bounded_record(tmp_path):
    # the master's rings hold RECORDED_SPANS spans whatever the length of the run; what is logged and
    # summarised is the same as with a record of every step
    from pantohil.orchestrator.hil_run import RECORDED_SPANS

    out = tmp_path / "long"
    proc = pantohil("run", "--out", str(out), "--quiet", "--engine", "inprocess",  # the same rings as the fmpy master's
                    "--set", f"run.max_spans={RECORDED_SPANS + 8}",
                    "--set", f"run.duration_s={(RECORDED_SPANS + 7.5) * 0.936}")
    assert proc.returncode in (0, 1), proc.stdout + proc.stderr  # converged or not within the fixed length
    summary, span = load_run(out)
    assert summary["spans"] == RECORDED_SPANS + 8
    force = np.array([row["force_at_sample"] for row in mcap_rows(out / "run.mcap", "/catenary")])
    n = summary["samples_per_span"]
    assert len(force) == summary["spans"] * n
    assert np.allclose(force[-n:], span[:, 3], rtol=1e-9, atol=0)  # the ring's last span = the logged one
