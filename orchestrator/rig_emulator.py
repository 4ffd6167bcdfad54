"""`pantohil rig-emulator`: a process that plays the rig's real-time controller over UDP.

Model-paced (lockstep) it answers each COMMAND with a FORCE: the rig moves the actuator and the
case's pantograph model gives the contact force, one step of dt per command. The rig is a rig file's
chain (`--rig FILE`, else the case's `[rig] file`: link delay, N_com decimation, the drive's ramp at
sub-steps, position loop, motion limits, load-cell low-pass; Paper B sec. 4, Paper D sec. 2), run by
the same model code as the in-process loop and the rig FMU (`models.hil.rig_loop.case_rig`), or else
the case's `[rig]` section (delay, N_com ramp, servo, load cell, offset, noise). Rig-paced it runs
the same models from its own clock (drift, jitter): every tick it sends a SAMPLE and uses the newest
ANSWER that has come back, counting the ticks that had to reuse an old one and timing every answer.
Faults are injected on what it sends, with a seed: loss, reordering (a datagram sent after the next
one), duplication, corruption and delay. A session belongs to the address and id that opened it
(docs/udp-protocol.md). Its counters go to a JSON file when a session ends and when it stops.
"""
from __future__ import annotations

import contextlib
import gc
import json
import math
import random
import select
import signal
import socket
import time
from collections import OrderedDict
from dataclasses import asdict, dataclass, field
from pathlib import Path

from pantohil.fmus import udp_protocol as proto
from pantohil.fmus.link_client import TICK_COUNTS
from pantohil.models.case import Case
from pantohil.models.pantograph.interface import make_pantograph
from pantohil.models.hil.rig_loop import case_rig
from pantohil.models.rig.drive_chain import RigSpec
from pantohil.models.rig.drive_chain import latency_steps as chain_latency_steps
from pantohil.models.storage import write_text_atomic

from .rig_clock import Percentiles, RigClock

RCVBUF_BYTES = 4 << 20
WINDOW = 4096  # rig-paced: samples awaiting an answer that are remembered


@dataclass(frozen=True)
class RigPacing:
    """How the emulator is paced: by the model (lockstep) or by its own clock, with drift and jitter."""

    paced_by: str = "model"
    drift_ppm: float = 0.0
    jitter_us: float = 0.0
    seed: int = 0
    slow_motion: float = 1.0  # wall-clock period / dt (a test of the link on a loaded machine)

    def __post_init__(self):
        if self.paced_by not in ("model", "rig"):
            raise ValueError(f"--paced-by: must be model or rig (got {self.paced_by!r})")
        if not (math.isfinite(self.drift_ppm) and abs(self.drift_ppm) <= 10000):
            raise ValueError(f"--drift-ppm: must be within +-10000 ppm (got {self.drift_ppm})")
        if not (math.isfinite(self.jitter_us) and 0 <= self.jitter_us <= 1e5):
            raise ValueError(f"--jitter-us: must be in [0, 100000] us (got {self.jitter_us})")
        if not (math.isfinite(self.slow_motion) and 1 <= self.slow_motion <= 1000):
            raise ValueError(f"--slow-motion: must be in [1, 1000] (got {self.slow_motion})")

    @property
    def mode(self) -> int:
        """The protocol's pacing code of the session: rig-paced or model-paced."""
        return proto.PACED_BY_RIG if self.paced_by == "rig" else proto.PACED_BY_MODEL


@dataclass
class PacedState:
    """A rig-paced session's loop: the clock (from the model's ANSWER 0), the reference in use and the
    bookkeeping of samples and answers (bounded: WINDOW samples awaiting an answer)."""

    clock: RigClock | None = None
    z_ref: float = 0.0
    newest: int = 0
    sent_ns: dict = field(default_factory=dict)
    samples: int = 0
    answered: int = 0
    unanswered: int = 0
    doubled: int = 0
    answer_us: Percentiles = field(default_factory=Percentiles)
    tick_late_us: Percentiles = field(default_factory=Percentiles)

    def record(self) -> dict:
        """The rig-paced counters of a session: samples, answered, unanswered, answer times."""
        tail = sum(1 for seq in self.sent_ns if seq > self.newest)  # sent after the model's last answer
        return {"samples": self.samples, "answered": self.answered,
                "unanswered": self.unanswered + len(self.sent_ns) - tail, "after_last_answer": tail,
                "doubled": self.doubled, "answer_us": self.answer_us.summary(),
                "tick_lateness_us": self.tick_late_us.summary()}


@dataclass(frozen=True)
class Faults:
    """Probabilities of the emulator's injected faults (loss, reorder, duplicate, corrupt), delay and seed."""
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
    """Counters of the rig emulator: sessions, commands, answers and every kind of fault."""
    sessions: int = 0
    commands: int = 0
    malformed: int = 0
    old_version: int = 0
    unexpected: int = 0
    foreign: int = 0
    nonfinite: int = 0
    bad_hello: int = 0
    replayed: int = 0
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
    session_log: list = field(default_factory=list)


@dataclass
class Session:
    """The session that owns the rig: only datagrams from its address with its id are taken."""

    number: int
    peer: tuple
    id: int
    mode: int
    dt_s: float
    last_heard: float
    commands: int = 0
    foreign: int = 0
    nonfinite: int = 0
    replayed: int = 0
    last_seq: int = 0  # model-paced: the newest COMMAND executed; none at or below it is executed again
    max_abs_height_m: float = 0.0
    paced: PacedState | None = None
    horizon: int = 1  # H granted
    heights: tuple = (0.0,)  # the newest answer's (COMMAND's) heights, for ticks (steps) newest + 1 (+ 0) ...
    ticks: dict = field(default_factory=lambda: dict.fromkeys(TICK_COUNTS, 0))

    def height_for(self, tick: int, newest: int, first: int) -> float | None:
        """The height the newest answer carries for `tick` (its heights start at tick newest + first), and
        the tick counted fresh or predicted; None and counted uncovered if it does not cover the tick
        (docs/udp-protocol.md, "Which height a tick takes")."""
        i = tick - newest - first
        if 0 <= i < len(self.heights):
            self.ticks["fresh" if i == 0 else "predicted"] += 1
            return self.heights[i]
        self.ticks["uncovered"] += 1
        return None

    def record(self, end: str) -> dict:
        """A session's record for the stats file: peer, id, pacing, counters, largest height, how it ended."""
        rig_paced = self.paced.record() if self.paced is not None else {}
        return {**rig_paced, "number": self.number, "peer": f"{self.peer[0]}:{self.peer[1]}", "id": f"{self.id:016x}",
                "paced_by": "rig" if self.mode == proto.PACED_BY_RIG else "model", "dt_s": self.dt_s,
                "commands": self.commands, "foreign": self.foreign, "nonfinite": self.nonfinite,
                "replayed": self.replayed, "horizon_steps": self.horizon, **self.ticks,
                "max_abs_height_m": self.max_abs_height_m, "end": end}


MIN_DT_S, MAX_DT_S = 1e-5, 1.0  # time steps a HELLO may ask for
ENDED_SESSIONS = 4096  # ids of ended sessions remembered: a replayed HELLO cannot reopen one


class RigEmulator:
    """Plays the rig controller for a case over UDP: the rig (`rig`, a rig file's chain, else the case's)
    and the case's pantograph, in lockstep or on the rig's own clock (Paper D sec. 2)."""
    def __init__(self, case: Case, listen: tuple[str, int], faults: Faults = Faults(),
                 stats_path: Path | None = None, key: bytes | None = None, session_timeout_s: float = 5.0,
                 announce=None, pacing: RigPacing = RigPacing(), rig: RigSpec | None = None):
        self.case = case
        self.rig_spec = rig if rig is not None else case.rig_spec
        self.faults = faults
        self.pacing = pacing
        self.key = key
        self.session_timeout_s = session_timeout_s
        self.announce = announce or (lambda line: None)
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
        self.session: Session | None = None
        self._ended_ids: OrderedDict = OrderedDict()
        self._held = None
        self._stop = False

    def _reset(self, dt: float) -> None:
        c = self.case
        self.dt = dt
        self.rig = case_rig(c, dt, self.rig_spec)
        self.pan = make_pantograph(c.pantograph, self.dt, c.reference_height_m())
        self.pan.settle(0.0)
        self._z = self._v = 0.0
        self._recorded = 0
        self._held = None

    def _record_command(self, z: float) -> None:
        """The reference a step or tick applies: the largest height, velocity and acceleration commanded."""
        s = self.stats
        v = (z - self._z) / self.dt
        a = (v - self._v) / self.dt if self._recorded > 1 else 0.0
        s.max_abs_height_m = max(s.max_abs_height_m, abs(z))
        self.session.max_abs_height_m = max(self.session.max_abs_height_m, abs(z))
        if self._recorded > 0:
            s.max_abs_velocity_m_s = max(s.max_abs_velocity_m_s, abs(v))
            s.max_abs_acceleration_m_s2 = max(s.max_abs_acceleration_m_s2, abs(a))
        s.last_height_m = z
        s.last_commands_m = (s.last_commands_m + [z])[-20:]
        self._z, self._v = z, v
        self._recorded += 1

    def _send(self, data: bytes, peer) -> None:
        with contextlib.suppress(OSError):
            self.sock.sendto(data, peer)

    def _status(self, peer, session: int, state: int, faults: int = 0, latency: int = 0, mode: int = 0,
                horizon: int = 0) -> None:
        self._send(proto.encode(proto.Message(proto.STATUS, 0, 0, a=float(latency), b=getattr(self, "dt", 0.0),
                                              u=state, w=faults, session=session, c=float(mode), horizon=horizon),
                                self.key), peer)

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
        """Handle one datagram: a session on HELLO, FORCE to a COMMAND (model-paced, after the faults), the
        height of an ANSWER (rig-paced), the session's end on BYE; anything else is counted and dropped."""
        try:
            msg = proto.decode(data, self.key)
        except proto.Malformed as exc:
            self.stats.malformed += 1
            if isinstance(exc, proto.OtherVersion):
                self.stats.old_version += 1
                version = proto.old_hello_version(data)
                if version is not None:  # an old model computer: tell it, in its own version, why not
                    session = int.from_bytes(data[8:16], "little") if version > 1 else 0
                    self._send(proto.old_refusal(version, session), peer)
            return
        self._expire(time.monotonic())
        s = self.session
        if msg.type == proto.HELLO:
            self._hello(msg, peer)
        elif msg.type not in (proto.COMMAND, proto.BYE, proto.ANSWER) or s is None:
            self.stats.unexpected += 1  # a command outside a session, or a rig-side message
        elif peer != s.peer or msg.session != s.id:
            self.stats.foreign += 1  # not the session's master: never moves the actuator
            s.foreign += 1
        elif msg.type == proto.BYE:
            s.last_heard = time.monotonic()
            self._close("bye")
        elif not proto.finite(msg):
            self.stats.nonfinite += 1
            s.nonfinite += 1
        else:
            s.last_heard = time.monotonic()
            if msg.type == proto.COMMAND and s.paced is None:
                self._command(msg, peer)
            elif msg.type == proto.ANSWER and s.paced is not None:
                self._take_answer(msg, s.paced)
            else:
                self.stats.unexpected += 1

    def _hello(self, msg: proto.Message, peer) -> None:
        """Open a session, repeat the answer to its own HELLO, or refuse (busy, bad values)."""
        s = self.session
        if s is not None and (peer != s.peer or msg.session != s.id):
            self.stats.foreign += 1
            s.foreign += 1
            self._status(peer, msg.session, proto.RIG_BUSY, proto.FAULT_BUSY)
            return
        if not proto.finite(msg):
            self.stats.nonfinite += 1
            self._status(peer, msg.session, proto.RIG_FAULT, proto.FAULT_BAD_HELLO)
            return
        if s is None and msg.session in self._ended_ids:  # a recorded HELLO: the ended session stays ended
            self.stats.replayed += 1
            self._status(peer, msg.session, proto.RIG_FAULT, proto.FAULT_BAD_HELLO, mode=self.pacing.mode)
            return
        bad_horizon = not 1 <= msg.horizon <= proto.MAX_HORIZON_STEPS
        if (not MIN_DT_S <= msg.a <= MAX_DT_S or msg.session == 0 or msg.u != self.pacing.mode
                or self._other_dt(msg.a) or bad_horizon):
            self.stats.bad_hello += 1
            faults = (proto.FAULT_BAD_HELLO | (proto.FAULT_PACING if msg.u != self.pacing.mode else 0)
                      | (proto.FAULT_HORIZON if bad_horizon else 0))
            self._status(peer, msg.session, proto.RIG_FAULT, faults, mode=self.pacing.mode)
            return
        opening = s is None
        if opening:
            self._reset(msg.a)
            self.stats.sessions += 1
            self.session = Session(self.stats.sessions, peer, msg.session, msg.u, msg.a, time.monotonic(),
                                   paced=PacedState() if msg.u == proto.PACED_BY_RIG else None, horizon=msg.horizon)
        latency = (chain_latency_steps(self.rig_spec, self.dt) if self.rig_spec is not None
                   else self.case.rig.latency_steps(self.dt))
        self._status(peer, msg.session, proto.RIG_READY, latency=latency, mode=msg.u, horizon=self.session.horizon)
        if opening:
            self.announce(f"session {self.session.number} opened by {peer[0]}:{peer[1]} "
                          f"({'rig' if msg.u == proto.PACED_BY_RIG else 'model'}-paced, dt {msg.a:g} s)")

    def _other_dt(self, dt: float) -> bool:
        """A rig file's chain runs at its own model step: a HELLO asking for another dt is refused."""
        spec = self.rig_spec
        return spec is not None and abs(dt - spec.model_step_s) > 1e-6 * spec.model_step_s

    def _command(self, msg: proto.Message, peer) -> None:
        """Model-paced (lockstep): one step of the rig and the pantograph per COMMAND, answered by a FORCE.
        A COMMAND whose seq is not above the newest executed one (a duplicate, a late one or a replay,
        authenticated or not) is never executed: counted `replayed`, not answered. Steps skipped (COMMANDs
        lost) are executed first, with the heights the newest executed COMMAND carries for them (or held)."""
        s = self.session
        if msg.seq <= s.last_seq or len(msg.ahead) >= s.horizon:
            s.replayed += msg.seq <= s.last_seq
            self.stats.replayed += msg.seq <= s.last_seq
            self.stats.malformed += msg.seq > s.last_seq  # more heights than the session's horizon
            return
        for skipped in range(max(s.last_seq + 1, msg.seq - WINDOW), msg.seq):
            z = s.height_for(skipped, s.last_seq, 0)
            self._rig_step(self._z if z is None else z)
        s.last_seq = msg.seq
        s.heights = (msg.a, *(h for h, _ in msg.ahead))
        s.height_for(msg.seq, msg.seq, 0)  # counted fresh
        self.stats.commands += 1
        self.session.commands += 1
        z_act, f = self._rig_step(msg.a)
        self.stats.answers += 1
        t = s.ticks
        self._answer(proto.encode(proto.Message(proto.FORCE, msg.seq, msg.t_ns, a=f, b=z_act, u=proto.RIG_RUNNING,
                                                session=msg.session, fresh=t["fresh"], predicted=t["predicted"],
                                                uncovered=t["uncovered"]), self.key), peer)

    def _rig_step(self, z_ref: float) -> tuple[float, float]:
        """One step of the rig and the pantograph at reference z_ref: the actuator height and the measured force."""
        self._record_command(z_ref)
        z_act = self.rig.height(z_ref)
        return z_act, self.rig.force(self.pan.step(z_act))

    def _take_answer(self, msg: proto.Message, p: PacedState) -> None:
        """Rig-paced: ANSWER 0 starts the loop; an answer to a sample is timed and, if it is the
        newest, becomes the reference of the next tick."""
        now = time.perf_counter_ns()
        s = self.session
        if len(msg.ahead) >= s.horizon:
            self.stats.malformed += 1  # more heights than the session's horizon
            return
        if p.clock is None:
            if msg.seq == 0:
                pc = self.pacing
                p.clock = RigClock(self.dt, now, pc.drift_ppm, pc.jitter_us, pc.seed, pc.slow_motion)
                p.z_ref = msg.a
                s.heights = (msg.a, *(h for h, _ in msg.ahead))
            return
        sent = p.sent_ns.pop(msg.seq, None)
        if sent is None:
            if 0 < msg.seq <= p.clock.tick:
                p.doubled += 1  # already answered (or answered after WINDOW ticks)
            else:
                self.stats.unexpected += 1  # an answer to a sample not sent
            return
        p.answered += 1
        p.answer_us.add((now - sent) / 1e3)
        if msg.seq > p.newest:
            p.newest = msg.seq
            s.heights = (msg.a, *(h for h, _ in msg.ahead))
            self.stats.commands += 1
            s.commands += 1

    def _tick(self, p: PacedState) -> None:
        """One tick of the rig's main loop: the tick's height from the newest answer that covers it (else
        the actuator holds), the force measured and sent as a SAMPLE with the tick counts."""
        now = time.perf_counter_ns()
        p.tick_late_us.add(max(now - p.clock.due_ns, 0) / 1e3)
        k = p.clock.advance()
        s = self.session
        z = s.height_for(k, p.newest, 1)
        if z is not None:
            p.z_ref = z
        z_act, f = self._rig_step(p.z_ref)
        t = s.ticks
        sample = proto.Message(proto.SAMPLE, k, p.clock.rig_time_ns(k), a=f, b=z_act, u=proto.RIG_RUNNING,
                               w=t["uncovered"], session=s.id, fresh=t["fresh"], predicted=t["predicted"],
                               uncovered=t["uncovered"])
        p.sent_ns[k] = time.perf_counter_ns()
        self._answer(proto.encode(sample, self.key), self.session.peer)
        p.samples += 1
        self.stats.answers += 1
        if len(p.sent_ns) > WINDOW:
            del p.sent_ns[next(iter(p.sent_ns))]
            p.unanswered += 1

    def _close(self, end: str) -> None:
        s = self.session
        if self._held is not None:
            self._send(self._held, s.peer)
            self._held = None
        self.stats.session_log.append(s.record(end))
        self._ended_ids[s.id] = True
        if len(self._ended_ids) > ENDED_SESSIONS:
            self._ended_ids.popitem(last=False)
        rec = self.stats.session_log[-1]
        paced = (f", {rec['samples']} samples, {rec['answered']} answered, ticks {rec['fresh']} fresh "
                 f"{rec['predicted']} predicted {rec['uncovered']} uncovered, answer p50 "
                 f"{rec['answer_us']['p50']:.0f} us p99 {rec['answer_us']['p99']:.0f} us max "
                 f"{rec['answer_us']['max']:.0f} us") if s.paced is not None else ""
        self.announce(f"session {s.number} closed ({end}): {s.commands} commands{paced}, {s.foreign} foreign "
                      f"datagrams refused")
        self.session = None
        self.write_stats()

    def _expire(self, now: float) -> None:
        """A session whose master has been silent for session_timeout_s ends; the actuator holds."""
        if self.session is not None and now - self.session.last_heard > self.session_timeout_s:
            self._close(f"expired: no datagram from its master for {self.session_timeout_s:g} s")

    def write_stats(self) -> None:
        """Write the counters and fault settings to the stats file, atomically."""
        if self.stats_path is None:
            return
        stats = {**asdict(self.stats), "faults": asdict(self.faults), "listen": f"{self.address[0]}:{self.address[1]}"}
        write_text_atomic(self.stats_path, json.dumps(stats, indent=1) + "\n")

    def _serve_once(self) -> None:
        """Tick if a rig-paced loop is due, then handle every datagram that is waiting; else wait for
        one until the next tick (or 0.2 s). select() waits to the microsecond (a socket timeout rounds
        up to whole milliseconds)."""
        s = self.session
        p = s.paced if s is not None else None
        timeout = 0.2
        if p is not None and p.clock is not None:
            wait_ns = p.clock.due_ns - time.perf_counter_ns()
            if wait_ns <= 0:
                self._tick(p)
                if p.clock.tick % 256 == 0:
                    self._expire(time.monotonic())
                timeout = 0.0
            else:
                timeout = min(wait_ns / 1e9, 0.2)
        readable, _, _ = select.select([self.sock], [], [], timeout)
        if not readable:
            if timeout > 0:
                self._expire(time.monotonic())
            return
        for _ in range(64):  # then back to the clock: a flood of datagrams never stops the ticks
            try:
                data, peer = self.sock.recvfrom(2048)
            except OSError:  # nothing more waiting (BlockingIOError), or an ICMP error on the socket
                return
            self.handle(data, peer)

    def serve(self, max_seconds: float | None = None) -> None:
        """Answer datagrams until SIGTERM/SIGINT (or max_seconds); always writes the stats."""
        def stop(signum, frame):
            self._stop = True

        signal.signal(signal.SIGTERM, stop)
        signal.signal(signal.SIGINT, stop)
        end = math.inf if max_seconds is None else time.monotonic() + max_seconds
        self.sock.setblocking(False)
        gc.collect()
        gc.disable()  # a collection pause would make answers late; the loop makes little garbage
        try:
            while not self._stop and time.monotonic() < end:
                self._serve_once()
        finally:
            gc.enable()
            if self.session is not None:
                self._close("emulator stopped")
            self.write_stats()
            self.sock.close()
