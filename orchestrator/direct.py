"""`pantohil direct`: the closed-form ASM steady state of a case (Paper A secs. 5.2-5.4)."""
from __future__ import annotations

import numpy as np

from pantohil.models.case import Case
from pantohil.models.catenary.asm.closed_form import (one_sided_harmonics, optimal_spacings, single_pantograph,
    two_pantographs)


def direct_solution(case: Case, second_at_m: float | None = None, max_spacing_m: float = 200.0) -> dict:
    """Closed-form ASM2 steady state of a case (Paper A eqs. 38-41), with a trailing pantograph if asked.

    With `second_at_m`, the trailing pantograph's std at that spacing and its optimal spacings L_min up to
    `max_spacing_m` (Paper A eqs. 42-45).
    """
    z0 = case.z0_samples()
    amps = one_sided_harmonics(z0)
    args = (case.catenary, case.pantograph, case.speed_m_s, case.span_m, amps, case.pantograph.uplift_force_N,
            case.n_harmonics)
    single = single_pantograph(*args)
    out = {
        "case": case.name, "speed_kmh": case.speed_kmh, "harmonics": case.n_harmonics,
        "max_frequency_hz": float(single.frequencies_hz[-1]),
        "single": {"mean_N": case.pantograph.uplift_force_N, "std_N": single.std_N(),
                   "std_20hz_N": single.std_N(20.0)},
    }
    if second_at_m is not None:
        lead, trail = two_pantographs(*args, spacing_m=second_at_m)
        order = np.argsort(-np.abs(amps[1:case.n_harmonics])) + 1
        out["two_pantographs"] = {
            "spacing_m": second_at_m,
            "leading_std_N": lead.std_N(), "trailing_std_N": trail.std_N(),
            "trailing_std_20hz_N": trail.std_N(20.0),
            "optimal_spacings_m": [
                {"harmonic": int(h), "frequency_hz": float(single.frequencies_hz[h]),
                 "z0_amplitude_m": float(abs(amps[h])),
                 "L_min_m": optimal_spacings(case.catenary, case.pantograph, case.speed_m_s,
                                             2 * np.pi * single.frequencies_hz[h], max_spacing_m)}
                for h in order[:5]
            ],
        }
    return out
