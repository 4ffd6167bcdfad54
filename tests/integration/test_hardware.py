"""The hardware path: adapter FMU <-UDP-> rig emulator on loopback, real time, faults,
fuzzing, link loss and actuator limits."""
import functools
import json
import math
import struct
import zlib
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import PATIENT_LINK, load_run, pantohil
from pantohil.fmus import udp_protocol as proto
from pantohil.orchestrator.mcap_follow import read_log

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
        self.lines: list[str] = []
        self._new_line = threading.Condition()
        threading.Thread(target=self._read_lines, daemon=True).start()

    def _read_lines(self):
        for line in self.proc.stdout:
            with self._new_line:
                self.lines.append(line)
                self._new_line.notify_all()
        with self._new_line:
            self.lines.append("")  # end of output
            self._new_line.notify_all()

    def wait_for(self, text: str, timeout: float = 900.0) -> str:
        """The first line of the emulator's output that contains `text` (waits for it)."""
        with self._new_line:
            found = self._new_line.wait_for(lambda: any(text in ln for ln in self.lines) or "" in self.lines,
                                            timeout)
            hits = [ln for ln in self.lines if text in ln]
        assert found and hits, f"no line with {text!r} in {self.lines}"
        return hits[0]

    def stop(self) -> dict:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            self.proc.wait(timeout=10)
        return json.loads(self.stats.read_text())


def mcap_rows(path: Path, topic: str) -> list[dict]:
    return [m for _, _, m in read_log(path, (topic,))]


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
        proc = pantohil("run", "--hardware", emu.address, "--realtime", "--out", str(out), "--quiet",
                        "--set", PATIENT_LINK)
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
    # 2 % loss and 2 % reordering injected by the emulator (as fast as possible). A stall of the
    # machine can make an answer late (after the 5 ms receive timeout) and several in a row: no link
    # fault for that here, and the counters must account for every command whatever the stalls.
    emu = Emulator(tmp_path, "--loss", "0.02", "--reorder", "0.02", "--seed", "11")
    out = tmp_path / "faults"
    try:
        proc = pantohil("run", "--hardware", emu.address, "--out", str(out), "--quiet",
                        "--set", "link.receive_timeout_s=0.005", "--set", "link.tolerated_losses=1000000")
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
    # every awaited answer came in time, late or never (the last command's is never awaited: pipeline 1)
    assert link["received"] + link["lost"] + link["late"] == link["sent"] - 1
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
    sid = proto.new_session_id()
    valid = proto.encode(proto.Message(proto.COMMAND, 1, 0, a=0.01, session=sid))
    sock.sendto(proto.encode(proto.Message(proto.HELLO, 0, 0, a=0.001, session=sid)), peer)
    assert proto.decode(sock.recvfrom(2048)[0]).type == proto.STATUS
    answers = 0
    for k in range(1, 1001):
        for _ in range(10):
            sock.sendto(_junk(rng, valid), peer)
        sock.sendto(proto.encode(proto.Message(proto.COMMAND, k, k * 1_000_000, a=0.01, session=sid)), peer)
        msg = proto.decode(sock.recvfrom(2048)[0])
        answers += msg.type == proto.FORCE and msg.seq == k
    sock.sendto(proto.encode(proto.Message(proto.BYE, 1001, 0, session=sid)), peer)
    emu.wait_for("session 1 closed")
    stats = emu.stop()
    assert stats["malformed"] == 10000
    assert answers == 1000 and stats["commands"] == 1000


@pytest.mark.slow
def test_fuzzing_the_adapter(tmp_path):
    # adapter side: the adapter FMU in this process, stepping against the emulator, which corrupts 20 % of
    # its answers (junk from the rig's own address), while 10,000 junk datagrams from elsewhere reach its
    # port (the kernel drops those: the adapter's socket is connected to the rig)
    from pantohil.builder.build_fmus import build_case_fmus
    from pantohil.models.case import load_case
    from pantohil.orchestrator.fmu_runtime import FmuInstance

    emu = Emulator(tmp_path, "--corrupt", "0.2", "--seed", "9")
    port = free_port()
    case = load_case(None, [f"link.local_port={port}", "link.receive_timeout_s=0.005",
                            "link.tolerated_losses=1000000"])
    fmu = build_case_fmus(case, tmp_path / "fmus", 7, ("adapter",), ("127.0.0.1", emu.port))["adapter"]
    inst = FmuInstance("adapter", fmu)
    try:
        inst.setup(0.0, {})
        assert inst.get_values(["link_state"])["link_state"] == 0
        rng = random.Random(9)
        fuzz = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        valid = proto.encode(proto.Message(proto.FORCE, 10**6, 0, a=1.0, session=12345))
        steps = 1000
        for k in range(steps + 20):  # 20 more steps drain what is still queued
            if k < steps:
                for _ in range(10):
                    fuzz.sendto(_junk(rng, valid), ("127.0.0.1", port))
            inst.set_values({"height_command": 0.001 * np.sin(k / 50)})
            inst.do_step(k * 0.001, 0.001)
        out = inst.get_values(["malformed", "received", "lost", "late", "foreign", "link_state", "sent"])
    finally:
        inst.close()
        stats = emu.stop()
    assert stats["corrupted"] > 100 and out["malformed"] == stats["corrupted"] and out["foreign"] == 0
    assert out["received"] + out["lost"] + out["late"] == out["sent"] - 1
    assert out["lost"] + out["late"] == stats["corrupted"]


def run_killing_the_rig(emu: Emulator, out: Path, tolerated_losses: int) -> tuple[str, str]:
    """A real-time hardware run whose emulator is killed once a span is logged; its stdout and stderr."""
    run = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--hardware", emu.address,
                            "--realtime", "--out", str(out), "--quiet", "--set",
                            f"link.tolerated_losses={tolerated_losses}"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    log = out / "run.mcap"
    while not (log.exists() and log.stat().st_size > 70_000):  # a span logged: the session is stepping
        assert run.poll() is None, run.communicate()
        time.sleep(0.05)
    emu.proc.kill()
    stdout, stderr = run.communicate(timeout=600)
    assert run.returncode == 3, stdout + stderr
    return stdout, stderr


@pytest.mark.slow
def test_link_loss_ends_the_run_with_exit_3_and_a_readable_log(tmp_path):
    # the emulator is killed mid-run
    out = tmp_path / "lost"
    stdout, stderr = run_killing_the_rig(Emulator(tmp_path), out, 100)
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "link to the rig lost" in lines[0] and "Traceback" not in stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "link_lost" and not summary["converged"]
    adapter = mcap_rows(out / "run.mcap", "/adapter")  # readable up to the stop
    forces = [row["measured_force"] for row in adapter]
    # the first step (pipelined) awaits nothing: it stands for the last answer if none came before the kill
    trailing = len(forces) - max([0] + [i for i, f in enumerate(forces) if f is not None]) - 1
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


def _hardware_run(emu: Emulator, out: Path, *extra: str) -> subprocess.CompletedProcess:
    # two runs against the lockstep emulator give the same span to the last bit
    return pantohil("run", "--hardware", emu.address, "--out", str(out), "--quiet", "--set", PATIENT_LINK, *extra)


class Intruder:
    """A second client on loopback that sends valid HELLO, COMMAND and BYE datagrams, with its own
    session id and with guessed ones, until told to stop."""

    def __init__(self, port: int):
        self.peer = ("127.0.0.1", port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sent = 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        rng = random.Random(17)
        own = proto.new_session_id()
        k = 0
        while not self.stop.is_set():
            k += 1
            guessed = rng.getrandbits(64)
            for m in (proto.Message(proto.HELLO, 0, 0, a=0.001, session=own),
                      proto.Message(proto.COMMAND, k, k * 1_000_000, a=0.11, session=own),
                      proto.Message(proto.COMMAND, k, k * 1_000_000, a=-0.11, session=guessed),
                      proto.Message(proto.HELLO, 0, 0, a=0.001, session=guessed),
                      proto.Message(proto.BYE, k, 0, session=guessed),
                      proto.Message(proto.BYE, k, 0, session=own)):
                self.sock.sendto(proto.encode(m), self.peer)
                self.sent += 1
            time.sleep(0.001)  # a steady stream, not a flood: the point is who may move the actuator


FEW_SPANS = ("--set", "run.max_spans=8")  # the intruder's datagrams fall on every span of the run


@pytest.mark.slow
def test_a_second_client_cannot_move_or_reset_the_rig(tmp_path):
    # datagrams of another client during a hardware session are refused and
    # counted, the actuator never moves for them, and the run's span equals an undisturbed run's
    emu = Emulator(tmp_path)
    try:
        undisturbed = _hardware_run(emu, tmp_path / "undisturbed", *FEW_SPANS)
        emu.wait_for("session 1 closed")
        intruder = Intruder(emu.port)
        result = {}
        disturbed_run = functools.partial(_hardware_run, emu, tmp_path / "disturbed", *FEW_SPANS)
        run = threading.Thread(target=lambda: result.update(proc=disturbed_run()))
        run.start()
        emu.wait_for("session 2 opened")
        intruder.thread.start()
        emu.wait_for("session 2 closed")
        intruder.stop.set()
        intruder.thread.join()
        run.join()
    finally:
        stats = emu.stop()
    # exit 1: the runs ended at the span limit, as planned
    assert undisturbed.returncode == 1 and result["proc"].returncode == 1, result["proc"].stderr
    quiet, disturbed = stats["session_log"][0], stats["session_log"][1]
    assert quiet["end"] == disturbed["end"] == "bye"  # the intruder's BYEs ended nothing
    assert disturbed["foreign"] > 100 and quiet["foreign"] == 0
    assert disturbed["foreign"] <= intruder.sent and stats["foreign"] >= disturbed["foreign"]
    summary_q, span_q = load_run(tmp_path / "undisturbed")
    summary_d, span_d = load_run(tmp_path / "disturbed")
    assert disturbed["commands"] == summary_d["link"]["sent"] and quiet["commands"] == summary_q["link"]["sent"]
    # the actuator went exactly where the session's own master sent it, never to the intruder's +-0.11 m
    assert disturbed["max_abs_height_m"] == quiet["max_abs_height_m"] < 0.1
    assert summary_d["spans"] == summary_q["spans"] and np.array_equal(span_d, span_q)
    assert summary_d["link"]["lost"] == 0 and summary_d["link"]["foreign"] == 0


def _ask(sock: socket.socket, peer, m: proto.Message) -> proto.Message:
    sock.sendto(proto.encode(m), peer)
    return proto.decode(sock.recvfrom(2048)[0])


def test_the_emulator_refuses_bad_values_and_other_versions(tmp_path):
    emu = Emulator(tmp_path)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.settimeout(30.0)
    peer = ("127.0.0.1", emu.port)
    try:
        for dt in (math.nan, math.inf, -1.0, 0.0, 10.0):
            status = _ask(sock, peer, proto.Message(proto.HELLO, 0, 0, a=dt, session=5))
            assert status.type == proto.STATUS and status.u == proto.RIG_FAULT and status.w == proto.FAULT_BAD_HELLO
        status = _ask(sock, peer, proto.Message(proto.HELLO, 0, 0, a=0.001, session=0))  # no session id
        assert status.w == proto.FAULT_BAD_HELLO
        status = _ask(sock, peer, proto.Message(proto.HELLO, 0, 0, a=0.001, session=6, horizon=65))
        assert status.w == proto.FAULT_BAD_HELLO | proto.FAULT_HORIZON and status.horizon == 0
        v1 = struct.Struct("<IBBHIQddII").pack(proto.MAGIC, 1, proto.HELLO, 0, 0, 0, 0.001, 0.0, 0, 0)
        sock.sendto(v1 + struct.pack("<I", zlib.crc32(v1)), peer)
        assert sock.recvfrom(2048)[0] == proto.old_refusal(1)
        v2 = struct.Struct("<IBBHQIQdddII").pack(proto.MAGIC, 2, proto.HELLO, 0, 99, 0, 0, 0.001, 0.0, 0.0, 0, 0)
        sock.sendto(v2 + struct.pack("<I", zlib.crc32(v2)), peer)
        assert sock.recvfrom(2048)[0] == proto.old_refusal(2, 99)
        sid = proto.new_session_id()
        assert _ask(sock, peer, proto.Message(proto.HELLO, 0, 0, a=0.001, session=sid)).w == 0
        for z in (math.nan, math.inf, -math.inf):
            sock.sendto(proto.encode(proto.Message(proto.COMMAND, 1, 0, a=z, session=sid)), peer)
        sock.sendto(proto.encode(proto.Message(proto.COMMAND, 2, 0, a=0.01, b=math.nan, session=sid)), peer)
        answer = _ask(sock, peer, proto.Message(proto.COMMAND, 3, 0, a=0.02, session=sid))
        assert answer.type == proto.FORCE and answer.seq == 3 and answer.session == sid  # the first one taken
        sock.sendto(proto.encode(proto.Message(proto.BYE, 4, 0, session=sid)), peer)
        emu.wait_for("session 1 closed")
    finally:
        stats = emu.stop()
    assert stats["nonfinite"] == 2 + 4 and stats["bad_hello"] == 5 and stats["old_version"] == 2
    assert stats["commands"] == 1 and stats["max_abs_height_m"] == 0.02 and stats["sessions"] == 1


def test_a_silent_master_loses_its_session(tmp_path):
    emu = Emulator(tmp_path, "--session-timeout-s", "0.5")
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.settimeout(30.0)
    peer = ("127.0.0.1", emu.port)
    try:
        assert _ask(sock, peer, proto.Message(proto.HELLO, 0, 0, a=0.001, session=11)).w == 0
        assert _ask(sock, peer, proto.Message(proto.HELLO, 0, 0, a=0.001, session=12)).u == proto.RIG_BUSY
        emu.wait_for("session 1 closed (expired")
        assert _ask(sock, peer, proto.Message(proto.HELLO, 0, 0, a=0.001, session=12)).w == 0
    finally:
        stats = emu.stop()
    assert stats["foreign"] == 1 and stats["sessions"] == 2


class FakeRig:
    """The test plays the rig controller on a real socket, answering COMMANDs with chosen forces (and
    reporting `latency` steps in its STATUS)."""

    def __init__(self, force: float, stranger: bool, latency: float = 0.0):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(30.0)
        self.port = self.sock.getsockname()[1]
        self.other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.force, self.stranger, self.latency = force, stranger, latency
        self.commands: list[float] = []  # the height of every COMMAND received
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                data, peer = self.sock.recvfrom(2048)
            except OSError:
                return
            m = proto.decode(data)
            if m.type == proto.HELLO:
                reply = proto.Message(proto.STATUS, 0, 0, a=self.latency, session=m.session)
            elif m.type == proto.COMMAND:
                self.commands.append(m.a)
                if self.stranger:  # a valid answer, from another address, then a guessed session's
                    self.other.sendto(proto.encode(proto.Message(proto.FORCE, m.seq, m.t_ns, a=5.0,
                                                                 session=m.session)), peer)
                    self.sock.sendto(proto.encode(proto.Message(proto.FORCE, m.seq, m.t_ns, a=5.0,
                                                                session=m.session ^ 1)), peer)
                reply = proto.Message(proto.FORCE, m.seq, m.t_ns, a=self.force, session=m.session)
            else:
                continue
            self.sock.sendto(proto.encode(reply), peer)


@pytest.mark.parametrize("force,stranger", [(math.nan, False), (math.inf, False), (100.0, True)])
def test_the_adapter_takes_finite_answers_of_its_own_session_only(tmp_path, force, stranger):
    from pantohil.builder.build_fmus import build_case_fmus
    from pantohil.models.case import load_case
    from pantohil.orchestrator.fmu_runtime import FmuInstance

    rig = FakeRig(force, stranger)
    # a refused answer leaves the step waiting for its timeout: short for those, long for the others
    timeout = 1.0 if stranger else 0.02
    case = load_case(None, [f"link.receive_timeout_s={timeout}", "link.tolerated_losses=1000"])
    fmu = build_case_fmus(case, tmp_path / "fmus", 7, ("adapter",), ("127.0.0.1", rig.port))["adapter"]
    inst = FmuInstance("adapter", fmu)
    steps = 200 if stranger else 50
    try:
        inst.setup(0.0, {})
        forces = []
        for k in range(steps):
            inst.do_step(k * 0.001, 0.001)
            forces.append(inst.get_values(["measured_force"])["measured_force"])
        out = inst.get_values(["received", "foreign", "nonfinite", "sent"])
    finally:
        inst.close()
    if stranger:  # the answers from another address never reach the adapter: its socket is connected to the rig
        assert out["foreign"] == steps - 1 and out["received"] == steps - 1
        assert all(f == 100.0 for f in forces[1:])
    else:
        assert steps - 1 <= out["nonfinite"] <= steps and out["received"] == 0 and out["foreign"] == 0
        assert all(math.isnan(f) for f in forces)


def _rig_paced_run(emu: Emulator, out: Path, *extra: str) -> subprocess.CompletedProcess:
    # three spans of rig time (about 2.8 s at dt = 1 ms), a fixed-length test
    return pantohil("run", "--hardware", emu.address, "--paced-by", "rig", "--out", str(out), "--quiet",
                    "--set", "run.max_spans=3", "--set", "run.duration_s=2.8", *extra)


@pytest.mark.realtime
@pytest.mark.parametrize("master", ["fmpy", "libcosim"])
def test_a_rig_paced_run_consumes_and_answers_every_rig_sample_once(tmp_path, master):
    # the emulator's own clock runs 100 ppm fast with 50 us of jitter; the master has no pacer
    emu = Emulator(tmp_path, "--paced-by", "rig", "--drift-ppm", "100", "--jitter-us", "50")
    out = tmp_path / "paced"
    try:
        proc = _rig_paced_run(emu, out, "--master", master)
        emu.wait_for("session 1 closed")
    finally:
        stats = emu.stop()
    assert proc.returncode in (0, 1), proc.stdout + proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    link, rig = summary["link"], stats["session_log"][0]
    steps = summary["spans"] * summary["samples_per_span"]
    assert summary["spans"] == 3 and link["paced_by"] == "rig"
    # one sample per step, each answered once: none lost, none doubled, none left unanswered
    assert link["samples"] == link["answered"] == steps and link["lost"] == 0 and link["duplicated"] == 0
    assert rig["answered"] == steps and rig["unanswered"] == 0 and rig["doubled"] == 0
    assert rig["samples"] == steps + rig["after_last_answer"]
    # every tick is counted once, fresh, predicted or uncovered; the adapter reports the rig's counts
    assert rig["fresh"] + rig["predicted"] + rig["uncovered"] == rig["samples"]
    assert all(link[c] <= rig[c] for c in ("fresh", "predicted", "uncovered"))
    assert link["fresh"] + link["predicted"] + link["uncovered"] >= steps - 1
    a = link["answer_us"]
    assert 0 < a["p50"] <= a["p99"] <= a["max"]
    adapter = mcap_rows(out / "run.mcap", "/adapter")  # both sides, per sample
    assert len(adapter) == steps
    assert [row["samples"] for row in adapter] == list(range(1, steps + 1))
    assert all(row["answer_time"] is not None and row["answer_time"] > 0 for row in adapter)
    # every force is measured but those held out after a tick no answer covered (a loaded machine), and
    # each of those is counted where it happened
    held = [i for i, row in enumerate(adapter) if row["measured_force"] is None]
    assert len(held) == link["held_out"], (held[:10], link)
    assert all(adapter[i]["held_out"] == (adapter[i - 1]["held_out"] if i else 0) + 1 for i in held)


def test_a_rig_that_runs_another_pacing_refuses_the_session(tmp_path):
    emu = Emulator(tmp_path, "--paced-by", "rig")
    out = tmp_path / "refused"
    try:
        proc = pantohil("run", "--hardware", emu.address, "--out", str(out), "--quiet")  # model-paced
    finally:
        stats = emu.stop()
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert "does not run that pacing" in proc.stderr.strip().splitlines()[-1]
    assert stats["sessions"] == 0 and stats["bad_hello"] >= 1


@pytest.mark.realtime
def test_a_rig_that_stops_sending_samples_is_a_link_fault(tmp_path):
    emu = Emulator(tmp_path, "--paced-by", "rig")
    out = tmp_path / "stopped"
    run = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--hardware", emu.address,
                            "--paced-by", "rig", "--out", str(out), "--quiet", "--set", "link.sample_timeout_s=0.2"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    emu.wait_for("session 1 opened")
    emu.proc.kill()
    stdout, stderr = run.communicate(timeout=300)
    assert run.returncode == 3, stdout + stderr
    assert "no sample from the rig for link.sample_timeout_s = 0.2 s" in stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "link_lost"
    held = [row["command_sent"] for row in mcap_rows(out / "run.mcap", "/adapter") if row["link_state"] == 2]
    assert held and len(set(held)) == 1


@pytest.mark.network
@pytest.mark.parametrize("pacing", ["model", "rig"])
def test_the_emulator_takes_a_late_ticks_height_from_the_newest_answers_horizon(tmp_path, pacing):
    """docs/udp-protocol.md, "Which height a tick takes": rig-paced, ANSWER 0 of 8 heights covers ticks 1-8
    (1 fresh, 7 predicted) and nothing covers tick 9 on (uncovered, held); lockstep, COMMAND 1 of 8 heights
    covers the skipped steps 2-8, and steps 9-10 are held, before COMMAND 11 (fresh). The counts depend
    on which answers came, never on when."""
    emu = Emulator(tmp_path, "--paced-by", pacing, *(("--slow-motion", "5") if pacing == "rig" else ()))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.settimeout(30.0)
    peer, sid = ("127.0.0.1", emu.port), proto.new_session_id()
    mode = proto.PACED_BY_RIG if pacing == "rig" else proto.PACED_BY_MODEL
    heights = tuple((0.001 * i, 0.0) for i in range(2, 9))
    try:
        status = _ask(sock, peer, proto.Message(proto.HELLO, 0, 0, a=0.001, u=mode, session=sid, horizon=8))
        assert (status.w, status.horizon) == (0, 8)
        if pacing == "rig":
            sock.sendto(proto.encode(proto.Message(proto.ANSWER, 0, 0, a=0.001, session=sid, ahead=heights)), peer)
            while (m := proto.decode(sock.recvfrom(4096)[0])).seq < 12:  # no sample is answered
                assert m.type == proto.SAMPLE
            counts = (m.fresh, m.predicted, m.uncovered)
            assert counts == (1, 7, 4) and m.w == 4
        else:
            first = _ask(sock, peer, proto.Message(proto.COMMAND, 1, 0, a=0.001, session=sid, ahead=heights))
            assert (first.seq, first.fresh, first.predicted, first.uncovered) == (1, 1, 0, 0)
            m = _ask(sock, peer, proto.Message(proto.COMMAND, 11, 0, a=0.011, session=sid))
            assert (m.seq, m.fresh, m.predicted, m.uncovered) == (11, 2, 7, 2)
        sock.sendto(proto.encode(proto.Message(proto.BYE, 99, 0, session=sid)), peer)
        emu.wait_for("session 1 closed")
    finally:
        stats = emu.stop()
    log = stats["session_log"][0]
    assert log["horizon_steps"] == 8 and log["predicted"] == 7
