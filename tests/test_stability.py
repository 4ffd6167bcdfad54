"""Stability of the virtual HIL iteration (Paper D sec. 4, appendix): the spectral radius of the linear
span-to-span map against simulated runs of the same loop."""
import numpy as np
import pytest

from pantohil.models.case import load_case
from pantohil.models.receptance import asm_operator
from pantohil.models.stability import span_map
from test_hil_loop import run_loop


def radius(overrides, latency):
    c = load_case(None, overrides)
    op = asm_operator(c.catenary, c.speed_m_s, c.samples_per_span, c.dt_s, c.n_harmonics)
    return span_map(op.kernel, c.pantograph, c.dt_s, c.hil_settings(latency), latency).spectral_radius, c


def test_step_by_step_prediction_meets_simulation():
    # default case (25 Hz): stable with a loop latency of 8 steps, unstable with 12 (see the README)
    rho8, case = radius([], 8)
    rho12, _ = radius([], 12)
    assert rho8 < 0.95 and rho12 > 1.05
    f, mon = run_loop(case, 8, max_spans=200)
    assert mon.history[-1]["change"] <= 1e-4
    _, mon12 = run_loop(case, 12, max_spans=60)
    assert mon12.history[-1]["change"] > 0.1


def test_the_convergence_rate_follows_the_spectral_radius():
    rho, case = radius([], 5)
    _, mon = run_loop(case, 5, max_spans=200)
    change = np.array([h["change"] for h in mon.history])
    rate = (change[-1] / change[-21]) ** (1 / 20)  # the last 20 spans, in the asymptotic regime
    assert rate == pytest.approx(rho, rel=0.05)


def test_span_by_span_is_delay_independent_and_bounded_by_the_contact_frequency():
    # Paper D sec. 4: span-by-span does not depend on the delay, and f_max above the pantograph's
    # contact frequency (14.8 Hz here) is a barrier
    low8, _ = radius(['hil.update="span"', "hil.max_frequency_hz=10"], 8)
    low12, case = radius(['hil.update="span"', "hil.max_frequency_hz=10"], 12)
    high, _ = radius(['hil.update="span"', "hil.max_frequency_hz=25"], 8)
    assert case.pantograph.contact_frequency_hz() == pytest.approx(14.8, abs=0.1)
    assert low8 < 1 and low8 == pytest.approx(low12, abs=1e-3)
    assert high > 1.05
