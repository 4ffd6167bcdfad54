"""`pantohil rig-emulator`: a process that plays the rig's real-time controller over UDP.

It answers each COMMAND with a FORCE: the case's rig model (delay, N_com ramp, servo, load cell,
offset, noise) moves the actuator and the case's pantograph model gives the contact force, one
step of dt per command (lockstep). Faults are injected on its answers with a seed: loss, reordering
(an answer sent after the next one), duplication, corruption and delay. Its counters go to a JSON
file when a session ends and when it stops.
"""
from __future__ import annotations

import contextlib
import gc
import json
import math
import random
import signal
import socket
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from pantohil.fmus import udp_protocol as proto
from pantohil.models.case import Case
from pantohil.models.pantograph.lumped import make_pantograph
from pantohil.models.rig.chain import Rig
from pantohil.models.storage import write_text_atomic

RCVBUF_BYTES = 4 << 20


@dataclass(frozen=True)
class Faults:
    loss: float = 0.0
    reorder: float = 0.0
    duplicate: float = 0.0
    corrupt: float = 0.0
    delay_us: float = 0.0
    seed: int = 0

    def __post_init__(self):
        for name in ("loss", "reorder", "duplicate", "corrupt"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{name}: a probability in [0, 1] (got {p})")
        if self.loss + self.reorder + self.duplicate + self.corrupt > 1.0:
            raise ValueError("the loss, reorder, duplicate and corrupt probabilities add up to more than 1")
        if self.delay_us < 0:
            raise ValueError(f"answer delay: must be >= 0 (got {self.delay_us})")


@dataclass
class EmulatorStats:
    sessions: int = 0
    commands: int = 0
    malformed: int = 0
    unexpected: int = 0
    answers: int = 0
    dropped: int = 0
    reordered: int = 0
    duplicated: int = 0
    corrupted: int = 0
    max_abs_height_m: float = 0.0
    max_abs_velocity_m_s: float = 0.0
    max_abs_acceleration_m_s2: float = 0.0
    last_height_m: float = 0.0
    last_commands_m: list = field(default_factory=list)


class RigEmulator:
    def __init__(self, case: Case, listen: tuple[str, int], faults: Faults = Faults(),
                 stats_path: Path | None = None):
        self.case = case
        self.faults = faults
        self.stats = EmulatorStats()
        self.stats_path = Path(stats_path) if stats_path else None
        self._rng = random.Random(faults.seed)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUFFORCE, RCVBUF_BYTES)
        except (OSError, AttributeError):
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
        self.sock.bind(listen)
        self.address = self.sock.getsockname()
        self._session = False
        self._held = None
        self._stop = False

    def _reset(self, dt: float) -> None:
        c = self.case
        self.dt = dt if dt > 0 else c.dt_s
        self.rig = Rig(c.rig, self.dt)
        self.pan = make_pantograph(c.pantograph, self.dt, c.reference_height_m())
        self.pan.settle(0.0)
        self._z = self._v = 0.0
        self._held = None
        self._session = True

    def _record_command(self, z: float) -> None:
        s = self.stats
        v = (z - self._z) / self.dt
        a = (v - self._v) / self.dt if s.commands > 1 else 0.0
        s.max_abs_height_m = max(s.max_abs_height_m, abs(z))
        if s.commands > 0:
            s.max_abs_velocity_m_s = max(s.max_abs_velocity_m_s, abs(v))
            s.max_abs_acceleration_m_s2 = max(s.max_abs_acceleration_m_s2, abs(a))
        s.last_height_m = z
        s.last_commands_m = (s.last_commands_m + [z])[-20:]
        self._z, self._v = z, v

    def _send(self, data: bytes, peer) -> None:
        with contextlib.suppress(OSError):
            self.sock.sendto(data, peer)

    def _answer(self, reply: bytes, peer) -> None:
        f, r, s = self.faults, self._rng.random(), self.stats
        if f.delay_us > 0:
            time.sleep(f.delay_us * 1e-6)
        held, self._held = self._held, None
        bands = ((f.loss, "drop"), (f.reorder, "hold"), (f.duplicate, "duplicate"), (f.corrupt, "corrupt"))
        fault, edge = None, 0.0
        for p, name in bands:
            edge += p
            if r < edge:
                fault = name
                break
        if fault == "hold" and held is not None:
            fault = None  # one answer held at a time: this one goes out as it is
        overtaken = False  # did this answer go out intact, ahead of a held one?
        if fault == "drop":
            s.dropped += 1
        elif fault == "hold":
            self._held = reply  # sent after the next answer
        elif fault == "corrupt":
            bad = bytearray(reply)
            bad[self._rng.randrange(len(bad))] ^= 1 << self._rng.randrange(8)
            self._send(bytes(bad), peer)
            s.corrupted += 1
        else:
            self._send(reply, peer)
            if fault == "duplicate":
                self._send(reply, peer)
                s.duplicated += 1
            overtaken = True
        if held is not None:
            self._send(held, peer)
            s.reordered += overtaken  # a swap on the wire; otherwise the held answer was only delayed

    def handle(self, data: bytes, peer) -> None:
        try:
            msg = proto.decode(data)
        except proto.Malformed:
            self.stats.malformed += 1
            return
        if msg.type == proto.HELLO:
            self._reset(msg.a)
            self.stats.sessions += 1
            latency = self.case.rig.latency_steps(self.dt)
            self._send(proto.encode(proto.Message(proto.STATUS, 0, 0, a=float(latency), u=proto.RIG_READY)), peer)
        elif msg.type == proto.COMMAND and self._session:
            self.stats.commands += 1
            self._record_command(msg.a)
            z_act = self.rig.height(msg.a)
            f = self.rig.force(self.pan.step(z_act))
            self.stats.answers += 1
            self._answer(proto.encode(proto.Message(proto.FORCE, msg.seq, msg.t_ns, a=f, b=z_act,
                                                    u=proto.RIG_RUNNING)), peer)
        elif msg.type == proto.BYE:
            if self._held is not None:
                self._send(self._held, peer)
                self._held = None
            self._session = False
            self.write_stats()
        else:
            self.stats.unexpected += 1  # a command outside a session, or a rig-side message

    def write_stats(self) -> None:
        if self.stats_path is None:
            return
        stats = {**asdict(self.stats), "faults": asdict(self.faults), "listen": f"{self.address[0]}:{self.address[1]}"}
        write_text_atomic(self.stats_path, json.dumps(stats, indent=1) + "\n")

    def serve(self, max_seconds: float | None = None) -> None:
        """Answer datagrams until SIGTERM/SIGINT (or max_seconds); always writes the stats."""
        def stop(signum, frame):
            self._stop = True

        signal.signal(signal.SIGTERM, stop)
        signal.signal(signal.SIGINT, stop)
        end = math.inf if max_seconds is None else time.monotonic() + max_seconds
        self.sock.settimeout(0.2)
        gc.collect()
        gc.disable()  # a collection pause would make answers late; the loop makes little garbage
        try:
            while not self._stop and time.monotonic() < end:
                try:
                    data, peer = self.sock.recvfrom(2048)
                except TimeoutError:
                    continue
                except OSError:
                    continue
                self.handle(data, peer)
        finally:
            gc.enable()
            self.write_stats()
            self.sock.close()
