"""Stability of the virtual HIL iteration (Paper D sec. 4, appendix): the spectral radius of the linear
span-to-span map against simulated runs of the same loop, and the fast constructions against the dense one."""
import numpy as np
import pytest

from pantohil.models.case import load_case
from pantohil.models.hil.loop import HilSettings
from pantohil.models.pantograph.interface import linear_pantograph
from pantohil.models.pantograph.lumped import PantographParameters, RigidMass
from pantohil.models.catenary.receptance import asm_operator, harmonic_count
from pantohil.models.stability.maps import (
    circulant_dense,
    circulant_range_basis,
    range_basis,
    reduced_span_map,
    span_map,
    step_matrix,
)
from pantohil.models.stability.map_point import RELAXATION_GRID, best_relaxation, problem_for, with_contact_stiffness
from pantohil.models.stability.step_roots import step_loop, step_spectral_radius
from test_hil_loop import run_loop


def operator(case, f_max=None):
    nh = case.n_harmonics if f_max is None else harmonic_count(f_max, case.samples_per_span, case.dt_s)
    return asm_operator(case.catenary, case.speed_m_s, case.samples_per_span, case.dt_s, nh)


def radius(overrides, latency):
    c = load_case(None, overrides)
    op = operator(c)
    lin = linear_pantograph(c.pantograph, c.dt_s)
    return span_map(circulant_dense(op.kernel), lin, c.hil_settings(latency), latency).spectral_radius, c


def test_step_by_step_prediction_meets_simulation():
    # default case (25 Hz): stable with a loop latency of 8 steps, unstable with 12 (docs/method.md)
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


@pytest.mark.parametrize("f_max,kc,latency,mu", [(25, 5e4, 8, 0.1), (10, 2e5, 1, 0.3), (15, 6e5, 12, 0.05),
                                                 (40, 1e4, 3, 0.7)])
def test_fast_constructions_equal_the_dense_span_map(f_max, kc, latency, mu):
    """Reduced span map and characteristic roots against A built by running the loop on unit states."""
    case = load_case(None, [])
    pan = linear_pantograph(with_contact_stiffness(case.pantograph, kc), case.dt_s)
    kernel = operator(case, f_max).kernel
    dense = circulant_dense(kernel)
    for update in ("span", "step"):
        s = HilSettings(update, mu, latency)
        ref = span_map(dense, pan, s, latency).spectral_radius
        if update == "span":
            fast = [reduced_span_map(dense, pan, s, latency, circulant_range_basis(kernel)).spectral_radius,
                    reduced_span_map(dense, pan, s, latency, range_basis(dense)).spectral_radius]
        else:
            fast = [step_matrix(kernel, pan, s, latency).spectral_radius,
                    step_spectral_radius(step_loop(kernel, pan, latency, latency), mu)]
        for value in fast:
            assert value == pytest.approx(ref, rel=1e-7)


def test_the_rigid_mass_step_map_is_its_time_integrator():
    params = PantographParameters((5.29,), (0.0,), (0.0,), 1.0, 0.0, "rigid_mass", 0.0)
    dt = 1e-3
    lin = linear_pantograph(params, dt)
    rm = RigidMass(params, dt)
    rm.settle(0.0)
    x, f = np.zeros(3), 0.0
    rng = np.random.default_rng(1)
    for z in rng.normal(0, 1e-3, 200):
        expected = rm.step(z)
        x = lin.Pp @ x + lin.pz * z + lin.pf * f
        f = lin.c @ x + lin.cz * z
        assert f == pytest.approx(expected, rel=1e-9, abs=1e-9)


def test_the_best_relaxation_beats_every_grid_value():
    case = load_case(None, [])
    pb = problem_for("step", case.pantograph, case.dt_s, 8, 8, kernel=operator(case).kernel)
    mu, rho = best_relaxation(pb)
    assert 0 < mu < 1
    assert rho <= min(pb.spectral_radius(m) for m in RELAXATION_GRID) + 1e-12
    assert rho == pytest.approx(pb.spectral_radius(mu), rel=1e-9)


@pytest.mark.parametrize("kc", [5e4, 1e5, 2e5])
def test_the_span_map_has_a_barrier_at_the_contact_frequency(kc):
    """Paper D Fig. 5: span-by-span, whatever the relaxation, stable with f_max below the head's
    contact natural frequency, unstable just above it."""
    case = load_case(None, [])
    pan = with_contact_stiffness(case.pantograph, kc)
    fc = np.sqrt((pan.stiffnesses_N_m[0] + kc) / pan.masses_kg[0]) / (2 * np.pi)
    best = {}
    for factor in (0.85, 1.05):
        pb = problem_for("span", pan, case.dt_s, 8, 8, kernel=operator(case, factor * fc).kernel)
        best[factor] = best_relaxation(pb)[1]
    assert best[0.85] < 1.0 and best[1.05] > 1.15, best


def test_queued_rank_one_updates_are_the_per_step_updates():
    """QueuedRankOne (the step-by-step maps' updates of every unit state, applied a block at a time) against the
    rank-one update at every step on random operators of two points: every row read between and the final X
    equal to rounding (1e-12 of the largest entry), over more steps than a block and a partial last block."""
    from pantohil.models.stability.maps import QueuedRankOne

    rng = np.random.default_rng(7)
    n, dim, points = 50, 12, 2
    C = [[rng.standard_normal((n, n)) for _ in range(points)] for _ in range(points)]
    X0 = rng.standard_normal((points, n, dim))
    queued, plain = QueuedRankOne(X0.copy(), C), X0.copy()
    worst = 0.0
    for m in rng.permutation(n)[:45]:
        queued.open(int(m))
        for j in range(points):
            delta = rng.standard_normal(dim)
            queued.set(j, delta)
            for i in range(points):
                plain[i] += np.outer(C[i][j][:, m], delta)
        r = int(rng.integers(n))
        worst = max(worst, *(np.max(np.abs(queued.row(i, r) - plain[i, r])) for i in range(points)))
    queued.flush()
    worst = max(worst, np.max(np.abs(queued.X - plain)))
    assert worst < 1e-12 * np.max(np.abs(plain))
