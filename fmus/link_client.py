"""The model computer's side of the rig link (docs/udp-protocol.md), as a plain class: the session,
both pacings, the horizon, loss/reorder/duplicate handling and every counter. The adapter FMU
(`pantohil_adapter.py`) wraps it; it knows nothing of FMI.

Each step it limits the commanded height (and the horizon after it) to the actuator's stroke,
velocity and acceleration and sends it. Model-paced with pipeline_steps = 1 (the default) it then
takes the rig's answer to the previous step's command, which had a whole period to arrive, so the step
never waits on the network; with 0 it waits for the answer to this step. Rig-paced it waits for the
rig's sample of this step and answers it at once. An answer that does not come in time makes the force
NaN ("not measured"); after more consecutive misses than tolerated the link is in fault: the client
keeps sending the last safe position and the master stops the run.

The link is bound to a session: the HELLO carries a random session id, and only datagrams from the
rig's address with that id and finite values are taken; the socket is connected to the rig's address,
so that the kernel drops datagrams from anywhere else before they can fill its buffer. No datagram
with a non-finite value is ever sent.
"""
from __future__ import annotations

import math
import socket
import struct
import sys
import time
from collections import OrderedDict
from dataclasses import dataclass, fields

from pantohil.fmus import udp_protocol as proto
from pantohil.models.rig.actuator import ActuatorLimits, Limiter

LINK_OK, LINK_DEGRADED, LINK_FAULT = 0, 1, 2
_WINDOW = 4096  # how many recent sequence numbers are remembered for late/duplicate detection
_SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux; the socket module does not export it
_ANCILLARY_BYTES = socket.CMSG_SPACE(16)
_RCVBUF_BYTES = 4 << 20
FIRST_ANSWER_TIMEOUT_S = 1.0  # the session's first answer may wait this long: a rig's first step can be slow
MAX_RIG_LATENCY_STEPS = 100_000  # a STATUS reporting more is refused (the range of hil.delay_steps)
REFUSED_LATENCY = 256  # rig_refusal bit set by this side: the STATUS's latency is not a step count in range
REFUSED_HORIZON = 512  # rig_refusal bit set by this side: the STATUS granted no horizon, or more than asked for

# The link's counters: one declaration, read by the adapter FMU (its outputs), the rig emulator, the
# run summary, the MCAP log and the live view.
COUNTERS = {
    "sent": "Commands (model-paced) or answers (rig-paced) sent",
    "received": "Answers (model-paced) or samples (rig-paced) received in time for their step",
    "lost": "Answers that never came (so far)",
    "late": "Answers that came after their step",
    "duplicated": "Answers received more than once",
    "reordered": "Answers that came before an earlier one (kept for their step)",
    "malformed": "Datagrams that were not valid pantohil messages",
    "limited": "Commands changed to respect the actuator limits",
    "foreign": "Valid datagrams refused: not from the rig's address or not of this session",
    "nonfinite": "Answers refused for a non-finite force or height",
}
RIG_PACED_COUNTERS = {
    "samples": "Rig-paced: rig samples received in time for their step",
    "answered": "Rig-paced: samples answered",
    "held_out": "Rig-paced: forces not taken as measured: at a tick no answer covered, or within "
                "link.settle_after_hold_s after one",
}
# The rig's tick counts (docs/udp-protocol.md, "Which height a tick takes"), from its latest FORCE or SAMPLE
TICK_COUNTS = {
    "fresh": "Rig ticks whose height came from the answer to the previous sample (or the step's own command)",
    "predicted": "Rig ticks whose height came from an older answer's horizon (the answer was late)",
    "uncovered": "Rig ticks no answer covered: the actuator held its last reference",
}


@dataclass(frozen=True)
class LinkConfig:
    """Where the rig is and how the link runs (the case's [link] and [actuator] keys)."""

    rig_host: str
    rig_port: int
    dt_s: float
    limits: ActuatorLimits
    paced_by: int = proto.PACED_BY_MODEL
    pipeline_steps: int = 1
    receive_timeout_s: float = 0.0003
    sample_timeout_s: float = 0.5
    settle_after_hold_s: float = 0.1
    tolerated_losses: int = 50
    horizon_steps: int = 1
    local_host: str = ""
    local_port: int = 0
    key_file: str = ""


@dataclass
class LinkCounters:
    """Every counter of the link (COUNTERS, RIG_PACED_COUNTERS, TICK_COUNTS)."""

    sent: int = 0
    received: int = 0
    lost: int = 0
    late: int = 0
    duplicated: int = 0
    reordered: int = 0
    malformed: int = 0
    limited: int = 0
    foreign: int = 0
    nonfinite: int = 0
    samples: int = 0
    answered: int = 0
    held_out: int = 0
    fresh: int = 0
    predicted: int = 0
    uncovered: int = 0


assert [f.name for f in fields(LinkCounters)] == [*COUNTERS, *RIG_PACED_COUNTERS, *TICK_COUNTS]


class LinkClient:
    """The model computer's end of a rig session. `open(height)` starts it; `step(height, ahead)` sends
    this step's command (and the horizon after it) and takes the rig's force; `close()` ends it."""

    def __init__(self, config: LinkConfig):
        self.cfg = config
        self.counts = LinkCounters()
        self.state = LINK_OK
        self.session_started = False
        self.rig_refusal = 0
        self.rig_latency_steps = 0
        self.horizon = 1  # H granted by the rig
        self.measured_force = math.nan
        self.actuator_height = 0.0
        self.command_sent = 0.0
        self.answer_time_s = math.nan
        self._sock = None
        self._key = None
        self._peer = None
        self._session = 0
        self._answered = OrderedDict()
        self._missing = OrderedDict()
        self._consecutive = 0
        self._missed = 0
        self._seq = 0
        self._uncovered_seen = 0  # rig-paced: the rig's uncovered count in the newest sample taken
        self._settle_left = 0  # rig-paced: samples still to hold out after the actuator held
        self._settle_steps = math.ceil(config.settle_after_hold_s / config.dt_s - 1e-9)
        self._early = {}  # answers that came before their step awaited them (reordering)
        self._arrival_ns = OrderedDict()  # rig-paced: kernel arrival time of each sample not yet answered
        self._limiter = Limiter(config.limits, config.dt_s, 0.0)

    @property
    def rig_paced(self) -> bool:
        """Whether the rig owns the clock."""
        return self.cfg.paced_by == proto.PACED_BY_RIG

    def open(self, height_m: float) -> None:
        """The limiter at the starting height, the socket, HELLO until the rig answers STATUS; a refusal,
        no answer, an unreachable rig or an unreadable key leave the link in fault."""
        self._limiter = Limiter(self.cfg.limits, self.cfg.dt_s, height_m)
        self.command_sent = self._limiter.z
        self._session = proto.new_session_id()
        try:
            self._key = proto.read_key(self.cfg.key_file) if self.cfg.key_file else None
            self._open_socket()
        except (OSError, ValueError):
            self.state = LINK_FAULT
            return
        self._hello()

    def _open_socket(self) -> None:
        cfg = self.cfg
        self._peer = socket.getaddrinfo(cfg.rig_host, int(cfg.rig_port), socket.AF_INET, socket.SOCK_DGRAM)[0][4]
        local = cfg.local_host
        if not local:  # the interface the routing table uses to reach the rig (connect() sends nothing)
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
                probe.connect(self._peer)
                local = probe.getsockname()[0]
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((local, int(cfg.local_port)))
        self._sock.connect(self._peer)  # the kernel then takes datagrams from the rig's address only
        try:  # room for the rig's samples while the master is held up (a 2 ms rig fills 64 kB in ~0.1 s)
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUFFORCE, _RCVBUF_BYTES)
        except (OSError, AttributeError):
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, _RCVBUF_BYTES)
        if sys.platform.startswith("linux"):  # arrival times of the rig's samples (answer times)
            self._sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)

    def _send(self, msg: proto.Message) -> bool:
        if self._sock is None or not proto.finite(msg):  # a non-finite value never leaves (a safety net)
            return False
        data = proto.encode(msg, self._key)
        for _ in range(2):  # a refusal reported for an earlier datagram (ICMP port unreachable) fails one send
            try:
                self._sock.send(data)
                return True
            except ConnectionRefusedError:
                continue
            except OSError:
                return False
        return False

    def _hello(self) -> None:
        """Start a session: the rig resets and answers with its status (latency, horizon), or refuses."""
        asked = int(self.cfg.horizon_steps)
        hello = proto.Message(proto.HELLO, 0, 0, a=self.cfg.dt_s, u=int(self.cfg.paced_by), session=self._session,
                              horizon=asked)
        for _ in range(10):
            if not self._send(hello):
                break
            msg = self._receive(time.perf_counter() + 0.2, lambda m: m.type == proto.STATUS)
            if msg is None:
                continue
            if msg.type != proto.STATUS:  # a STATUS in another protocol version (_receive marks it so)
                self.rig_refusal = proto.FAULT_VERSION
            elif msg.w:
                self.rig_refusal = int(msg.w)
            elif not 0 <= msg.a <= MAX_RIG_LATENCY_STEPS:
                self.rig_refusal = REFUSED_LATENCY
            elif not 1 <= msg.horizon <= asked:
                self.rig_refusal = REFUSED_HORIZON
            else:
                self.rig_latency_steps = int(round(msg.a))
                self.horizon = msg.horizon  # a rig may keep fewer heights than asked for
                self.session_started = True
                return
            break
        self.state = LINK_FAULT  # no rig, or a refusal: the master reads the state and stops

    def _receive(self, deadline: float, wanted):
        """Read datagrams until one satisfies `wanted` or the deadline passes; count the others. A STATUS of
        this session in another protocol version is returned as a Message of type 0."""
        while self._sock is not None:
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                return None
            self._sock.settimeout(remaining)
            try:
                data, ancillary, _, sender = self._sock.recvmsg(4096, _ANCILLARY_BYTES)
            except (TimeoutError, BlockingIOError):
                return None
            except OSError:  # e.g. ICMP port unreachable reported on the socket
                continue
            try:
                msg = proto.decode(data, self._key)
            except proto.Malformed:
                self.counts.malformed += 1
                if not self.session_started and proto.other_version_status(data, self._session):
                    return proto.Message(0, 0, 0)
                continue
            if sender != self._peer or msg.session != self._session:
                self.counts.foreign += 1
                continue
            if not proto.finite(msg):
                self.counts.nonfinite += 1
                continue
            if msg.type == proto.SAMPLE:
                self._arrival_ns[msg.seq] = _arrival_ns(ancillary)
            if wanted(msg):
                return msg
            if msg.type == (proto.SAMPLE if self.rig_paced else proto.FORCE):
                self._note_stray_answer(msg)
        return None

    def _note_stray_answer(self, msg) -> None:
        seq = msg.seq
        if seq in self._answered or seq in self._early:
            self.counts.duplicated += 1
        elif seq in self._missing:
            del self._missing[seq]
            self._remember(seq)
            self.counts.late += 1
        elif self._awaitable(seq):
            self._early[seq] = msg  # not yet awaited: keep it for its step
        else:
            self.counts.malformed += 1  # an answer to nothing we sent, or a sample from far off
        while len(self._arrival_ns) > _WINDOW:
            self._arrival_ns.popitem(last=False)

    def _awaitable(self, seq: int) -> bool:
        if self.rig_paced:  # a rig sample ahead of the model's step
            return self._seq < seq <= self._seq + _WINDOW
        return self._seq - _WINDOW < seq <= self._seq  # sent, not yet awaited

    def _remember(self, seq: int) -> None:
        self._answered[seq] = True
        if len(self._answered) > _WINDOW:
            self._answered.popitem(last=False)

    def step(self, height_m: float, ahead_m=()) -> None:
        """One step: send this step's command with the heights of the next ones (`ahead_m`, as many as
        the horizon has room for), limited, and take the rig's force (model-paced: of the previous
        step's command with pipeline_steps = 1; rig-paced: of this step's sample, answered at once)."""
        self._seq += 1
        if self.rig_paced:
            self._rig_paced_step(height_m, ahead_m)
            return
        seq = self._seq
        z, v, ahead = self._next_command(height_m, ahead_m)
        if self._send(proto.Message(proto.COMMAND, seq, int(round((seq - 1) * self.cfg.dt_s * 1e9)), a=z, b=v,
                                    session=self._session, ahead=ahead)):
            self.counts.sent += 1  # a failed send is counted as a missing answer below
        awaited = seq - int(self.cfg.pipeline_steps)
        if awaited < 1:  # the first pipelined step: nothing answered yet
            self.measured_force = math.nan
            return
        msg = self._early.pop(awaited, None)
        if msg is None:
            first = awaited == 1 and self.session_started  # a rig's first step may be slow
            timeout = max(self.cfg.receive_timeout_s, FIRST_ANSWER_TIMEOUT_S) if first else self.cfg.receive_timeout_s
            msg = self._receive(time.perf_counter() + timeout, lambda m: m.type == proto.FORCE and m.seq == awaited)
            if msg is not None and self._early:  # it came after a later answer: a reordering
                self.counts.reordered += 1
        self._take(msg, awaited)

    def _next_command(self, height_m: float, ahead_m) -> tuple[float, float, tuple]:
        """This step's (height, velocity) within the limits, and the horizon's next H - 1 (height,
        velocity) as the limiter would take them; on a fault, the last safe position held, no horizon."""
        if self.state == LINK_FAULT:
            z, v, ahead = self.command_sent, 0.0, ()
        else:
            z, v = self._limiter(height_m)
            wanted = _horizon_inputs(height_m, ahead_m, self.horizon - 1)
            ahead = tuple(zip(*self._limiter.preview(wanted), strict=True)) if wanted else ()
        self.command_sent = z
        self.counts.limited = self._limiter.limited
        return z, v, ahead

    def _take(self, msg, awaited: int) -> None:
        """The rig's answer (or sample) for this step, or None: force, counters and link state."""
        c = self.counts
        if msg is None:
            self.measured_force = math.nan
            self._missed += 1
            self._missing[awaited] = True
            if len(self._missing) > _WINDOW:
                self._missing.popitem(last=False)
            self._consecutive += 1
            if self._consecutive > self.cfg.tolerated_losses:
                self.state = LINK_FAULT
            elif self.state != LINK_FAULT:
                self.state = LINK_DEGRADED
        else:
            self.measured_force = msg.a
            self.actuator_height = msg.b
            c.received += 1
            c.fresh, c.predicted, c.uncovered = msg.fresh, msg.predicted, msg.uncovered
            if self.rig_paced and self._held_out(msg.uncovered):
                self.measured_force = math.nan
                c.held_out += 1
            self._remember(awaited)
            self._consecutive = 0
            if self.state != LINK_FAULT:
                self.state = LINK_OK
        c.lost = self._missed - c.late

    def _held_out(self, uncovered: int) -> bool:
        """Whether this sample's force is not taken as measured: the rig's uncovered count grew since the
        previous sample (the actuator held at this tick, or at a tick whose sample was lost), or it did within
        link.settle_after_hold_s before (the actuator's return to the wanted height disturbs the force)."""
        if uncovered > self._uncovered_seen:
            self._uncovered_seen = uncovered
            self._settle_left = self._settle_steps
            return True
        if self._settle_left > 0:
            self._settle_left -= 1
            return True
        return False

    def _rig_paced_step(self, height_m: float, ahead_m) -> None:
        """Consume the rig's sample for this step (waiting for it), answer it with the heights at once.

        The first step's ANSWER 0 (the initial height for H ticks) starts the rig's loop. A sample that
        does not come within sample_timeout (the rig stopped) is a link fault; a sample overtaken by the
        next one is waited for a fraction of a tick, then counted lost."""
        k, c = self._seq, self.counts
        if self.state == LINK_FAULT:
            self._next_command(height_m, ahead_m)
            return  # nothing comes from the rig: hold, answer nothing
        if k == 1:
            held = ((self.command_sent, 0.0),) * (self.horizon - 1)
            self._send(proto.Message(proto.ANSWER, 0, 0, a=self.command_sent, session=self._session, ahead=held))
        msg = self._early.pop(k, None)
        if msg is None:
            msg = self._receive(time.perf_counter() + self.cfg.sample_timeout_s,
                                lambda m: m.type == proto.SAMPLE and m.seq >= k)
            if msg is None:
                self._take(None, k)
                self.state = LINK_FAULT
                self._next_command(height_m, ahead_m)
                return
            if msg.seq > k:
                self._early[msg.seq] = msg
                msg = self._receive(time.perf_counter() + 0.5 * self.cfg.dt_s,
                                    lambda m: m.type == proto.SAMPLE and m.seq == k)
                c.reordered += msg is not None
        self._take(msg, k)
        c.samples = c.received
        z, v, ahead = self._next_command(height_m, ahead_m)
        if self._send(proto.Message(proto.ANSWER, k, msg.t_ns if msg else 0, a=z, b=v, session=self._session,
                                    ahead=ahead)):
            c.answered += 1
            c.sent = c.answered
        arrived = self._arrival_ns.pop(k, None)
        self.answer_time_s = (time.time_ns() - arrived) * 1e-9 if msg is not None and arrived else math.nan

    def close(self) -> None:
        """Send BYE to the rig and close the socket."""
        if self._sock is not None:
            self._send(proto.Message(proto.BYE, self._seq + 1, 0, session=self._session))
            self._sock.close()
            self._sock = None


def _horizon_inputs(height_m: float, ahead_m, count: int) -> list:
    """The next `count` wanted heights after this step's. Inputs a master left unconnected read exactly 0
    while the command is not: then there is no horizon to send (the rig holds on a late answer)."""
    if count <= 0:
        return []
    wanted = list(ahead_m[:count])
    if len(wanted) < count or (height_m != 0.0 and not any(wanted)):
        return []
    return wanted


def _arrival_ns(ancillary) -> int:
    """The kernel's arrival time of a datagram (SO_TIMESTAMPNS, CLOCK_REALTIME) or, without it, now."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(data) >= 16:
            sec, nsec = struct.unpack_from("qq", data)
            return sec * 1_000_000_000 + nsec
    return time.time_ns()
