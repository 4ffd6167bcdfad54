"""Hardware adapter FMU: the UDP link to a rig's real-time controller (docs/udp-protocol.md).

Each step it limits the commanded height to the actuator's stroke, velocity and acceleration and sends
it. With pipeline_steps = 1 (the default) it then takes the rig's answer to the previous step's
command, which had a whole period to arrive, so the step never waits on the network: one step of
latency, compensated by the catenary's delay advance. With 0 it waits for the answer to this step.
An answer that does not come within the receive timeout makes the force NaN ("not measured": the
catenary keeps that sample's previous value). After more consecutive misses than tolerated the link is
in fault: the adapter keeps sending the last safe position and the master stops the run.
"""
from __future__ import annotations

import dataclasses
import math
import socket
import time
from collections import OrderedDict

from pantohil.fmus import udp_protocol as proto
from pantohil.fmus.fmu_support import PantohilSlave, Var, case_variables, register_all
from pantohil.models.rig.actuator import ActuatorLimits, Limiter
import contextlib

LINK_OK, LINK_DEGRADED, LINK_FAULT = 0, 1, 2
_WINDOW = 4096  # how many recent sequence numbers are remembered for late/duplicate detection

VARIABLES = [
    *case_variables("adapter"),
    Var("rig_host", "string", "parameter", "1", "Address of the rig controller", "127.0.0.1"),
    Var("rig_port", "integer", "parameter", "1", "UDP port of the rig controller", 47800, 1, 65535),
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
]


class PantohilAdapter(PantohilSlave):
    """The hardware adapter FMU: the UDP link to a rig controller, within the actuator's limits."""
    author = "pantohil"
    description = "Hardware adapter: UDP link from the catenary model to a HIL rig controller, with actuator limits."
    transient = ("_sock",)  # a state restores the counters and the limiter, not the socket

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        register_all(self, VARIABLES)
        self._sock = None
        self._answered = OrderedDict()
        self._missing = OrderedDict()
        self._consecutive = 0
        self._missed = 0
        self._seq = 0
        self._early = {}  # answers that came before their step awaited them (reordering)

    def exit_initialization_mode(self):
        """Open the link: the limiter at the starting height, the socket, HELLO until the rig answers STATUS."""
        limits = ActuatorLimits(**{f.name: getattr(self, f.name) for f in dataclasses.fields(ActuatorLimits)})
        self._limiter = Limiter(limits, self.time_step, self.height_command)
        self.command_sent = self._limiter.z
        self.measured_force = math.nan
        self._peer = (self.rig_host, int(self.rig_port))
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("0.0.0.0", int(self.local_port)))
        self._hello()

    def _hello(self):
        """Start a session: the rig resets and answers with its status (latency in steps)."""
        hello = proto.encode(proto.Message(proto.HELLO, 0, 0, a=self.time_step))
        for _ in range(10):
            try:
                self._sock.sendto(hello, self._peer)
            except OSError:  # unreachable or unresolvable rig: a link fault, reported by link_state
                break
            msg = self._receive(time.perf_counter() + 0.2, lambda m: m.type == proto.STATUS)
            if msg is not None:
                self.rig_latency_steps = int(round(msg.a))
                return
        self.link_state = LINK_FAULT  # no rig: the master reads the state and stops

    def _receive(self, deadline: float, wanted):
        """Read datagrams until one satisfies `wanted` or the deadline passes; count the others."""
        while True:
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                return None
            self._sock.settimeout(remaining)
            try:
                data, _ = self._sock.recvfrom(2048)
            except (TimeoutError, BlockingIOError):
                return None
            except OSError:  # e.g. ICMP port unreachable reported on the socket
                continue
            try:
                msg = proto.decode(data)
            except proto.Malformed:
                self.malformed += 1
                continue
            if wanted(msg):
                return msg
            if msg.type == proto.FORCE:
                self._note_stray_answer(msg)

    def _note_stray_answer(self, msg):
        seq = msg.seq
        if seq in self._answered or seq in self._early:
            self.duplicated += 1
        elif seq in self._missing:
            del self._missing[seq]
            self._remember(seq)
            self.late += 1
        elif self._seq - _WINDOW < seq <= self._seq:
            self._early[seq] = msg  # sent, not yet awaited: keep it for its step
        else:
            self.malformed += 1  # an answer to nothing we sent

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
        seq = self._seq
        if self.link_state == LINK_FAULT:
            z, v = self.command_sent, 0.0  # hold the last safe position
        else:
            z, v = self._limiter(self.height_command)
        self.command_sent = z
        self.limited = self._limiter.limited
        t_ns = int(round(current_time * 1e9))
        try:
            self._sock.sendto(proto.encode(proto.Message(proto.COMMAND, seq, t_ns, a=z, b=v)), self._peer)
            self.sent += 1
        except OSError:
            pass  # counted as a missing answer below
        awaited = seq - int(self.pipeline_steps)
        if awaited < 1:  # the first pipelined step: nothing answered yet
            self.measured_force = math.nan
            return True
        msg = self._early.pop(awaited, None)
        if msg is None:
            msg = self._receive(time.perf_counter() + self.receive_timeout_s,
                                lambda m: m.type == proto.FORCE and m.seq == awaited)
            if msg is not None and self._early:  # it came after a later answer: a reordering
                self.reordered += 1
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
        return True

    def terminate(self):
        """Send BYE to the rig and close the socket."""
        if self._sock is not None:
            with contextlib.suppress(OSError):
                self._sock.sendto(proto.encode(proto.Message(proto.BYE, self._seq + 1, 0)), self._peer)
            self._sock.close()
            self._sock = None
