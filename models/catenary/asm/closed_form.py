"""Closed-form steady state of one or two pantographs on ASM2 with a periodic wire height.

Harmonics use one-sided amplitudes: z0(x) = Z0 + sum_n Re(Z_n exp(i k_n x)), so that the contact
force standard deviation is sqrt(1/2 sum |F_n|^2) (Paper A eq. 41).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pantohil.models.catenary.asm.string import (AsmParameters, characteristic_coefficients, poles, receptance_ahead,
    receptance_behind, receptance_direct)
from pantohil.models.pantograph.interface import receptance
from pantohil.models.pantograph.lumped import PantographParameters


def one_sided_harmonics(samples: np.ndarray) -> np.ndarray:
    """One-sided complex amplitudes of a periodic sampled signal (index n = harmonic n)."""
    spec = np.fft.rfft(samples) / len(samples)
    spec[1:] *= 2.0
    if len(samples) % 2 == 0:
        spec[-1] /= 2.0
    return spec


def synthesize(amplitudes: np.ndarray, n_samples: int) -> np.ndarray:
    """Inverse of `one_sided_harmonics` (missing harmonics are zero)."""
    spec = np.zeros(n_samples // 2 + 1, dtype=complex)
    m = min(len(amplitudes), len(spec))
    spec[:m] = amplitudes[:m]
    spec[1:] /= 2.0
    if n_samples % 2 == 0:
        spec[-1] *= 2.0
    return np.fft.irfft(spec * n_samples, n=n_samples)


@dataclass
class SteadyState:
    """Harmonic contact forces of the converged periodic state."""

    frequencies_hz: np.ndarray  # of harmonics 0..n-1
    force_amplitudes_N: np.ndarray  # one-sided, harmonic 0 holds the mean force

    def std_N(self, max_frequency_hz: float | None = None) -> float:
        """Contact-force standard deviation from the harmonics, Paper A eq. (41)."""
        keep = slice(1, None)
        amp = self.force_amplitudes_N[keep]
        if max_frequency_hz is not None:
            amp = amp[self.frequencies_hz[keep] <= max_frequency_hz]
        return math.sqrt(0.5 * float(np.sum(np.abs(amp) ** 2)))

    def force_series(self, n_samples: int) -> np.ndarray:
        """The steady contact force at n_samples points of one span, from its harmonics (Paper A eq. 28)."""
        return synthesize(self.force_amplitudes_N, n_samples)


def dynamic_stiffness(cat: AsmParameters, pan: PantographParameters, omega, speed: float):
    """K_D = -1 / (H_p + H11), Paper A eq. (40)."""
    return -1.0 / (receptance(pan, omega) + receptance_direct(cat, omega, speed))


def single_pantograph(cat: AsmParameters, pan: PantographParameters, speed: float, span_m: float,
                      z0_amplitudes: np.ndarray, mean_force_N: float, n_harmonics: int) -> SteadyState:
    """F_n = K_D(Omega_n) Z_n for n = 1..n_harmonics-1 plus the mean force, Paper A eqs. (38)-(39)."""
    n = np.arange(n_harmonics)
    omega = 2 * np.pi * n * speed / span_m  # Paper A eq. (29)
    forces = np.zeros(n_harmonics, dtype=complex)
    forces[0] = mean_force_N
    if n_harmonics > 1:
        forces[1:] = dynamic_stiffness(cat, pan, omega[1:], speed) * z0_amplitudes[1:n_harmonics]
    return SteadyState(omega / (2 * np.pi), forces)


def two_pantographs(cat: AsmParameters, pan: PantographParameters, speed: float, span_m: float,
                    z0_amplitudes: np.ndarray, mean_force_N: float, n_harmonics: int,
                    spacing_m: float) -> tuple[SteadyState, SteadyState]:
    """Leading (1) and trailing (2) pantograph forces `spacing_m` apart, Paper A eqs. (24)-(30)."""
    n = np.arange(n_harmonics)
    omega = 2 * np.pi * n * speed / span_m
    f1 = np.zeros(n_harmonics, dtype=complex)
    f2 = np.zeros(n_harmonics, dtype=complex)
    f1[0] = f2[0] = mean_force_N
    for j in range(1, n_harmonics):
        w = omega[j]
        hp = receptance(pan, w)[0]
        h11 = receptance_direct(cat, w, speed)
        h12 = receptance_ahead(cat, w, speed, spacing_m)
        h21 = receptance_behind(cat, w, speed, spacing_m)
        H = np.array([[-hp - h11, -h12], [-h21, -hp - h11]])
        z = z0_amplitudes[j] * np.array([np.exp(1j * w * spacing_m / speed), 1.0])  # eq. (30)
        f1[j], f2[j] = np.linalg.solve(H, z)
    freq = omega / (2 * np.pi)
    return SteadyState(freq, f1), SteadyState(freq, f2)


def pair_forces(cat: AsmParameters, pan: PantographParameters, speed: float, dt_s: float, z0_pair: np.ndarray,
                mean_force_N: float, n_harmonics: int, spacing_m: float, second_leading: bool) -> np.ndarray:
    """Each contact point's steady force at its own N samples of a span, shape (2, N) [N]: Paper A eqs. (24)-(25)
    with the heights each point passes (`z0_pair`, first and second, as models/hil/pair_loop.py samples them);
    the receptance at one point from the other's load is H12 (ahead) for the leading point, H21 (behind) for the
    trailing one."""
    n = z0_pair.shape[1]
    z = [one_sided_harmonics(row) for row in z0_pair]
    f = np.zeros((2, n_harmonics), dtype=complex)
    f[:, 0] = mean_force_N
    for j in range(1, n_harmonics):
        w = 2 * np.pi * j / (n * dt_s)
        direct = -receptance(pan, w)[0] - receptance_direct(cat, w, speed)
        ahead, behind = receptance_ahead(cat, w, speed, spacing_m), receptance_behind(cat, w, speed, spacing_m)
        at_first, at_second = (behind, ahead) if second_leading else (ahead, behind)
        f[:, j] = np.linalg.solve([[direct, -at_first], [-at_second, direct]], [z[0][j], z[1][j]])
    return np.array([synthesize(f[p], n) for p in range(2)])


def optimal_spacings(cat: AsmParameters, pan: PantographParameters, speed: float, omega: float,
                     max_spacing_m: float) -> list[float]:
    """Spacings that minimise the trailing pantograph's harmonic at omega, Paper A eqs. (43)-(45)."""
    pl = poles(cat, omega, speed)
    if not pl.lower or not pl.upper:
        return []
    k1, k2 = pl.lower[0], pl.upper[0]
    k3 = pl.upper[1] if len(pl.upper) > 1 else None
    lam = characteristic_coefficients(cat, omega, speed)[0]
    prod = (k2 - k1) * (k2 - k3) if k3 is not None else (k2 - k1)
    hp = receptance(pan, omega)[0]
    c_a = 1j / ((hp + receptance_direct(cat, omega, speed)) * lam * prod)
    denom = omega / speed + k2.real
    period = 2 * math.pi / abs(denom)
    first = (-np.angle(c_a) / denom) % period  # the n of eq. (45) that gives the smallest L > 0
    return [float(L) for L in np.arange(first, max_spacing_m, period)]
