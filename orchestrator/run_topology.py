"""The co-simulation system of a HIL run: the virtual HIL (catenary -> rig -> pantograph -> rig ->
catenary, all FMUs) or the hardware HIL (catenary <-> adapter FMU <-UDP-> rig), the signals logged per
FMU, and the delay advance D the loop's latency asks for."""
from __future__ import annotations

from dataclasses import dataclass, replace

from pantohil.builder.system import (
    CONNECTIONS,
    FMU_NAMES,
    HARDWARE_CONNECTIONS,
    HARDWARE_FMU_NAMES,
    HORIZON_OUTPUTS,
    SECOND_PANTOGRAPH,
    SECOND_PANTOGRAPH_CONNECTIONS,
    loop_latency_steps,
)
from pantohil.fmus import link_client
from pantohil.models.case import Case, CaseError
from pantohil.models.catenary.interface import catenary_model

from .run_options import RunOptions, is_rig_paced

_CATENARY_GROUP = {"height_command": "commanded height [m]", "contact_force": "force received (NaN: not measured) [N]",
                   "force_at_sample": "force in use at the sample [N]",
                   "height_at_sample": "converging height at the sample [m]",
                   "profile_at_sample": "static height z0 [m]", "sample_index": "sample label [-]",
                   "span_index": "virtual span [-]"}
_SECOND_POINT_GROUP = {"height_command_2": "commanded height at the second contact point [m]",
                       "contact_force_2": "force received from the second pantograph [N]",
                       "force_at_sample_2": "force in use at the second point's sample [N]",
                       "height_at_sample_2": "converging height at the second point's sample [m]",
                       "profile_at_sample_2": "static height z0 at the second point's sample [m]"}


@dataclass(frozen=True)
class Topology:
    """A co-simulation system: its FMUs, connections and the MCAP groups logged."""
    name: str
    fmus: tuple
    connections: tuple
    groups: dict  # MCAP topic -> {signal: description}; topic "/x" logs FMU x
    contact_forces: tuple  # (FMU, output) of each contact force: a span of zeros in one is a lost contact
    hardware: bool = False  # through the adapter and its link to a rig
    pantographs: int = 1

    def with_second_pantograph(self, name: str) -> Topology:
        """The system with a second, virtual pantograph (Paper A sec. 3.4): an instance of the pantograph FMU at
        the catenary's second contact point (models/hil/pair.py)."""
        groups = {**self.groups, "/catenary": {**self.groups["/catenary"], **_SECOND_POINT_GROUP},
                  f"/{SECOND_PANTOGRAPH}": {"contact_force": "second pantograph's contact force [N]",
                                            "head_height": "second pantograph's head height [m]"}}
        return replace(self, name=name, fmus=(*self.fmus, SECOND_PANTOGRAPH),
                       connections=(*self.connections, *SECOND_PANTOGRAPH_CONNECTIONS), groups=groups,
                       contact_forces=(*self.contact_forces, (SECOND_PANTOGRAPH, "contact_force")), pantographs=2)


VIRTUAL = Topology("virtual", FMU_NAMES, CONNECTIONS, {
    "/catenary": _CATENARY_GROUP,
    "/rig": {"actuator_height": "actuator height [m]", "measured_force": "measured force [N]"},
    "/pantograph": {"contact_force": "contact force [N]", "head_height": "head height [m]"},
}, (("pantograph", "contact_force"),))
HARDWARE = Topology("hardware", HARDWARE_FMU_NAMES, HARDWARE_CONNECTIONS, {
    "/catenary": _CATENARY_GROUP,
    "/adapter": {"command_sent": "height sent, within the actuator limits [m]",
                 "measured_force": "force from the rig (NaN: no answer) [N]",
                 "actuator_height": "actuator height reported by the rig [m]",
                 "link_state": "0 ok, 1 missing, 2 fault", **{c: "[-]" for c in link_client.COUNTERS},
                 **{c: f"{text} [-]" for c, text in link_client.TICK_COUNTS.items()}},
}, (("adapter", "measured_force"),), hardware=True)
PAIR = VIRTUAL.with_second_pantograph("pair")  # both virtual
HARDWARE_PAIR = HARDWARE.with_second_pantograph("hardware_pair")  # the first on the rig, the second virtual
RIG_PACED_FIELDS = {"answer_time": "rig-paced: from the sample reaching the socket to the answer [s]",
                    **{c: f"{text} [-]" for c, text in link_client.RIG_PACED_COUNTERS.items()}}


def delay_plan(case: Case, topology: Topology = VIRTUAL) -> dict:
    """D = one step per connection of the loop (+ the adapter's pipeline step) + the rig's latency
    (Paper D sec. 3.4: the advance that makes the converged result independent of the loop latency)."""
    loop = loop_latency_steps(topology.connections)
    if topology.hardware:
        loop += case.sections.link.pipeline_steps
    d = case.delay_steps(loop)
    if d >= case.samples_per_span:
        raise CaseError(_delay_refusal(case, loop, d, topology.hardware))
    return {"delay_steps": d, "loop_latency_steps": loop, "rig_latency_steps": case.rig_latency_steps(),
            "rig_compensation": "response" if case.compensates_rig_response else "delay",
            "steady_state_period_spans": case.rig_period_spans()}


def _delay_refusal(case: Case, loop: int, d: int, hardware: bool) -> str:
    """Why the advance D does not fit in a span, blamed on the key that adds the most to it."""
    rig = 0 if case.compensates_rig_response or not case.delay_compensation else case.rig_latency_steps()
    hold = case.hold_steps if case.delay_compensation else 0
    rig_key = "rig.file" if case.rig_spec is not None else "rig.delay_steps"
    terms = {"link.pipeline_steps" if hardware else "the loop": loop, "hil.hold_steps": hold, rig_key: rig}
    key = max(terms, key=terms.get)
    return (f"{key}: the delay advance D = {d} steps (loop {loop} + hold {hold} + rig {rig}) must be shorter "
            f"than a span ({case.samples_per_span} steps)")


def run_topology(case: Case, options: RunOptions) -> Topology:
    """The loop of the run (a hardware run connects only the horizon's H - 1 heights), with the rig-paced
    link's fields and, for a slackening PFEM, the dropper corrections logged."""
    pair = case.sections.second_pantograph is not None
    check_pair = getattr(catenary_model(case), "check_pair", None)
    if pair and check_pair is not None:
        check_pair(case, hardware=options.hardware is not None)
    topology = {(False, False): VIRTUAL, (False, True): PAIR, (True, False): HARDWARE,
                (True, True): HARDWARE_PAIR}[(options.hardware is not None, pair)]
    if options.hardware is not None:
        ahead = set(HORIZON_OUTPUTS[case.horizon_steps - 1:])
        topology = replace(topology, connections=tuple(c for c in topology.connections if c[1] not in ahead))
    if is_rig_paced(case, options):
        topology = replace(topology, groups={**topology.groups, "/adapter": {**topology.groups["/adapter"],
                                                                             **RIG_PACED_FIELDS}})
    droppers = catenary_model(case).dropper_positions_m(case)
    if droppers:
        extra = {f"dropper_correction_{d + 1}": f"correction force of dropper {d + 1} at this step [N]"
                 for d in range(len(droppers))}
        extra["slack_droppers"] = "droppers corrected at this step [-]"
        topology = replace(topology, groups={**topology.groups, "/catenary": {**topology.groups["/catenary"], **extra}})
    return topology
