"""Hardware adapter FMU: the UDP link to a rig's real-time controller (docs/udp-protocol.md).

Each step it limits the commanded height to the actuator's stroke, velocity and acceleration and sends
it. With pipeline_steps = 1 (the default) it then takes the rig's answer to the previous step's
command, which had a whole period to arrive, so the step never waits on the network: one step of
latency, compensated by the catenary's delay advance. With 0 it waits for the answer to this step.
An answer that does not come within the receive timeout makes the force NaN ("not measured": the
catenary keeps that sample's previous value). After more consecutive misses than tolerated the link is
in fault: the adapter keeps sending the last safe position and the master stops the run.

The link is bound to a session (docs/udp-protocol.md): the HELLO carries a random session id, and
only datagrams from the rig's address with that id and finite values are taken; the socket is bound
to the interface that reaches the rig unless `local_host` names another, and connected to the rig's
address, so that the kernel drops datagrams from anywhere else before they can fill its buffer. No
datagram with a non-finite value is ever sent.
"""
from __future__ import annotations

import dataclasses
import math
import socket
import struct
import sys
import time
from collections import OrderedDict

from pantohil.fmus import udp_protocol as proto
from pantohil.fmus.fmu_support import PantohilSlave, Var, case_variables, register_all
from pantohil.models.rig.actuator import ActuatorLimits, Limiter

LINK_OK, LINK_DEGRADED, LINK_FAULT = 0, 1, 2
PACED_BY_RIG = proto.PACED_BY_RIG
_WINDOW = 4096  # how many recent sequence numbers are remembered for late/duplicate detection
_SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux; the socket module does not export it
_ANCILLARY_BYTES = socket.CMSG_SPACE(16)
_RCVBUF_BYTES = 4 << 20
FIRST_ANSWER_TIMEOUT_S = 1.0  # the session's first answer may wait this long: a rig's first step can be slow
MAX_RIG_LATENCY_STEPS = 100_000  # a STATUS reporting more is refused (the range of hil.delay_steps)
REFUSED_LATENCY = 256  # rig_refusal bit set by this side: the STATUS's latency is not a step count in range

VARIABLES = [
    *case_variables("adapter"),
    Var("rig_host", "string", "parameter", "1", "Address of the rig controller", "127.0.0.1"),
    Var("rig_port", "integer", "parameter", "1", "UDP port of the rig controller", 47800, 1, 65535),
    Var(
        "local_host",
        "string",
        "parameter",
        "1",
        "Local address to bind (empty: the interface that reaches the rig)",
        "",
    ),
    Var(
        "key_file",
        "string",
        "parameter",
        "1",
        "File with the pre-shared key authenticating each datagram (HMAC-SHA256); empty: none",
        "",
    ),
    Var("time_step", "real", "parameter", "s", "Sampling time dt", 0.001, 1e-6),
    Var("height_command", "real", "input", "m", "Height commanded by the catenary model", 0.0),
    Var(
        "measured_force", "real", "output", "N", "Force measured by the rig for this step; NaN when no answer came", 0.0
    ),
    Var("actuator_height", "real", "output", "m", "Actuator height reported by the rig", 0.0),
    Var("command_sent", "real", "output", "m", "Height sent to the rig, within the actuator limits", 0.0),
    Var("link_state", "integer", "output", "1", "0 ok, 1 answers missing, 2 fault (beyond tolerated losses)", 0),
    Var("rig_latency_steps", "integer", "output", "1", "Latency the rig controller reports, in steps", 0),
    Var("sent", "integer", "output", "1", "Commands sent", 0),
    Var("received", "integer", "output", "1", "Answers received in time", 0),
    Var("lost", "integer", "output", "1", "Answers that never came (so far)", 0),
    Var("late", "integer", "output", "1", "Answers that came after their step", 0),
    Var("duplicated", "integer", "output", "1", "Answers received more than once", 0),
    Var("reordered", "integer", "output", "1", "Answers that came before an earlier one (kept for their step)", 0),
    Var("malformed", "integer", "output", "1", "Datagrams that were not valid pantohil messages", 0),
    Var("limited", "integer", "output", "1", "Commands changed to respect the actuator limits", 0),
    Var(
        "foreign",
        "integer",
        "output",
        "1",
        "Valid datagrams refused: not from the rig's address or not of this session",
        0,
    ),
    Var("nonfinite", "integer", "output", "1", "Answers refused for a non-finite force or height", 0),
    Var(
        "answer_time",
        "real",
        "output",
        "s",
        "Rig-paced: time from this step's sample reaching the socket to the answer leaving it",
        0.0,
    ),
    Var("samples", "integer", "output", "1", "Rig-paced: rig samples received in time for their step", 0),
    Var("answered", "integer", "output", "1", "Rig-paced: samples answered", 0),
    Var(
        "reused",
        "integer",
        "output",
        "1",
        "Rig-paced: rig ticks that reused an old answer (the rig's count, from its latest sample)",
        0,
    ),
    Var(
        "session_started",
        "integer",
        "output",
        "1",
        "1 once the rig has accepted the session (STATUS ready to this session's HELLO)",
        0,
    ),
    Var(
        "rig_refusal",
        "integer",
        "output",
        "1",
        "Fault bits of the rig's refusal of the session start "
        "(0: accepted; 1 protocol version, 2 bad HELLO, 4 busy with another session, 8 other pacing; "
        "256: refused here, a latency outside 0..100000 steps)",
        0,
    ),
]


class PantohilAdapter(PantohilSlave):
    """The hardware adapter FMU: the UDP link to a rig controller, within the actuator's limits."""
    author = "pantohil"
    description = "Hardware adapter: UDP link from the catenary model to a HIL rig controller, with actuator limits."
    transient = ("_sock", "_key")  # a state restores the counters and the limiter, not the socket or the key

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        register_all(self, VARIABLES)
        self._sock = None
        self._key = None
        self._peer = None
        self._session = 0
        self._answered = OrderedDict()
        self._missing = OrderedDict()
        self._consecutive = 0
        self._missed = 0
        self._seq = 0
        self._early = {}  # answers that came before their step awaited them (reordering)
        self._arrival_ns = OrderedDict()  # rig-paced: kernel arrival time of each sample not yet answered
        self._rig_type = proto.FORCE

    def exit_initialization_mode(self):
        """Open the link: the limiter at the starting height, the socket, HELLO until the rig answers STATUS."""
        self.check_parameters()
        limits = ActuatorLimits(**{f.name: getattr(self, f.name) for f in dataclasses.fields(ActuatorLimits)})
        self._limiter = Limiter(limits, self.time_step, self.height_command)
        self.command_sent = self._limiter.z
        self.measured_force = math.nan
        self._session = proto.new_session_id()
        try:
            self._key = proto.read_key(self.key_file) if self.key_file else None
            self._open_socket()
        except (OSError, ValueError):  # unresolvable or unreachable rig, unreadable key: a link fault
            self.link_state = LINK_FAULT
            return
        self._hello()

    def _open_socket(self):
        self._peer = socket.getaddrinfo(self.rig_host, int(self.rig_port), socket.AF_INET, socket.SOCK_DGRAM)[0][4]
        local = self.local_host
        if not local:  # the interface the routing table uses to reach the rig (connect() sends nothing)
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
                probe.connect(self._peer)
                local = probe.getsockname()[0]
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((local, int(self.local_port)))
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

    def _hello(self):
        """Start a session: the rig resets and answers with its status (latency in steps), or refuses."""
        self._rig_type = proto.SAMPLE if self.link_paced_by == PACED_BY_RIG else proto.FORCE
        hello = proto.Message(proto.HELLO, 0, 0, a=self.time_step, u=int(self.link_paced_by), session=self._session)
        for _ in range(10):
            if not self._send(hello):
                break
            msg = self._receive(time.perf_counter() + 0.2, lambda m: m.type == proto.STATUS)
            if msg is not None and msg.w == 0 and not 0 <= msg.a <= MAX_RIG_LATENCY_STEPS:
                self.rig_refusal = REFUSED_LATENCY
                break
            if msg is not None and msg.w == 0:
                self.rig_latency_steps = int(round(msg.a))
                self.session_started = 1
                return
            if msg is not None:
                self.rig_refusal = int(msg.w)
                break
        self.link_state = LINK_FAULT  # no rig, or a refusal: the master reads the state and stops

    def _receive(self, deadline: float, wanted):
        """Read datagrams until one satisfies `wanted` or the deadline passes; count the others."""
        while self._sock is not None:
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                return None
            self._sock.settimeout(remaining)
            try:
                data, ancillary, _, sender = self._sock.recvmsg(2048, _ANCILLARY_BYTES)
            except (TimeoutError, BlockingIOError):
                return None
            except OSError:  # e.g. ICMP port unreachable reported on the socket
                continue
            try:
                msg = proto.decode(data, self._key)
            except proto.Malformed:
                self.malformed += 1
                continue
            if sender != self._peer or msg.session != self._session:
                self.foreign += 1
                continue
            if not proto.finite(msg):
                self.nonfinite += 1
                continue
            if msg.type == proto.SAMPLE:
                self._arrival_ns[msg.seq] = _arrival_ns(ancillary)
            if wanted(msg):
                return msg
            if msg.type == self._rig_type:
                self._note_stray_answer(msg)
        return None

    def _note_stray_answer(self, msg):
        seq = msg.seq
        if seq in self._answered or seq in self._early:
            self.duplicated += 1
        elif seq in self._missing:
            del self._missing[seq]
            self._remember(seq)
            self.late += 1
        elif self._awaitable(seq):
            self._early[seq] = msg  # not yet awaited: keep it for its step
        else:
            self.malformed += 1  # an answer to nothing we sent, or a sample from far off
        while len(self._arrival_ns) > _WINDOW:
            self._arrival_ns.popitem(last=False)

    def _awaitable(self, seq: int) -> bool:
        if self.link_paced_by == PACED_BY_RIG:  # a rig sample ahead of the model's step
            return self._seq < seq <= self._seq + _WINDOW
        return self._seq - _WINDOW < seq <= self._seq  # sent, not yet awaited

    def _remember(self, seq: int):
        self._answered[seq] = True
        if len(self._answered) > _WINDOW:
            self._answered.popitem(last=False)

    def do_step(self, current_time, step_size):
        """Send this step's COMMAND (limited, or the held position on a fault) and take the rig's FORCE.

        By default the answer used is the one to the previous command, so a step never waits on the network;
        a missing answer makes the force NaN, and more than tolerated_losses in a row a link fault.
        """
        self._seq += 1
        if self.link_paced_by == PACED_BY_RIG:
            return self._rig_paced_step()
        seq = self._seq
        z, v = self._next_command()
        t_ns = int(round(current_time * 1e9))
        if self._send(proto.Message(proto.COMMAND, seq, t_ns, a=z, b=v, session=self._session)):
            self.sent += 1  # a failed send is counted as a missing answer below
        awaited = seq - int(self.pipeline_steps)
        if awaited < 1:  # the first pipelined step: nothing answered yet
            self.measured_force = math.nan
            return True
        msg = self._early.pop(awaited, None)
        if msg is None:
            first = awaited == 1 and self.session_started  # a rig's first step may be slow
            timeout = max(self.receive_timeout_s, FIRST_ANSWER_TIMEOUT_S) if first else self.receive_timeout_s
            msg = self._receive(time.perf_counter() + timeout, lambda m: m.type == proto.FORCE and m.seq == awaited)
            if msg is not None and self._early:  # it came after a later answer: a reordering
                self.reordered += 1
        self._take(msg, awaited)
        return True

    def _next_command(self) -> tuple[float, float]:
        if self.link_state == LINK_FAULT:
            z, v = self.command_sent, 0.0  # hold the last safe position
        else:
            z, v = self._limiter(self.height_command)
        self.command_sent = z
        self.limited = self._limiter.limited
        return z, v

    def _take(self, msg, awaited: int) -> None:
        """The rig's answer (or sample) for this step, or None: force, counters and link state."""
        if msg is None:
            self.measured_force = math.nan
            self._missed += 1
            self._missing[awaited] = True
            if len(self._missing) > _WINDOW:
                self._missing.popitem(last=False)
            self._consecutive += 1
            if self._consecutive > self.tolerated_losses:
                self.link_state = LINK_FAULT
            elif self.link_state != LINK_FAULT:
                self.link_state = LINK_DEGRADED
        else:
            self.measured_force = msg.a
            self.actuator_height = msg.b
            self.received += 1
            self._remember(awaited)
            self._consecutive = 0
            if self.link_state != LINK_FAULT:
                self.link_state = LINK_OK
        self.lost = self._missed - self.late

    def _rig_paced_step(self) -> bool:
        """Consume the rig's sample for this step (waiting for it), answer it with the height at once.

        The first step's ANSWER 0 (the initial height) starts the rig's loop. A sample that does not
        come within sample_timeout (the rig stopped) is a link fault; a sample overtaken by the next
        one is waited for a fraction of a tick, then counted lost."""
        k = self._seq
        if self.link_state == LINK_FAULT:
            self._next_command()
            return True  # nothing comes from the rig: hold, answer nothing
        if k == 1:
            self._send(proto.Message(proto.ANSWER, 0, 0, a=self.command_sent, session=self._session))
        msg = self._early.pop(k, None)
        if msg is None:
            msg = self._receive(time.perf_counter() + self.sample_timeout_s,
                                lambda m: m.type == proto.SAMPLE and m.seq >= k)
            if msg is None:
                self._take(None, k)
                self.link_state = LINK_FAULT
                self._next_command()
                return True
            if msg.seq > k:
                self._early[msg.seq] = msg
                msg = self._receive(time.perf_counter() + 0.5 * self.time_step,
                                    lambda m: m.type == proto.SAMPLE and m.seq == k)
                self.reordered += msg is not None
        self._take(msg, k)
        self.samples = self.received
        z, v = self._next_command()
        if msg is not None:
            self.reused = int(msg.w)
        if self._send(proto.Message(proto.ANSWER, k, msg.t_ns if msg else 0, a=z, b=v, session=self._session)):
            self.answered += 1
            self.sent = self.answered
        arrived = self._arrival_ns.pop(k, None)
        self.answer_time = (time.time_ns() - arrived) * 1e-9 if msg is not None and arrived else math.nan
        return True

    def terminate(self):
        """Send BYE to the rig and close the socket."""
        if self._sock is not None:
            self._send(proto.Message(proto.BYE, self._seq + 1, 0, session=self._session))
            self._sock.close()
            self._sock = None


def _arrival_ns(ancillary) -> int:
    """The kernel's arrival time of a datagram (SO_TIMESTAMPNS, CLOCK_REALTIME) or, without it, now."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(data) >= 16:
            sec, nsec = struct.unpack_from("qq", data)
            return sec * 1_000_000_000 + nsec
    return time.time_ns()
