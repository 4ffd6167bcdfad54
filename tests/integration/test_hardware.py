"""The hardware path: adapter FMU <-UDP-> rig emulator on loopback, real time, faults,
fuzzing, link loss and actuator limits."""
import json
import random
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from conftest import load_run, pantohil
from pantohil.fmus import udp_protocol as proto

pytestmark = pytest.mark.network


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Emulator:
    """`pantohil rig-emulator` in a process of its own, on a free loopback port."""

    def __init__(self, tmp: Path, *args: str):
        self.stats = tmp / f"emulator-{time.monotonic_ns()}.json"
        self.proc = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "rig-emulator",
                                      "--listen", "127.0.0.1:0", "--stats", str(self.stats), *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        assert "listening on" in line, line + self.proc.stderr.read()
        self.port = int(line.split("listening on ")[1].split()[0].rsplit(":", 1)[1])
        self.address = f"127.0.0.1:{self.port}"

    def stop(self) -> dict:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            self.proc.wait(timeout=10)
        return json.loads(self.stats.read_text())


def mcap_rows(path: Path, topic: str) -> list[dict]:
    with open(path, "rb") as fh:
        return [json.loads(m.data) for _, _, m in make_reader(fh).iter_messages(topics=[topic])]


def rel_rms(a, b):
    return float(np.sqrt(np.mean(((a - a.mean()) - (b - b.mean())) ** 2)) / b.std())


@pytest.mark.slow
@pytest.mark.realtime
def test_realtime_run_through_the_emulator_matches_the_virtual_hil(default_run, tmp_path):
    # real time at dt = 1 ms on loopback; the deadline figure is reported, not asserted
    # (shared machines are noisy); convergence, accuracy and the link are asserted
    emu = Emulator(tmp_path)
    out = tmp_path / "rt"
    try:
        proc = pantohil("run", "--hardware", emu.address, "--realtime", "--out", str(out), "--quiet")
    finally:
        stats = emu.stop()
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary, span = load_run(out)
    _, virtual = load_run(default_run)
    assert summary["converged"] and summary["topology"] == "hardware"
    assert rel_rms(span[:, 3], virtual[:, 3]) <= 0.01
    assert summary["link"]["lost"] == 0 and summary["link"]["malformed"] == 0
    assert summary["realtime"]["steps"] == summary["spans"] * 936
    print(f"\nreal time: {summary['realtime']}")
    assert stats["commands"] == summary["link"]["sent"]


@pytest.mark.slow
def test_loss_and_reordering_still_converge_and_the_counters_match(default_run, tmp_path):
    # 2 % loss and 2 % reordering injected by the emulator (as fast as possible; a
    # generous receive timeout so that only injected faults make answers late)
    emu = Emulator(tmp_path, "--loss", "0.02", "--reorder", "0.02", "--seed", "11")
    out = tmp_path / "faults"
    try:
        proc = pantohil("run", "--hardware", emu.address, "--out", str(out), "--quiet",
                        "--set", "link.receive_timeout_s=0.005", "--set", "link.tolerated_losses=20")
    finally:
        stats = emu.stop()
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary, span = load_run(out)
    _, virtual = load_run(default_run)
    link = summary["link"]
    assert summary["converged"]
    assert rel_rms(span[:, 3], virtual[:, 3]) <= 0.03
    assert stats["dropped"] > 0.015 * stats["commands"] and stats["reordered"] > 0.015 * stats["commands"]
    assert link["lost"] == stats["dropped"]
    # with the adapter's pipeline step an answer overtaken by the next one still arrives in time and is
    # counted as reordered; only a stall of the machine (> receive timeout) can make one late instead
    assert link["reordered"] <= stats["reordered"] <= link["reordered"] + link["late"]
    assert link["late"] <= 0.002 * stats["commands"]
    assert link["malformed"] == 0 and link["duplicated"] == 0


def _junk(rng: random.Random, valid: bytes) -> bytes:
    kind = rng.randrange(4)
    if kind == 0:
        return bytes(rng.randrange(256) for _ in range(rng.randrange(0, 100)))
    if kind == 1:
        return valid[: rng.randrange(0, len(valid))]  # truncated
    if kind == 2:
        bad = bytearray(valid)
        bad[rng.randrange(len(bad))] ^= 1 << rng.randrange(8)  # one flipped bit
        return bytes(bad)
    return bytes(rng.randrange(256) for _ in range(proto.SIZE))  # right size, random


def test_fuzzing_the_emulator(tmp_path):
    # emulator side: 10,000 random and truncated datagrams, each counted as malformed,
    # while a valid session goes on
    emu = Emulator(tmp_path)
    rng = random.Random(5)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.settimeout(2.0)
    peer = ("127.0.0.1", emu.port)
    valid = proto.encode(proto.Message(proto.COMMAND, 1, 0, a=0.01))
    sock.sendto(proto.encode(proto.Message(proto.HELLO, 0, 0, a=0.001)), peer)
    assert proto.decode(sock.recvfrom(64)[0]).type == proto.STATUS
    answers = 0
    for k in range(1, 1001):
        for _ in range(10):
            sock.sendto(_junk(rng, valid), peer)
        sock.sendto(proto.encode(proto.Message(proto.COMMAND, k, k * 1_000_000, a=0.01)), peer)
        msg = proto.decode(sock.recvfrom(64)[0])
        answers += msg.type == proto.FORCE and msg.seq == k
    sock.sendto(proto.encode(proto.Message(proto.BYE, 1001, 0)), peer)
    time.sleep(0.3)
    stats = emu.stop()
    assert stats["malformed"] == 10000
    assert answers == 1000 and stats["commands"] == 1000


@pytest.mark.slow
def test_fuzzing_the_adapter(tmp_path):
    # adapter side: the adapter FMU in this process, stepping against the emulator
    # while 10,000 junk datagrams reach its port
    from pantohil.builder.build_fmus import build_case_fmus
    from pantohil.models.case import load_case
    from pantohil.orchestrator.fmu_runtime import FmuInstance

    emu = Emulator(tmp_path)
    port = free_port()
    case = load_case(None, [f"link.local_port={port}", "link.receive_timeout_s=0.01"])
    fmu = build_case_fmus(case, tmp_path / "fmus", 7, ("adapter",), ("127.0.0.1", emu.port))["adapter"]
    inst = FmuInstance("adapter", fmu)
    try:
        inst.setup(0.0, {})
        assert inst.get_values(["link_state"])["link_state"] == 0
        rng = random.Random(9)
        fuzz = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        valid = proto.encode(proto.Message(proto.FORCE, 10**6, 0, a=1.0))
        steps = 1000
        for k in range(steps + 20):  # 20 more steps drain what is still queued
            if k < steps:
                for _ in range(10):
                    fuzz.sendto(_junk(rng, valid), ("127.0.0.1", port))
            inst.set_values({"height_command": 0.001 * np.sin(k / 50)})
            inst.do_step(k * 0.001, 0.001)
        out = inst.get_values(["malformed", "received", "lost", "link_state", "sent"])
    finally:
        inst.close()
        emu.stop()
    assert out["malformed"] == 10000
    assert out["received"] == out["sent"] - 1 and out["lost"] == 0 and out["link_state"] == 0


@pytest.mark.slow
def test_link_loss_ends_the_run_with_exit_3_and_a_readable_log(tmp_path):
    # the emulator is killed mid-run
    emu = Emulator(tmp_path)
    out = tmp_path / "lost"
    run = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--hardware", emu.address,
                            "--realtime", "--out", str(out), "--quiet", "--set", "link.tolerated_losses=100"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    log = out / "run.mcap"
    while not (log.exists() and log.stat().st_size > 70_000):  # a span logged: the session is stepping
        assert run.poll() is None, run.communicate()
        time.sleep(0.05)
    emu.proc.kill()
    stdout, stderr = run.communicate(timeout=120)
    assert run.returncode == 3, stdout + stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "link to the rig lost" in lines[0] and "Traceback" not in stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "link_lost" and not summary["converged"]
    adapter = mcap_rows(out / "run.mcap", "/adapter")  # readable up to the stop
    forces = [row["measured_force"] for row in adapter]
    trailing = len(forces) - max(i for i, f in enumerate(forces) if f is not None) - 1
    assert trailing == 101  # stopped right after the tolerated 100 missing answers
    held = [row["command_sent"] for row in adapter if row["link_state"] == 2]
    assert held and len(set(held)) == 1  # the last position is held


@pytest.mark.slow
def test_commands_never_exceed_the_actuator_limits(tmp_path):
    # a case whose heights need more stroke, velocity and acceleration than allowed
    emu = Emulator(tmp_path)
    out = tmp_path / "limits"
    limits = {"actuator.stroke_min_m": -0.01, "actuator.stroke_max_m": 0.03,
              "actuator.max_velocity_m_s": 0.02, "actuator.max_acceleration_m_s2": 2.0}
    args = [a for key, v in limits.items() for a in ("--set", f"{key}={v}")]
    try:
        proc = pantohil("run", "--hardware", emu.address, "--out", str(out), "--quiet", "--set", "run.max_spans=4",
                        "--set", "hil.ramp_steps=0", *args)
    finally:
        stats = emu.stop()
    summary = json.loads((out / "summary.json").read_text())
    assert proc.returncode in (0, 1)
    assert summary["link"]["limited"] > 100
    assert stats["max_abs_height_m"] <= 0.03 + 1e-12
    assert stats["max_abs_velocity_m_s"] <= 0.02 * (1 + 1e-6)
    assert stats["max_abs_acceleration_m_s2"] <= 2.0 * (1 + 1e-6)
