"""The HIL system's topology: which FMU output feeds which input, and the loop latency it implies.

Under Jacobi stepping (fmpy master here, libcosim) every connection delays a signal by one step, so
a loop of C connections through the catenary makes the height reach the pantograph C steps after
the force it answers was measured there: the catenary's delay advance must include C (Paper D sec. 3.4).
"""
from __future__ import annotations

from pantohil.models.hil.loop import MAX_HORIZON_STEPS

FMU_NAMES = ("catenary", "rig", "pantograph")
HARDWARE_FMU_NAMES = ("catenary", "adapter")

CONNECTIONS = (
    ("catenary", "height_command", "rig", "height_command"),
    ("rig", "actuator_height", "pantograph", "height"),
    ("pantograph", "contact_force", "rig", "true_force"),
    ("rig", "measured_force", "catenary", "contact_force"),
)

# Two pantographs, both virtual: a second instance of the pantograph FMU at the catenary's second contact point,
# 2 connections on its loop (models/hil/pair_loop.py)
SECOND_PANTOGRAPH = "pantograph_2"
SECOND_PANTOGRAPH_CONNECTIONS = (
    ("catenary", "height_command_2", SECOND_PANTOGRAPH, "height"),
    (SECOND_PANTOGRAPH, "contact_force", "catenary", "contact_force_2"),
)
PAIR_FMU_NAMES = (*FMU_NAMES, SECOND_PANTOGRAPH)
PAIR_CONNECTIONS = (*CONNECTIONS, *SECOND_PANTOGRAPH_CONNECTIONS)



def system_components(fmus: dict, two_pantographs: bool) -> tuple[dict, tuple]:
    """The virtual HIL's components (component -> FMU file, from the built `fmus` by name) and connections:
    with two pantographs the second is a second instance of the pantograph FMU."""
    components = {n: fmus[n] for n in FMU_NAMES}
    if not two_pantographs:
        return components, CONNECTIONS
    return with_second_pantograph(components, fmus), PAIR_CONNECTIONS


def with_second_pantograph(components: dict, fmus: dict) -> dict:
    """`components` and the second pantograph, an instance of the built pantograph FMU (`fmus["pantograph"]`)."""
    return {**components, SECOND_PANTOGRAPH: fmus["pantograph"]}


# The catenary's horizon: the heights its next steps command as the iterate stands (docs/udp-protocol.md)
HORIZON_OUTPUTS = tuple(f"height_ahead_{i}" for i in range(1, MAX_HORIZON_STEPS))

# On a real rig (or the rig emulator) the adapter stands for rig and pantograph: 2 connections on the
# loop, and the horizon from the catenary to the adapter beside it.
HARDWARE_CONNECTIONS = (
    ("catenary", "height_command", "adapter", "height_command"),
    ("adapter", "measured_force", "catenary", "contact_force"),
    *(("catenary", name, "adapter", name) for name in HORIZON_OUTPUTS),
)


def loop_latency_steps(connections=CONNECTIONS, start: str = "catenary") -> int:
    """Connections on the cycle that leaves and returns to `start` (each is one step of latency)."""
    # the rig appears twice on the cycle (height path, force path): follow edges, not nodes
    edges = list(connections)
    path, node, used = 0, start, set()
    while True:
        nxt = next((i for i, e in enumerate(edges) if e[0] == node and i not in used), None)
        if nxt is None:
            raise ValueError(f"no loop through {start!r} in the connections")
        used.add(nxt)
        path += 1
        node = edges[nxt][2]
        if node == start:
            return path
