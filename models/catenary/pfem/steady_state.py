"""The periodic steady state of a linear pantograph on the PFEM in one linear solve, without the HIL iteration:
the fixed point the virtual HIL converges to when the pantograph stays in contact and no dropper slackens.

At that fixed point the contact-wire height at the contact point is z = z0 + I_cc f (Paper D eq. 11 with no
dropper correction, I_cc reduced to N_h harmonics on its observed index) and the pantograph in contact answers
the height with H_p(w) f = x_s - z at every harmonic (its contact-point receptance, Paper A eq. 18, contact
spring in series; x_s its static head height). With f = F0 + sum over harmonics 1..N_h-1 of a_k cos + b_k sin
(F0 the mean force, the uplift), the harmonics 1..N_h-1 of

    H_p f + I_cc f + z0 = x_s

are 2 (N_h - 1) real equations in the a_k, b_k: Paper A eqs. (38)-(39) with the string's diagonal H11 replaced
by the PFEM's full periodic operator (a moving load on a catenary whose stiffness varies along the span excites
every harmonic at once). The pantograph being linear, f has no harmonics above N_h - 1, so the solve is exact
in the operators' own space. What a catenary designer evaluates a design by (issue 34): the std of f, its
maximum and minimum, in a few milliseconds once the operators are built.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LinearSteadyState:
    """The contact force over one span of the steady state, sampled as the operators are [N]."""

    force_N: np.ndarray
    dt_s: float

    @property
    def std_N(self) -> float:
        """Standard deviation over the span (harmonics up to the operators' N_h - 1)."""
        return float(np.std(self.force_N))

    @property
    def max_N(self) -> float:
        """Largest force over the span."""
        return float(self.force_N.max())

    @property
    def min_N(self) -> float:
        """Smallest force over the span (negative: the linear model would need the wire to pull the head)."""
        return float(self.force_N.min())


def harmonic_basis(n: int, n_harmonics: int) -> np.ndarray:
    """[cos(2 pi k i / n) for k = 1..N_h-1, then sin(...)] as the columns of an n x 2 (N_h - 1) matrix."""
    theta = 2 * np.pi * np.outer(np.arange(n), np.arange(1, n_harmonics)) / n
    return np.hstack([np.cos(theta), np.sin(theta)])


def irfft_rows(n: int, n_harmonics: int) -> np.ndarray:
    """Row i: the weights that give a real sequence's value at index i from the real parts, then the
    imaginary parts, of its rfft harmonics 0..n_harmonics-1 (np.fft.irfft's, the harmonics above zero):
    a dropper window's elongation at an instant from its harmonics (Paper C eqs. 35-40)."""
    a = np.full(n_harmonics, 2.0)
    a[0] = 1.0
    if n % 2 == 0 and n_harmonics == n // 2 + 1:
        a[-1] = 1.0
    theta = 2 * np.pi * np.outer(np.arange(n), np.arange(n_harmonics)) / n
    return np.concatenate([a * np.cos(theta), -a * np.sin(theta)], axis=1) / n


def receptance_block(h: np.ndarray) -> np.ndarray:
    """H_p acting on the coefficients (a, b) of a cos + b sin at each harmonic: a cos + b sin ->
    (Re H a + Im H b) cos + (Re H b - Im H a) sin, as one 2 (N_h - 1) square matrix."""
    hr, hi = np.diag(h.real), np.diag(h.imag)
    return np.block([[hr, hi], [-hi, hr]])


def linear_steady_state(cc: np.ndarray, z0_m: np.ndarray, pantograph_receptance_m_N: np.ndarray, dt_s: float,
                        mean_force_N: float) -> LinearSteadyState:
    """The steady contact force over one span (module docstring): `cc` as `PfemOperators.cc` (row m: the heights
    per unit force at sample m), `z0_m` the static wire height at the contact samples, the pantograph's contact-
    point receptance at the span's harmonics 1..N_h-1 (w_k = 2 pi k / (N dt)), and the mean force."""
    n = len(z0_m)
    if cc.shape != (n, n):
        raise ValueError(f"cc must be {n} x {n} (got {cc.shape})")
    basis, _, system, rhs = harmonic_balance(cc, z0_m, pantograph_receptance_m_N, mean_force_N)
    coefficients = np.linalg.solve(system, rhs)
    return LinearSteadyState(mean_force_N + basis @ coefficients, dt_s)


def harmonic_balance(cc: np.ndarray, z0_m: np.ndarray, pantograph_receptance_m_N: np.ndarray,
                     mean_force_N: float) -> tuple:
    """The harmonic balance of the linear solve (Paper A eqs. 38-39 with the PFEM's operator): the basis of
    harmonics 1..N_h-1 over the span, the projection onto their coefficients, the system and its right-hand
    side (`linear_steady_state`; the steady state with slack droppers adds its corrections to them)."""
    n = len(z0_m)
    basis = harmonic_basis(n, len(pantograph_receptance_m_N) + 1)
    project = basis.T * (2.0 / n)  # coefficients of harmonics 1..N_h-1 (orthogonal columns of norm^2 n / 2)
    i_cc = cc.T
    system = receptance_block(np.asarray(pantograph_receptance_m_N)) + project @ (i_cc @ basis)
    rhs = -project @ (np.asarray(z0_m, dtype=float) + i_cc @ np.full(n, mean_force_N))
    return basis, project, system, rhs


def span_frequencies_rad_s(n: int, dt_s: float, n_harmonics: int) -> np.ndarray:
    """w_k = 2 pi k / (N dt) for k = 1..N_h-1: the harmonics of a span passed in N steps of dt."""
    return 2 * np.pi * np.arange(1, n_harmonics) / (n * dt_s)
