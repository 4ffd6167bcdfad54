"""`pantohil watch`: follows a run.mcap as it grows, reading only complete records, and shows the
figures the run itself reports (summary.json's convergence history)."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from pantohil.orchestrator.mcap_follow import McapFollower, read_log
from pantohil.orchestrator.recorder import McapWriter
from pantohil.orchestrator.watch import span_line

from conftest import pantohil

GROUPS = {"/catenary": {"force_at_sample": "force [N]"}}


def _span(writer: McapWriter, span: int, n: int = 50) -> None:
    t = (span * n + np.arange(n)) * 1e-3
    writer.write_block("/catenary", t, (100.0 + span + np.sin(t))[:, None])
    writer.write_event(
        "/convergence",
        (span + 1) * n * 1e-3,
        {
            "span": span,
            "change": 1.0 / (span + 1),
            "mean_N": 100.0 + span,
            "std_N": 0.7,
            "max_N": 101.0 + span,
            "min_N": 99.0 + span,
        },
    )
    writer.flush()


def test_follower_reads_complete_records_of_a_growing_file(tmp_path):
    path = tmp_path / "run.mcap"
    writer = McapWriter(path, GROUPS, {"case": "growing"})
    follower = McapFollower(path)
    seen = []
    for span in range(40):  # enough for several chunks
        _span(writer, span)
        seen += follower.poll()
    writer.close()
    seen += follower.poll()
    assert follower.finished and follower.metadata == {"case": "growing"}
    assert [m["span"] for topic, _, m in seen if topic == "/convergence"] == list(range(40))
    forces = [m["force_at_sample"] for topic, _, m in seen if topic == "/catenary"]
    assert len(forces) == 40 * 50 and forces[0] == 100.0
    whole = path.read_bytes()
    for cut in (len(whole) // 3, len(whole) // 2, len(whole) - 3):  # a file cut anywhere: what is complete
        (tmp_path / "cut.mcap").write_bytes(whole[:cut])
        part = McapFollower(tmp_path / "cut.mcap").poll()
        spans = [m["span"] for topic, _, m in part if topic == "/convergence"]
        assert spans == list(range(len(spans)))  # a prefix, in order, nothing invented


def test_a_chunk_whose_header_is_being_patched_is_not_read_yet(tmp_path):
    """A writer that patches a finished chunk's length, then its header field by field (the mcap crate's, in
    foxglove-sdk): seen between the two, the chunk's compressed size is still all ones. The follower waits for
    it instead of failing ("a record cannot be read"), and reads it once it is patched."""
    path = tmp_path / "run.mcap"
    writer = McapWriter(path, GROUPS, {"case": "patched"})
    _span(writer, 0)
    writer.close()
    whole = path.read_bytes()
    offset = len(b"\x89MCAP0\r\n")
    while whole[offset] != 0x06:  # the first chunk record
        offset += 9 + int.from_bytes(whole[offset + 1:offset + 9], "little")
    length = int.from_bytes(whole[offset + 1:offset + 9], "little")
    end = offset + 9 + length
    name_bytes = int.from_bytes(whole[offset + 9 + 28:offset + 9 + 32], "little")
    size_at = offset + 9 + 32 + name_bytes
    half = whole[:size_at] + b"\xff" * 8 + whole[size_at + 8:end]  # length patched, compressed size not yet
    growing = tmp_path / "growing.mcap"
    growing.write_bytes(half)
    follower = McapFollower(growing)
    assert follower.poll() == [] and follower.offset == offset
    growing.write_bytes(whole[:end])  # the header patched
    got = follower.poll()
    assert got and got[0] == read_log(path)[0]


@pytest.mark.slow
def test_watch_follows_a_run_to_its_end(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    watcher = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "watch", str(out),
                                "--interval", "0.1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    run = pantohil("run", "--out", str(out), "--quiet", "--set", "run.max_spans=6")
    assert run.returncode == 1, run.stderr
    lines, err = watcher.communicate(timeout=600)
    assert watcher.returncode == 0, err
    summary = json.loads((out / "summary.json").read_text())
    expected = [span_line(rec) for rec in summary["convergence"]]
    assert lines.splitlines() == expected + [f"{summary['status']}: {summary['message']}"]


def test_watch_bad_folder_is_one_line_and_exit_2(tmp_path):
    for args in ([str(tmp_path / "missing"), "--once"], [str(tmp_path), "--once"], [str(tmp_path), "--interval", "0"]):
        proc = pantohil("watch", *args)
        assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "watch:" in proc.stderr, proc.stderr
    (tmp_path / "run.mcap").write_bytes(b"not an mcap file at all")
    proc = pantohil("watch", str(tmp_path))
    assert proc.returncode == 2 and "not an MCAP file" in proc.stderr


@pytest.mark.slow
def test_watch_started_before_its_run_waits_for_it_and_shows_units(tmp_path):
    out = tmp_path / "later"
    watcher = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "watch", str(out),
                                "--interval", "0.1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert "waiting up to 60 s" in watcher.stderr.readline()  # it is waiting: now the run starts
    run = pantohil("run", "--out", str(out), "--quiet", "--engine", "inprocess", "--set", "run.max_spans=3")
    assert run.returncode == 1, run.stderr
    lines, err = watcher.communicate(timeout=600)
    assert watcher.returncode == 0, err
    assert lines.splitlines()[-1].startswith("span_limit: ")
    once = pantohil("watch", str(out), "--once")
    rows = {ln.split("│")[1].strip(): ln.split("│")[3].strip() for ln in once.stdout.splitlines() if ln.count("│") == 4}
    assert rows["/catenary.height_command"] == "m" and rows["/pantograph.contact_force"] == "N", once.stdout
