"""Hardware adapter FMU: the UDP link to a rig's real-time controller (docs/udp-protocol.md).

Each step it gives the commanded height and the horizon after it (height_ahead_1 ..) to its link client
(`link_client.LinkClient`: the session, both pacings, the actuator limits, every counter) and outputs
the rig's measured force and the link's counters. An FMU state holds the link client's counters, limiter
and session bookkeeping; its socket is shared with the live instance (`constants`), never copied.
"""
from __future__ import annotations

import dataclasses
import importlib.util
import math
from pathlib import Path

# pythonfmu imports this script from the FMU's resources/: its pantohil imports are the FMU's own copy of the
# package there, whatever pantohil the process holds (fmus/own_package.py, loaded by its path from beside this file)
_spec = importlib.util.spec_from_file_location("pantohil_own_package", Path(__file__).with_name("own_package.py"))
_binding = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_binding)

with _binding.own_package(globals()):
    from pantohil.fmus import udp_protocol as proto
    from pantohil.fmus.fmu_support import PantohilSlave
    from pantohil.fmus.variables import Var, case_variables, register_all
    from pantohil.fmus.link_client import (COUNTERS, REFUSED_HORIZON, REFUSED_LATENCY, RIG_PACED_COUNTERS,
                                           TICK_COUNTS, LinkClient, LinkConfig)
    from pantohil.models.hil.loop import MAX_HORIZON_STEPS
    from pantohil.models.rig.actuator import ActuatorLimits

PACED_BY_RIG = proto.PACED_BY_RIG

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
    Var(
        "horizon_steps",
        "integer",
        "parameter",
        "1",
        "Heights each command or answer carries: height_command and height_ahead_1 .. height_ahead_{H-1} "
        "(docs/udp-protocol.md); 1: no horizon",
        1,
        1,
        MAX_HORIZON_STEPS,
    ),
    Var("height_command", "real", "input", "m", "Height commanded by the catenary model", 0.0),
    *[
        Var(f"height_ahead_{i}", "real", "input", "m", f"The height the catenary commands {i} steps later, as its "
            "iterate stands (connect catenary.height_ahead_i)", 0.0)
        for i in range(1, MAX_HORIZON_STEPS)
    ],
    Var(
        "measured_force", "real", "output", "N", "Force measured by the rig for this step; NaN when no answer came", 0.0
    ),
    Var("actuator_height", "real", "output", "m", "Actuator height reported by the rig", 0.0),
    Var("command_sent", "real", "output", "m", "Height sent to the rig, within the actuator limits", 0.0),
    Var("link_state", "integer", "output", "1", "0 ok, 1 answers missing, 2 fault (beyond tolerated losses)", 0),
    Var("rig_latency_steps", "integer", "output", "1", "Latency the rig controller reports, in steps", 0),
    *[Var(name, "integer", "output", "1", text, 0) for name, text in {**COUNTERS, **RIG_PACED_COUNTERS}.items()],
    *[Var(name, "integer", "output", "1", f"{text} (the rig's count, from its latest answer)", 0)
      for name, text in TICK_COUNTS.items()],
    Var(
        "answer_time",
        "real",
        "output",
        "s",
        "Rig-paced: time from this step's sample reaching the socket to the answer leaving it",
        0.0,
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
        "(0: accepted; 1 protocol version, 2 bad HELLO, 4 busy with another session, 8 other pacing, "
        f"16 horizon; {REFUSED_LATENCY}: refused here, a latency outside 0..100000 steps; {REFUSED_HORIZON}: "
        "refused here, no horizon granted or more than asked for)",
        0,
    ),
]

# a rig's first answer may come during initialisation: every output may depend on every input then
VARIABLES = [dataclasses.replace(v, initial_inputs=None) if v.causality == "output" else v for v in VARIABLES]
_AHEAD_INPUTS = tuple(f"height_ahead_{i}" for i in range(1, MAX_HORIZON_STEPS))
_LINK_OUTPUTS = ("measured_force", "actuator_height", "command_sent", "rig_latency_steps", "rig_refusal")


class PantohilAdapter(PantohilSlave):
    """The hardware adapter FMU: the UDP link to a rig controller, within the actuator's limits."""
    author = "pantohil"
    description = "Hardware adapter: UDP link from the catenary model to a HIL rig controller, with actuator limits."

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._client = None
        register_all(self, VARIABLES)

    def _config(self) -> LinkConfig:
        limits = ActuatorLimits(**{f.name: getattr(self, f.name) for f in dataclasses.fields(ActuatorLimits)})
        return LinkConfig(rig_host=self.rig_host, rig_port=int(self.rig_port), dt_s=self.time_step, limits=limits,
                          paced_by=int(self.link_paced_by), pipeline_steps=int(self.pipeline_steps),
                          receive_timeout_s=self.receive_timeout_s, sample_timeout_s=self.sample_timeout_s,
                          settle_after_hold_s=self.settle_after_hold_s,
                          tolerated_losses=int(self.tolerated_losses), horizon_steps=int(self.horizon_steps),
                          local_host=self.local_host, local_port=int(self.local_port), key_file=self.key_file)

    def exit_initialization_mode(self):
        """Open the link: the limiter at the starting height, the socket, HELLO until the rig answers STATUS."""
        self.check_parameters()
        self._client = LinkClient(self._config())
        self._client.open(self.height_command)

    def do_step(self, current_time, step_size):
        """Send this step's command and horizon (limited, or the held position on a fault) and take the rig's
        force (link_client.LinkClient.step)."""
        c = self._client
        ahead = [getattr(self, name) for name in _AHEAD_INPUTS[:max(c.horizon - 1, 0)]]
        c.step(self.height_command, ahead)
        return True

    def constants(self) -> dict[str, object]:
        """The link's socket: shared by the live instance and its states, never copied or serialized."""
        sock = None if self._client is None else self._client._sock
        return {} if sock is None else {"link.socket": sock}

    def terminate(self):
        """Send BYE to the rig and close the socket."""
        if self._client is not None:
            self._client.close()

    def _link_value(self, name: str):
        c = self._client
        if c is None:
            return math.nan if name == "measured_force" else 0
        if name in _LINK_OUTPUTS:
            return getattr(c, name)
        return int(c.session_started)

    @property
    def link_state(self) -> int:
        """Output: 0 ok, 1 answers missing, 2 fault."""
        return 0 if self._client is None else self._client.state

    @property
    def answer_time(self) -> float:
        """Output: rig-paced answer time of this step [s]."""
        return math.nan if self._client is None else self._client.answer_time_s


def _link_output(name: str) -> property:
    return property(lambda self: self._link_value(name))


def _counter_output(name: str) -> property:
    return property(lambda self: 0 if self._client is None else getattr(self._client.counts, name))


for _name in (*_LINK_OUTPUTS, "session_started"):
    setattr(PantohilAdapter, _name, _link_output(_name))
for _name in (*COUNTERS, *RIG_PACED_COUNTERS, *TICK_COUNTS):
    setattr(PantohilAdapter, _name, _counter_output(_name))
