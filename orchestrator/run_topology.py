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
    PAIR_CONNECTIONS,
    PAIR_FMU_NAMES,
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


@dataclass(frozen=True)
class Topology:
    """A co-simulation system: its FMUs, connections and the MCAP groups logged."""
    name: str
    fmus: tuple
    connections: tuple
    groups: dict  # MCAP topic -> {signal: description}; topic "/x" logs FMU x
    contact_forces: tuple  # (FMU, output) of each contact force: a span of zeros in one is a lost contact


VIRTUAL = Topology("virtual", FMU_NAMES, CONNECTIONS, {
    "/catenary": _CATENARY_GROUP,
    "/rig": {"actuator_height": "actuator height [m]", "measured_force": "measured force [N]"},
    "/pantograph": {"contact_force": "contact force [N]", "head_height": "head height [m]"},
}, (("pantograph", "contact_force"),))
# Two pantographs, both virtual (Paper A sec. 3.4): the second an instance of the pantograph FMU at the catenary's
# second contact point (models/hil/pair.py)
PAIR = Topology("pair", PAIR_FMU_NAMES, PAIR_CONNECTIONS, {
    "/catenary": {**_CATENARY_GROUP, "height_command_2": "commanded height at the second contact point [m]",
                  "contact_force_2": "force received from the second pantograph [N]",
                  "force_at_sample_2": "force in use at the second point's sample [N]",
                  "height_at_sample_2": "converging height at the second point's sample [m]",
                  "profile_at_sample_2": "static height z0 at the second point's sample [m]"},
    **{g: VIRTUAL.groups[g] for g in ("/rig", "/pantograph")},
    "/pantograph_2": {"contact_force": "second pantograph's contact force [N]",
                      "head_height": "second pantograph's head height [m]"},
}, (("pantograph", "contact_force"), ("pantograph_2", "contact_force")))
HARDWARE = Topology("hardware", HARDWARE_FMU_NAMES, HARDWARE_CONNECTIONS, {
    "/catenary": _CATENARY_GROUP,
    "/adapter": {"command_sent": "height sent, within the actuator limits [m]",
                 "measured_force": "force from the rig (NaN: no answer) [N]",
                 "actuator_height": "actuator height reported by the rig [m]",
                 "link_state": "0 ok, 1 missing, 2 fault", **{c: "[-]" for c in link_client.COUNTERS},
                 **{c: f"{text} [-]" for c, text in link_client.TICK_COUNTS.items()}},
}, (("adapter", "measured_force"),))
RIG_PACED_FIELDS = {"answer_time": "rig-paced: from the sample reaching the socket to the answer [s]",
                    **{c: f"{text} [-]" for c, text in link_client.RIG_PACED_COUNTERS.items()}}


def delay_plan(case: Case, topology: Topology = VIRTUAL) -> dict:
    """D = one step per connection of the loop (+ the adapter's pipeline step) + the rig's latency
    (Paper D sec. 3.4: the advance that makes the converged result independent of the loop latency)."""
    loop = loop_latency_steps(topology.connections)
    if topology.name == HARDWARE.name:
        loop += case.sections.link.pipeline_steps
    d = case.delay_steps(loop)
    if d >= case.samples_per_span:
        raise CaseError(_delay_refusal(case, loop, d, topology.name == HARDWARE.name))
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
    if case.sections.second_pantograph is not None:  # virtual only (run_options.check_options)
        return PAIR
    topology = HARDWARE if options.hardware is not None else VIRTUAL
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
