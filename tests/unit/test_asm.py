"""ASM2 (Paper A secs. 3-4): printed numbers, pole classification, and the FRF checked against an
independent evaluation of the wavenumber integral of Paper A eq. (8)."""
import math

import numpy as np
import pytest
from scipy import integrate

from pantohil.models.catenary.asm.string import (AsmParameters, characteristic_coefficients, poles, receptance_ahead,
                                 receptance_behind, receptance_direct, wavelength_at_rest)

TABLE1 = AsmParameters(tension_N=31500.0, density_kg_m=1.4735, support_stiffness_N_m2=51.15,
                       alpha_1_s=0.0125, beta_s=1e-4)


def test_static_stiffness_matches_paper_a_eq31():
    # Paper A eq. (31): k_z = 2 sqrt(kbar T) = 2538.68 N/m (NOTES.md)
    assert TABLE1.static_stiffness_N_m == pytest.approx(2538.68, abs=0.01)
    assert 1.0 / receptance_direct(TABLE1, 0.0, 0.0).real == pytest.approx(2538.68, abs=0.01)


def test_wave_speed():
    assert TABLE1.wave_speed_m_s == pytest.approx(146.2, abs=0.05)


@pytest.mark.parametrize("speed_kmh", [50, 150, 200, 250, 300, 350, 400])
@pytest.mark.parametrize("freq_hz", [0.5, 2, 5, 10, 20, 40])
def test_exactly_one_pole_below_the_real_axis(speed_kmh, freq_hz):
    # Paper A sec. 3.3: in the range of interest only k1 has a negative imaginary part
    pl = poles(TABLE1, 2 * math.pi * freq_hz, speed_kmh / 3.6)
    assert len(pl.lower) == 1 and len(pl.upper) == 2


def test_direct_frf_is_hermitian_and_real_at_zero_frequency():
    v = 250 / 3.6
    h0 = receptance_direct(TABLE1, 0.0, v)
    assert abs(h0.imag) < 1e-12 * abs(h0.real)
    for w in (3.0, 30.0, 150.0):
        assert receptance_direct(TABLE1, -w, v) == pytest.approx(np.conj(receptance_direct(TABLE1, w, v)), rel=1e-9)


def _wavenumber_integral(p, omega, speed, offset):
    """w(x - vt = offset) / F0 = (1/2 pi) int exp(-i k offset) / P(k) dk, Paper A eq. (8), by quadrature."""
    lam, eta, tau, sigma = characteristic_coefficients(p, omega, speed)
    def P(k):
        return lam * k**3 + eta * k**2 + tau * k + sigma
    def f(k):
        return np.exp(-1j * k * offset) / P(k)
    kmax = 2000.0
    re = integrate.quad(lambda k: f(k).real, -kmax, kmax, limit=4000, points=[-0.5, -0.2, 0, 0.2, 0.5])[0]
    im = integrate.quad(lambda k: f(k).imag, -kmax, kmax, limit=4000, points=[-0.5, -0.2, 0, 0.2, 0.5])[0]
    return (re + 1j * im) / (2 * math.pi)


@pytest.mark.parametrize("freq_hz,speed_kmh", [(2.0, 250), (10.0, 250), (10.0, 300), (20.0, 200)])
def test_residue_frfs_match_direct_quadrature(freq_hz, speed_kmh):
    w, v = 2 * math.pi * freq_hz, speed_kmh / 3.6
    h11 = receptance_direct(TABLE1, w, v)
    assert h11 == pytest.approx(_wavenumber_integral(TABLE1, w, v, 0.0), rel=2e-3)
    # H12: 20 m ahead (x - vt > 0); H21: 20 m behind (x - vt < 0), Paper A eqs. (15)-(16)
    assert receptance_ahead(TABLE1, w, v, 20.0) == pytest.approx(
        _wavenumber_integral(TABLE1, w, v, 20.0), rel=5e-3, abs=1e-9
    )
    assert receptance_behind(TABLE1, w, v, 20.0) == pytest.approx(
        _wavenumber_integral(TABLE1, w, v, -20.0), rel=5e-3, abs=1e-9
    )


def test_wavelength_at_rest_is_that_of_the_undamped_string_at_high_frequency():
    # well above the support's cut-off the wave is a string wave: lambda = 2 pi sqrt(T/mu) / omega
    w = 2 * math.pi * 30.0
    assert wavelength_at_rest(TABLE1, w) == pytest.approx(2 * math.pi * TABLE1.wave_speed_m_s / w, rel=0.02)
