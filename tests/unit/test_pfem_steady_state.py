"""The linear steady state in one solve (models/catenary/pfem/steady_state.py): against the ASM closed form where
the operator is the string's circulant one, and against the virtual HIL's converged force on the PFEM."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import CASES_DIR as CASES
from pantohil.models.case import load_case
from pantohil.models.catenary.asm.model import closed_form_reference
from pantohil.models.catenary.pfem.operator_cache import case_operators
from pantohil.models.catenary.pfem.operator_file import load_operators
from pantohil.models.catenary.pfem.steady_state import linear_steady_state, span_frequencies_rad_s
from pantohil.models.catenary.receptance import asm_operator
from pantohil.models.hil.rig_loop import run_loop
from pantohil.models.pantograph.interface import receptance


def _solve(case, cc, z0, mean_force_N):
    w = span_frequencies_rad_s(case.samples_per_span, case.dt_s, case.n_harmonics)
    return linear_steady_state(cc, z0, receptance(case.pantograph, w), case.dt_s, mean_force_N)


@pytest.mark.parametrize("overrides", [[], ["run.speed_kmh=300"], ["pantograph.masses_kg=[7.0]",
                                                                   "pantograph.stiffnesses_N_m=[80.0]",
                                                                   "pantograph.dampings_Ns_m=[40.0]"]])
def test_a_circulant_operator_gives_paper_a_closed_form(overrides):
    """With the string's operator (circulant: H11 at each harmonic) the solve is Paper A eqs. (38)-(39) term by
    term; only rounding separates them."""
    case = load_case(None, overrides)
    op = asm_operator(case.catenary, case.speed_m_s, case.samples_per_span, case.dt_s, case.n_harmonics)
    solved = _solve(case, op.dense().T, case.z0_samples(), case.pantograph.uplift_force_N)
    reference = closed_form_reference(case)
    assert np.abs(solved.force_N - reference).max() < 1e-9 * reference.std()


@pytest.mark.slow
def test_the_pfem_solve_is_the_fixed_point_of_the_virtual_hil():
    """Paper A's stitched catenary on the PFEM, 250 km/h, 60 Hz, droppers held in tension: the HIL iteration
    converged (tolerance 1e-5) and the one solve agree within 0.5 % rms of the std (0.19 % measured; the HIL's
    pantograph is stepped by HHT, whose receptance departs from the exact one of the solve by the same order, as
    in the ASM pair's 0.09-0.15 %), with the HIL's own mean force (its static setting comes from the ASM fit)."""
    case = load_case(CASES / "pfem_stitched_250.toml", ["pfem.droppers=false", "run.convergence_tol=1e-5"])
    ops = load_operators(case_operators(case, progress=False).path)
    result = run_loop(case)
    assert result.status == "converged"
    f = result.force_N
    solved = _solve(case, ops.cc, ops.z0, float(f.mean()))
    assert np.sqrt(np.mean((solved.force_N - f) ** 2)) < 5e-3 * f.std()
    assert solved.std_N == pytest.approx(f.std(), rel=1e-3)
    assert (solved.max_N, solved.min_N) == pytest.approx((f.max(), f.min()), abs=0.01 * f.std())


def test_the_solve_refuses_an_operator_of_another_size():
    with pytest.raises(ValueError, match="cc must be 8 x 8"):
        linear_steady_state(np.zeros((7, 7)), np.zeros(8), np.ones(3, dtype=complex), 1e-3, 100.0)


@pytest.mark.parametrize("n,jd", [(12, 7), (12, 4), (11, 6), (11, 3)])
def test_the_window_rows_are_numpys_inverse_real_fft(n, jd):
    """`irfft_rows` (the dropper windows' instants from their harmonics, shared by the HIL and the steady state
    with slack droppers) against np.fft.irfft of the same harmonics, the ones above jd - 1 zero."""
    from pantohil.models.catenary.pfem.steady_state import irfft_rows

    rng = np.random.default_rng(n * jd)
    harmonics = np.zeros(n // 2 + 1, dtype=complex)
    harmonics[:jd] = rng.normal(size=jd) + 1j * rng.normal(size=jd)
    harmonics[0] = harmonics[0].real
    if n % 2 == 0:
        harmonics[-1] = harmonics[-1].real
    rows = irfft_rows(n, jd) @ np.concatenate([harmonics[:jd].real, harmonics[:jd].imag])
    assert np.allclose(rows, np.fft.irfft(harmonics, n), rtol=0, atol=1e-12)
