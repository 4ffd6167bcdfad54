"""Fault injection: stop signals and SIGKILLs at random instants of default runs (seeded). Every
instant is taken relative to an event of the run (its folder locked, run.mcap written to,
steady_span.csv written), never to how fast the machine is."""
from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader
from pantohil.orchestrator.run_folder import LOCK_NAME

SEED = 15
N_SPAN = 936  # samples per span of the default case
NEVER_CONVERGES = ["--set", "run.convergence_tol=1e-12"]  # 200 spans: far longer than any wait below
EVENT_WAIT_S = 600  # a bound on waiting for an event, not a speed requirement


def _start(out: Path, extra: list[str], env: dict | None = None) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--out", str(out), "--quiet", *extra]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env=env)


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except FileNotFoundError:
        return -1


def _wait_for(path: Path, proc: subprocess.Popen, min_bytes: int = 0) -> None:
    """Until `path` exists with at least `min_bytes`."""
    deadline = time.monotonic() + EVENT_WAIT_S
    while _size(path) < min_bytes:
        assert proc.poll() is None, f"the run ended before {path.name} appeared: {proc.communicate()}"
        assert time.monotonic() < deadline, f"no {path.name} within {EVENT_WAIT_S} s"
        time.sleep(0.01)


def _session_processes(sid: int) -> list[int]:
    """Processes of a session (the run was started as its leader)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            fields = stat.rsplit(")", 1)[1].split()
            if int(fields[3]) == sid and fields[0] != "Z":
                pids.append(int(entry.name))
    return pids


def _wait_session_gone(sid: int) -> None:
    deadline = time.monotonic() + EVENT_WAIT_S
    while _session_processes(sid):
        assert time.monotonic() < deadline, f"processes of the run left: {_session_processes(sid)}"
        time.sleep(0.05)


def _send(proc: subprocess.Popen, how: str) -> int:
    if how == "group":
        os.killpg(proc.pid, signal.SIGINT)
        return signal.SIGINT
    sig = signal.SIGINT if how == "SIGINT" else signal.SIGTERM
    proc.send_signal(sig)
    return sig


def _mcap_counts(path: Path) -> dict:
    """Messages per topic, read completely through the file's summary and index."""
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None, f"{path} has no summary section"
        topics = {cid: ch.topic for cid, ch in summary.channels.items()}
        counts: dict[str, int] = {}
        for _schema, channel, _message in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert sum(counts.values()) == summary.statistics.message_count
    assert counts == {topics[c]: n for c, n in summary.statistics.channel_message_counts.items() if n}
    return counts


def _check_interrupted(proc: subprocess.Popen, sig: int, out: Path) -> dict:
    stdout, stderr = proc.communicate(timeout=EVENT_WAIT_S)
    assert proc.returncode == 128 + sig, stdout + stderr
    assert "Traceback" not in stderr, stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "interrupted" and not s["converged"], s["message"]
    assert s["stop_signal"] == signal.Signals(sig).name
    if (out / "run.mcap").exists() or s["spans"]:
        counts = _mcap_counts(out / "run.mcap")
        steps = round(s["timing"]["simulated_s"] / s["dt_s"])
        assert counts.get("/catenary", 0) == counts.get("/pantograph", 0) == steps
        assert counts.get("/convergence", 0) == s["spans"] == steps // N_SPAN
    assert not (out / LOCK_NAME).exists()
    _wait_session_gone(proc.pid)
    return s


def _plan() -> list[tuple[str, str]]:
    """20 interrupts: (phase, how); each way of interrupting in each phase."""
    hows = ["SIGINT", "SIGTERM", "group"]
    phases = ["build"] * 4 + ["stepping"] * 12 + ["final write"] * 4
    return [(phase, hows[i % 3]) for i, phase in enumerate(phases)]


@pytest.mark.slow
def test_twenty_interrupts_each_leave_a_complete_record(tmp_path):
    rng = random.Random(SEED)
    messages = {"build": [], "stepping": [], "final write": []}
    for i, (phase, how) in enumerate(_plan()):
        out = tmp_path / f"run{i:02d}"
        for _attempt in range(5):  # a final write can end before the test sees it begin: try again
            env = dict(os.environ, PANTOHIL_CACHE=str(tmp_path / f"cache{i:02d}")) if phase == "build" else None
            proc = _start(out, ["--set", "run.max_spans=3"] if phase == "final write" else NEVER_CONVERGES, env)
            if phase == "build":
                _wait_for(out / LOCK_NAME, proc)
                time.sleep(rng.uniform(0.0, 0.3))
            elif phase == "stepping":
                _wait_for(out / "run.mcap", proc)
                time.sleep(rng.uniform(0.0, 8.0))
            else:
                _wait_for(out / "steady_span.csv", proc)
            if (out / "summary.json").exists():
                proc.communicate(timeout=EVENT_WAIT_S)
                _wait_session_gone(proc.pid)
                shutil.rmtree(out)
                continue
            sig = _send(proc, how)
            messages[phase].append(_check_interrupted(proc, sig, out)["message"])
            break
        else:
            pytest.fail(f"interrupt {i} ({phase}): the run folder was complete before every attempt to interrupt")
    assert any("while the FMUs were built" in m for m in messages["build"]), messages["build"]
    assert sum("while writing the run folder" in m for m in messages["final write"]) == 4, messages["final write"]
    assert all("in span" in m for m in messages["stepping"]), messages["stepping"]


def _stream_counts(path: Path) -> dict:
    """Messages per channel of a file that may be cut short, read in order up to the cut."""
    counts: dict[int, int] = {}
    try:
        with open(path, "rb") as fh:
            for record in StreamReader(fh).records:
                if isinstance(record, Message):
                    counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
    except Exception:  # the cut itself
        pass
    return counts


@pytest.mark.slow
def test_after_five_sigkills_nothing_of_the_run_is_left_and_the_log_reads(tmp_path):
    rng = random.Random(SEED + 1)
    for i in range(5):
        out = tmp_path / f"kill{i}"
        proc = _start(out, NEVER_CONVERGES)
        # an instant after the first span was logged (run.mcap past its first chunk)
        _wait_for(out / "run.mcap", proc, min_bytes=70_000)
        time.sleep(rng.uniform(0.0, 4.0))
        whole_group = i == 4  # the writer dies too: its file is cut short, and read up to the cut
        if whole_group:
            os.killpg(proc.pid, signal.SIGKILL)
        else:
            proc.kill()
        proc.communicate(timeout=EVENT_WAIT_S)
        _wait_session_gone(proc.pid)
        assert not (out / "summary.json").exists()
        if whole_group:
            counts = _stream_counts(out / "run.mcap")
            assert sum(counts.values()) >= N_SPAN, counts
            continue
        counts = _mcap_counts(out / "run.mcap")  # finished by the writer after its parent died
        spans = counts["/convergence"]
        assert spans >= 1
        assert counts["/catenary"] in (spans * N_SPAN, (spans + 1) * N_SPAN), counts
