"""A rig session that cannot lie or be hijacked: a dead rig is never "converged", a NaN height is never
sent, a replayed datagram never moves the actuator (with or without the key), a flood of datagrams
from elsewhere never crowds out the rig's answers, and a STATUS with an implausible latency is refused."""
from __future__ import annotations

import json
import math
import socket
import subprocess
import sys
import threading

import pytest

from pantohil.fmus import udp_protocol as proto
from test_hardware import Emulator, FakeRig, free_port, run_killing_the_rig

pytestmark = pytest.mark.network


def _adapter(tmp_path, port: int, *overrides: str):
    from pantohil.builder.build_fmus import build_case_fmus
    from pantohil.models.case import load_case
    from pantohil.orchestrator.fmu_runtime import FmuInstance

    case = load_case(None, ["link.receive_timeout_s=1.0", "link.tolerated_losses=1000", *overrides])
    fmu = build_case_fmus(case, tmp_path / "fmus", 7, ("adapter",), ("127.0.0.1", port))["adapter"]
    return FmuInstance("adapter", fmu)


def test_a_nan_height_is_never_sent_and_the_commands_recover(tmp_path):
    # heights 0.01 m x 20, NaN x 5, 0.01 m x 45, as another master could set them
    rig = FakeRig(100.0, stranger=False)
    inst = _adapter(tmp_path, rig.port)
    heights = [0.01] * 20 + [math.nan] * 5 + [0.01] * 45
    try:
        inst.setup(0.0, {})
        sent = []
        for k, z in enumerate(heights):
            inst.set_values({"height_command": z})
            inst.do_step(k * 0.001, 0.001)
            sent.append(inst.get_values(["command_sent"])["command_sent"])
        state = inst.get_values(["link_state", "sent"])
    finally:
        inst.close()
    assert state["link_state"] == 0 and state["sent"] == len(heights)
    assert len(rig.commands) == len(heights) and all(math.isfinite(z) for z in rig.commands + sent)
    assert rig.commands == sent
    # during the NaN heights the actuator is held (braked within its limits), then it tracks 0.01 m again
    assert abs(rig.commands[-1] - 0.01) < 1e-9 and max(abs(z) for z in rig.commands) <= 0.12


class _Master:
    """The test plays the session's master on a socket of its own, recording what it sends."""

    def __init__(self, port: int, key: bytes | None):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(5.0)
        self.peer, self.key, self.sent = ("127.0.0.1", port), key, []
        self.session = proto.new_session_id()

    def send(self, m: proto.Message) -> None:
        data = proto.encode(m, self.key)
        self.sent.append(data)
        self.sock.sendto(data, self.peer)

    def answer(self, wait_s: float = 5.0) -> proto.Message | None:
        self.sock.settimeout(wait_s)
        try:
            return proto.decode(self.sock.recvfrom(2048)[0], self.key)
        except TimeoutError:
            return None


@pytest.mark.parametrize("keyed", [False, True])
def test_a_replayed_datagram_never_moves_the_actuator(tmp_path, keyed):
    key = b"0123456789abcdef-pantohil" if keyed else None
    args = ()
    if keyed:
        (tmp_path / "key").write_bytes(key)
        args = ("--key-file", str(tmp_path / "key"))
    emu = Emulator(tmp_path, *args)
    master = _Master(emu.port, key)
    try:
        master.send(proto.Message(proto.HELLO, 0, 0, a=0.001, session=master.session))
        assert master.answer().type == proto.STATUS
        heights = [0.0005 * k for k in range(1, 41)]
        for k, z in enumerate(heights, start=1):
            master.send(proto.Message(proto.COMMAND, k, k * 1_000_000, a=z, session=master.session))
            assert master.answer().seq == k
        recorded = list(master.sent)
        for data in recorded[1:]:  # every COMMAND again, byte for byte, from the master's own address
            master.sock.sendto(data, master.peer)
        master.sock.sendto(recorded[0], master.peer)  # the HELLO again: answered, resets nothing
        status = master.answer()
        assert status is not None and status.type == proto.STATUS and status.w == 0
        assert master.answer(wait_s=0.5) is None  # no replayed COMMAND was answered
        master.send(proto.Message(proto.BYE, 41, 0, session=master.session))
        emu.wait_for("session 1 closed")
        for data in recorded:  # after the session: its HELLO cannot reopen it, its COMMANDs move nothing
            master.sock.sendto(data, master.peer)
        refusal = master.answer()
        assert refusal.type == proto.STATUS and refusal.w & proto.FAULT_BAD_HELLO
        assert master.answer(wait_s=0.5) is None
    finally:
        stats = emu.stop()
    session = stats["session_log"][0]
    assert session["commands"] == stats["commands"] == len(heights)
    assert session["replayed"] == len(heights) and stats["replayed"] == len(heights) + 1
    assert stats["unexpected"] == len(heights) and stats["sessions"] == 1
    assert stats["last_commands_m"] == heights[-20:]  # the actuator's last references: the master's own


def test_a_flood_from_elsewhere_does_not_crowd_out_the_rig(tmp_path):
    # 100 000 junk datagrams at the adapter's port while it runs: the kernel drops them (connected socket)
    rig = FakeRig(100.0, stranger=False)
    port = free_port()
    inst = _adapter(tmp_path, rig.port, "link.tolerated_losses=0", f"link.local_port={port}")
    stop = threading.Event()
    try:
        inst.setup(0.0, {})
        flood = threading.Thread(target=_flood, args=(port, stop, 100_000), daemon=True)
        flood.start()
        for k in range(300):
            inst.do_step(k * 0.001, 0.001)
        stop.set()
        flood.join()
        out = inst.get_values(["received", "lost", "malformed", "foreign", "link_state"])
    finally:
        stop.set()
        inst.close()
    assert out["link_state"] == 0 and out["lost"] == 0 and out["received"] == 299
    assert out["malformed"] == 0 and out["foreign"] == 0


def _flood(port: int, stop: threading.Event, count: int) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        junk = bytes(64)
        for _ in range(count):
            if stop.is_set():
                return
            s.sendto(junk, ("127.0.0.1", port))


def test_a_status_with_an_implausible_latency_is_refused(tmp_path):
    rig = FakeRig(100.0, stranger=False, latency=1e300)  # it accepts the session with 1e300 steps
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--hardware",
                           f"127.0.0.1:{rig.port}", "--out", str(out), "--quiet"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 3, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "latency outside 0..100000 steps" in lines[0] and "Traceback" not in proc.stderr
    assert json.loads((out / "summary.json").read_text())["status"] == "link_lost"


@pytest.mark.slow
@pytest.mark.realtime
def test_a_dead_rig_is_never_converged_whatever_the_tolerated_losses(tmp_path):
    out = tmp_path / "dead"
    _, stderr = run_killing_the_rig(Emulator(tmp_path), out, 1_000_000)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "link_lost" and not summary["converged"]
    assert "data failed" in stderr and "were measured" in stderr
    # the force it reports is of a span the rig answered (link.min_measured_fraction, 0.5), not the kept forces
    n = summary["samples_per_span"]
    assert summary["convergence"][-1]["measured"] < n / 2
    if "reported_span" in summary:
        assert summary["convergence"][summary["reported_span"]]["measured"] >= 0.5 * n
    else:
        assert "contact_force" not in summary


@pytest.mark.parametrize("command", ["emulator", "run"])
def test_a_key_file_that_is_a_fifo_is_one_line(tmp_path, command):
    import os

    fifo = tmp_path / "key"
    os.mkfifo(fifo)
    if command == "emulator":
        argv = ["rig-emulator", "--listen", "127.0.0.1:0", "--key-file", str(fifo)]
    else:
        argv = ["run", "--hardware", "127.0.0.1:9", "--out", str(tmp_path / "run"), "--quiet",
                "--set", f'link.key_file="{fifo}"']
    proc = subprocess.run([sys.executable, "-m", "pantohil.orchestrator.cli", *argv], capture_output=True,
                          text=True, timeout=300)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "not a regular file" in lines[0], proc.stderr
    assert not (tmp_path / "run").exists()
