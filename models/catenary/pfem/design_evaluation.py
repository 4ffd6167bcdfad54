"""One catenary design evaluated by its PFEM steady state (issue 34): form-found, its contact operator built
(the contact point's only: no dropper windows, the droppers held in tension) at each speed, and the linear
pantograph's steady force solved in one step (steady_state.py). What an optimiser minimises: the contact
force's standard deviation (EN 50367's quality indicator, over the harmonics the settings keep, 0-20 Hz
for `pantohil optimise`), over several speeds the root of the weighted mean variance; with its max and min,
and the shortest dropper.

A design that cannot be built (a dropper in compression or of no length: form-finding's one line) is returned
as infeasible with that line, not raised: the optimiser steps away from it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from pantohil.models.catenary.fe.definition import CatenaryError, build_definition
from pantohil.models.catenary.fe.model import form_find
from pantohil.models.catenary.pfem.blocks import periodic_block
from pantohil.models.catenary.pfem.operator_data import PfemSettings
from pantohil.models.catenary.pfem.operators import build_operators
from pantohil.models.catenary.pfem.steady_state import linear_steady_state


@dataclass(frozen=True)
class SpeedPoint:
    """One speed of the objective: the operators' settings at it, the pantograph's receptance at the span's
    harmonics 1..N_h-1, the mean force (EN 50367's at that speed) and the speed's weight."""

    speed_kmh: float
    settings: PfemSettings
    receptance_m_N: np.ndarray
    mean_force_N: float
    weight: float = 1.0


def contact_block(cat, samples_per_span: int):
    """The PFEM block of `cat` with the contact point's functional only (no dropper correction windows)."""
    return replace(periodic_block(cat, samples_per_span), dropper_x_m=None)


def evaluate_design(raw: dict, points: list[SpeedPoint], min_dropper_length_m: float = 0.0,
                    keep_force: bool = False) -> dict:
    """The design's objective (the std; over several speeds the root of the weighted mean variance), each
    speed's std, max and min [N], the shortest dropper [m] and, with `keep_force`, each speed's force over the
    span; or `feasible` False with the reason."""
    t0 = time.perf_counter()
    try:
        cat = build_definition(raw)
        ff = form_find(cat, 3)
    except CatenaryError as exc:
        return {"feasible": False, "reason": str(exc), "seconds": time.perf_counter() - t0}
    shortest = float(ff.dropper_lengths_m.min())
    if shortest < min_dropper_length_m:
        return {"feasible": False, "seconds": time.perf_counter() - t0, "shortest_dropper_m": shortest,
                "reason": f"a dropper of {shortest:.3f} m, below min_dropper_length_m = {min_dropper_length_m:g} m"}
    speeds = []
    for p in points:
        ops = build_operators(contact_block(cat, p.settings.samples_per_span), p.settings)
        ss = linear_steady_state(ops.cc, ops.z0, p.receptance_m_N, p.settings.dt_s, p.mean_force_N)
        row = {"speed_kmh": p.speed_kmh, "std_N": ss.std_N, "max_N": ss.max_N, "min_N": ss.min_N}
        if keep_force:
            row["force_N"] = ss.force_N.tolist()
        speeds.append(row)
    weights = np.array([p.weight for p in points], dtype=float)
    objective = float(np.sqrt(np.dot(weights, [s["std_N"] ** 2 for s in speeds]) / weights.sum()))
    return {"feasible": True, "objective_N": objective, "speeds": speeds, "shortest_dropper_m": shortest,
            "dropper_tensions_min_N": float(ff.dropper_tensions_N.min()), "seconds": time.perf_counter() - t0}
