"""One catenary design evaluated by its PFEM steady state (issue 34): form-found, its operators built with the
droppers' windows at each speed (the case's own f_max), and the linear pantograph's steady force solved with
dropper slackening (slack_steady_state.py: one linear solve when no dropper slackens, a few when some do). What
an optimiser minimises: the contact force's standard deviation low-passed at 20 Hz (EN 50367's quality
indicator, the filter `pantohil run` and `pantohil fem-sim` report with), over several speeds the root of the
weighted mean variance; with its max and min, the slack droppers and the shortest dropper.

A design that cannot be built (a dropper in compression or of no length: form-finding's one line) or whose
steady state loses contact is returned as infeasible with that line, not raised: the optimiser steps away from
it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from pantohil.models.catenary.fe.definition import CatenaryError, build_definition
from pantohil.models.catenary.fe.model import form_find
from pantohil.models.catenary.pfem.blocks import periodic_block
from pantohil.models.catenary.pfem.operator_data import PfemSettings
from pantohil.models.catenary.pfem.operators import build_operators
from pantohil.models.catenary.pfem.slack_steady_state import SlackSteadyStateError, slack_steady_state
from pantohil.models.metrics import lowpass_periodic

QUALITY_BAND_HZ = 20.0  # EN 50367's contact-force statistics: 0-20 Hz


@dataclass(frozen=True)
class SpeedPoint:
    """One speed of the objective: the operators' settings at it, the pantograph's receptance at the span's
    harmonics 1..N_h-1, the mean force (EN 50367's at that speed), the speed's weight and the band the force's
    statistics are taken in."""

    speed_kmh: float
    settings: PfemSettings
    receptance_m_N: np.ndarray
    mean_force_N: float
    weight: float = 1.0
    band_hz: float = QUALITY_BAND_HZ


def _infeasible(reason: str, t0: float, **extra) -> dict:
    return {"feasible": False, "reason": reason, "seconds": time.perf_counter() - t0, **extra}


def evaluate_design(raw: dict, points: list[SpeedPoint], min_dropper_length_m: float = 0.0,
                    keep_force: bool = False) -> dict:
    """The design's objective (the std; over several speeds the root of the weighted mean variance), each
    speed's std, max and min [N] in its band and its slack (dropper, instant) pairs, the shortest dropper [m]
    and, with `keep_force`, each speed's band-limited force over the span; or `feasible` False with the reason."""
    t0 = time.perf_counter()
    try:
        cat = build_definition(raw)
        ff = form_find(cat, 3)
    except CatenaryError as exc:
        return _infeasible(str(exc), t0)
    shortest = float(ff.dropper_lengths_m.min())
    if shortest < min_dropper_length_m:
        return _infeasible(f"a dropper of {shortest:.3f} m, below min_dropper_length_m = {min_dropper_length_m:g} m",
                           t0, shortest_dropper_m=shortest)
    speeds = []
    for p in points:
        ops = build_operators(periodic_block(cat, p.settings.samples_per_span), p.settings)
        try:
            ss = slack_steady_state(ops, p.receptance_m_N, p.mean_force_N)
        except SlackSteadyStateError as exc:
            return _infeasible(f"at {p.speed_kmh:g} km/h: {exc}", t0, shortest_dropper_m=shortest)
        if ss.min_N <= 0.0:
            return _infeasible(f"at {p.speed_kmh:g} km/h the pantograph loses contact (force {ss.min_N:.1f} N)", t0,
                               shortest_dropper_m=shortest)
        f = lowpass_periodic(ss.force_N, p.settings.dt_s, p.band_hz)
        row = {"speed_kmh": p.speed_kmh, "std_N": float(f.std()), "max_N": float(f.max()), "min_N": float(f.min()),
               "slack_pairs": ss.slack_pairs}
        if keep_force:
            row["force_N"] = f.tolist()
        speeds.append(row)
    weights = np.array([p.weight for p in points], dtype=float)
    objective = float(np.sqrt(np.dot(weights, [s["std_N"] ** 2 for s in speeds]) / weights.sum())) if points else 0.0
    return {"feasible": True, "objective_N": objective, "speeds": speeds, "shortest_dropper_m": shortest,
            "dropper_tensions_min_N": float(ff.dropper_tensions_N.min()), "seconds": time.perf_counter() - t0}
