"""The periodic HIL iteration in-process (Paper D sec. 3) against the closed form (Paper A eqs. 38-41).

The loop here has the minimal latency of the thesis (force at sample n -> height at n + 1) plus a pure
delay; the FMU runs in test_cli_run.py add the master's own latency."""
import math
from collections import deque

import numpy as np
import pytest

from pantohil.models.case import load_case
from pantohil.models.hil.loop import ConvergenceMonitor, HilSettings, PeriodicHil
from pantohil.models.pantograph.interface import make_pantograph
from pantohil.models.catenary.receptance import CirculantOperator, asm_operator, reduce_harmonics
from pantohil.models.catenary.asm.model import closed_form_reference


def run_loop(case, latency, max_spans=400, tol=1e-4, settings=None):
    n, dt = case.samples_per_span, case.dt_s
    op = asm_operator(case.catenary, case.speed_m_s, n, dt, case.n_harmonics)
    hil = PeriodicHil(op, reduce_harmonics(case.z0_samples(), case.n_harmonics), settings or case.hil_settings(latency))
    pan = make_pantograph(case.pantograph, dt, case.reference_height_m())
    f = pan.settle(0.0)
    wire = deque([0.0] * (latency - 1))
    mon, span_f = ConvergenceMonitor(n), np.zeros(n)
    for _ in range(max_spans * n):
        label = hil.sample
        span_f[label] = f
        wire.append(hil.step(f))
        f = pan.step(wire.popleft())
        if label == n - 1:
            rec = mon.close_span(hil.span - 1, span_f)
            if rec["change"] <= tol:
                return span_f, mon
    return span_f, mon


def rel_error(f, ref):
    return np.sqrt(np.mean(((f - f.mean()) - (ref - ref.mean())) ** 2)) / ref.std()


@pytest.mark.parametrize("overrides,latency", [
    ([], 1),                                            # step-by-step, 25 Hz, no delay
    (["rig.delay_steps=4"], 5),                          # with a delay, compensated
    (['hil.update="span"', "hil.max_frequency_hz=10", "hil.relaxation=0.3"], 9),
])
def test_virtual_hil_converges_to_the_closed_form(overrides, latency):
    case = load_case(None, overrides)
    f, mon = run_loop(case, latency)
    assert mon.history[-1]["change"] <= 1e-4
    assert rel_error(f, closed_form_reference(case)) < 5e-3
    assert f.mean() == pytest.approx(case.pantograph.uplift_force_N, rel=1e-3)


def test_uncompensated_delay_changes_the_result():
    case = load_case()
    # the pantograph sees each height 5 samples late, but the catenary advances it by 1 only
    n = case.samples_per_span
    settings = case.hil_settings(1)
    op = asm_operator(case.catenary, case.speed_m_s, n, case.dt_s, case.n_harmonics)
    hil = PeriodicHil(op, reduce_harmonics(case.z0_samples(), case.n_harmonics), settings)
    pan = make_pantograph(case.pantograph, case.dt_s, case.reference_height_m())
    f, wire, span_f = pan.settle(0.0), deque([0.0] * 4), np.zeros(n)
    for _ in range(150 * n):
        span_f[hil.sample] = f
        wire.append(hil.step(f))
        f = pan.step(wire.popleft())
    assert rel_error(span_f, closed_form_reference(case)) > 0.05


def test_span_by_span_blends_the_last_two_blocks():
    z0 = np.zeros(4)

    class Zero:
        def column(self, m):
            return np.zeros(4)

        def apply(self, f):
            return np.asarray(f, dtype=float)  # I = identity: z^b = mu f^b + (1 - mu) z^(b-1)

    hil = PeriodicHil(Zero(), z0, HilSettings("span", 1.0, 0, 0))
    out = [hil.step(1.0) for _ in range(4)]  # block 0: blends z0 and z0
    assert out == [0.0, 0.0, 0.0, 0.0]
    out = [hil.step(1.0) for _ in range(4)]  # block 1: from z^(-1) = z0 towards z^0 = 1 (Paper D eq. 3)
    assert out == pytest.approx([0.25, 0.5, 0.75, 1.0])


@pytest.mark.parametrize("update", ["step", "span"])
@pytest.mark.parametrize("hold_steps", [0, 3])
@pytest.mark.parametrize("ramp_steps", [0, 80])
@pytest.mark.parametrize("start", [0, 37, 45])
def test_the_horizon_is_what_the_next_steps_command_while_the_iterate_stands(update, hold_steps, ramp_steps, start):
    """PeriodicHil.ahead: with the iterate standing (forces not measured within a block; the fixed point of
    zero force across blocks) the next steps return exactly the predicted commands: the heights a late
    answer leaves the rig (docs/udp-protocol.md, "The horizon")."""
    rng = np.random.default_rng(1)
    n = 50
    op = CirculantOperator(rng.normal(size=n) * 1e-4)
    z0 = rng.normal(size=n) * 0.01
    hil = PeriodicHil(op, z0, HilSettings(update=update, relaxation=0.3, delay_steps=4, ramp_steps=ramp_steps,
                                          hold_steps=hold_steps))
    crosses = update == "span" and start == 45
    for _ in range(start):
        hil.step(0.0 if crosses else 100 + rng.normal())
    count = 70 if crosses else 10 if update == "span" else 60
    predicted = hil.ahead(count)
    taken = [hil.step(0.0 if crosses else math.nan) for _ in range(count)]
    np.testing.assert_allclose(predicted, taken, rtol=0, atol=1e-15)
