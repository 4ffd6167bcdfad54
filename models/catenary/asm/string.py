"""Analytical string model ASM2: an infinite tensioned string on a visco-elastic support.

Governing equation (Paper A eq. 7, Paper B eq. 1):
    mu w_tt - T w_xx + (alpha mu + beta kbar) w_t - beta T (w_xx)_t + kbar w = p(x, t)
A harmonic load F0 exp(i Omega t) moving at speed v gives displacements built from the roots
(poles) of the cubic P(k) = lambda k^3 + eta k^2 + tau k + sigma (Paper A eqs. 8-9).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class AsmParameters:
    """ASM2 string data (Paper B Table 1). SI units."""

    tension_N: float
    density_kg_m: float
    support_stiffness_N_m2: float
    alpha_1_s: float
    beta_s: float

    @property
    def wave_speed_m_s(self) -> float:
        """Critical speed sqrt(T/mu) of the undamped string (Paper A sec. 3.1)."""
        return math.sqrt(self.tension_N / self.density_kg_m)

    @property
    def static_stiffness_N_m(self) -> float:
        """Static contact-point stiffness 2 sqrt(kbar T) (Paper A eq. 31)."""
        return 2.0 * math.sqrt(self.support_stiffness_N_m2 * self.tension_N)

    @property
    def viscous_damping(self) -> float:
        """The support damping term alpha mu + beta kbar of Paper A eq. (7)."""
        return self.alpha_1_s * self.density_kg_m + self.beta_s * self.support_stiffness_N_m2


def characteristic_coefficients(p: AsmParameters, omega: float, speed: float):
    """Coefficients (lambda, eta, tau, sigma) of the pole polynomial, Paper A eq. (9)."""
    T, mu, kbar, c = p.tension_N, p.density_kg_m, p.support_stiffness_N_m2, p.viscous_damping
    lam = 1j * p.beta_s * T * speed
    eta = T - mu * speed**2 + 1j * p.beta_s * T * omega
    tau = 1j * c * speed - 2.0 * mu * speed * omega
    sigma = kbar + 1j * c * omega - mu * omega**2
    return lam, eta, tau, sigma


@dataclass(frozen=True)
class Poles:
    """Poles of ASM2 at one frequency, classified by the sign of their imaginary part.

    `lower` holds the poles with negative imaginary part (k1 in Paper A), `upper` those with
    positive imaginary part, ordered by increasing |Im| (k2 then k3: k3 is the strongly damped
    wave). `derivative` maps each pole to P'(k), the residue denominator of Paper A eq. (12).
    """

    lower: tuple
    upper: tuple
    derivative: dict

    @property
    def all(self) -> tuple:
        """The three poles, those below the real axis first."""
        return self.lower + self.upper


def poles(p: AsmParameters, omega: float, speed: float) -> Poles:
    """Roots of lambda k^3 + eta k^2 + tau k + sigma (Paper A eqs. 10-11), classified (sec. 3.3)."""
    coeffs = np.array(characteristic_coefficients(p, omega, speed), dtype=complex)
    while abs(coeffs[0]) == 0.0:  # speed 0 or beta 0: the cubic degenerates
        coeffs = coeffs[1:]
    roots = np.roots(coeffs)
    dcoeffs = np.polyder(coeffs)
    deriv = {complex(k): complex(np.polyval(dcoeffs, k)) for k in roots}
    lower = tuple(sorted((complex(k) for k in roots if k.imag < 0), key=lambda k: -k.imag))
    upper = tuple(sorted((complex(k) for k in roots if k.imag > 0), key=lambda k: k.imag))
    if len(lower) + len(upper) != len(roots):
        raise ValueError(f"ASM pole on the real axis at omega={omega} rad/s, v={speed} m/s")
    return Poles(lower, upper, deriv)


def receptance_direct(p: AsmParameters, omega, speed: float):
    """Direct FRF H11 = H22 at the moving load point, Paper A eq. (17) / Paper B eq. (4).

    Evaluated by residues over the poles with negative imaginary part, which equals eq. (17)
    when exactly one such pole exists and stays valid if that ever changes.
    """
    return _vectorised(lambda w: _h_direct(p, w, speed), omega)


def receptance_ahead(p: AsmParameters, omega, speed: float, distance: float):
    """H12: response at the point `distance` ahead (x - vt = L) to the load, Paper A eq. (15)."""
    return _vectorised(lambda w: _h_ahead(p, w, speed, distance), omega)


def receptance_behind(p: AsmParameters, omega, speed: float, distance: float):
    """H21: response at the point `distance` behind (x - vt = -L) to the load, Paper A eq. (16)."""
    return _vectorised(lambda w: _h_behind(p, w, speed, distance), omega)


def _h_direct(p, omega, speed):
    pl = poles(p, omega, speed)
    return -1j * sum(1.0 / pl.derivative[k] for k in pl.lower)


def _h_ahead(p, omega, speed, distance):
    pl = poles(p, omega, speed)
    return -1j * sum(np.exp(-1j * k * distance) / pl.derivative[k] for k in pl.lower)


def _h_behind(p, omega, speed, distance):
    pl = poles(p, omega, speed)
    return 1j * sum(np.exp(1j * k * distance) / pl.derivative[k] for k in pl.upper)


def _vectorised(fn, omega):
    arr = np.asarray(omega, dtype=float)
    out = np.array([fn(float(w)) for w in arr.ravel()], dtype=complex).reshape(arr.shape)
    return out if arr.ndim else complex(out)


def wavelength_at_rest(p: AsmParameters, omega: float) -> float:
    """Wavelength -2 pi / Re(k2) of the wave radiated by a fixed harmonic load, Paper A eq. (36)."""
    pl = poles(p, omega, 0.0)
    k2 = pl.upper[0]
    return abs(2.0 * math.pi / k2.real)
