"""Paper D sec. 4's stability statements (Figs. 5-7) on the stitched PFEM with the 1-DOF pantograph
(`paper_d_stability_stitched`: 6.6 kg, 7000 N/m, 10 N s/m; 250 km/h, dt = 2 ms), the best mu_c at every
point. The whole maps (20 f_max x 9 k_c, and D = 1..34) are in docs/validation.md; these are their
statements at points chosen from the contact natural frequency f_c = sqrt((k_1 + k_c) / m_1) / 2 pi, not from
the maps."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from pantohil.models.case import load_case
from pantohil.orchestrator.stability_run import stability_row

CASE = Path(__file__).resolve().parents[2] / "models" / "data" / "cases" / "paper_d_stability_stitched.toml"
CASE_DELAY = 8  # D of the case: 4 connections of the master and the rig's 4 steps

pytestmark = pytest.mark.slow


def _radii(update: str, f_max_hz: float, contact_stiffness_N_m: list[float], delay: int = CASE_DELAY) -> list[float]:
    rows = stability_row({"case": str(CASE), "overrides": [], "update": update, "f_max_hz": f_max_hz,
                          "contact_stiffness_N_m": contact_stiffness_N_m, "delay_steps": delay,
                          "latency_steps": delay, "relaxation": None})
    return [r["spectral_radius"] for r in rows]


def _contact_frequency_hz(kc: float) -> float:
    pan = load_case(CASE).pantograph
    return math.sqrt((pan.stiffnesses_N_m[0] + kc) / pan.masses_kg[0]) / (2 * math.pi)


def test_span_by_span_is_stable_over_more_of_the_map_than_step_by_step():
    """Figs. 5 and 6: on a 3 x 3 grid spanning the map, more points are stable span-by-span."""
    stiffness = [1e4, 1e5, 5.6e5]
    stable = {"span": 0, "step": 0}
    for update in stable:
        for f_max in (6.0, 20.0, 34.0):
            stable[update] += sum(rho < 1 for rho in _radii(update, f_max, stiffness))
    assert stable["span"] > stable["step"], stable


@pytest.mark.parametrize("kc", [1e5, 3.16e5])
def test_span_by_span_is_unstable_just_above_the_contact_frequency(kc):
    """Fig. 5: for k_c of 1e5 N/m and more, f_max at 0.9 f_c converges and at 1.1 f_c diverges."""
    f_c = _contact_frequency_hz(kc)
    below, = _radii("span", 0.9 * f_c, [kc])
    above, = _radii("span", 1.1 * f_c, [kc])
    assert below < 1 < above, (f_c, below, above)


def test_step_by_step_over_the_delay_is_periodic_in_the_contact_period():
    """Fig. 7: step-by-step at k_c = 6e5 N/m over D is unstable around D = 6 and every contact period
    1 / (f_c dt) steps after it (about 10.4 steps), and stable half a period away from those."""
    kc, dt = 6e5, load_case(CASE).dt_s
    period = 1.0 / (_contact_frequency_hz(kc) * dt)
    for k in range(3):
        peak = round(6 + k * period)
        trough = round(6 + (k + 0.5) * period)
        rho_peak, = _radii("step", 40.0, [kc], peak)
        rho_trough, = _radii("step", 40.0, [kc], trough)
        assert rho_peak > 1 > rho_trough, (k, peak, rho_peak, trough, rho_trough)
