"""The periodic receptance operator z = z0 + I_cc f over one span (Paper B eqs. 6-11, Paper D eq. 1).

For a homogeneous string (ASM) I_cc(n, n_hat) depends only on (n - n_hat) mod N: it is circulant
and is stored as its first column (the kernel). Frequency reduction keeps harmonics 0..N_h-1
(Paper D eqs. 4-8): the kernel and z0 are filtered once, offline.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pantohil.models.catenary.asm.string import AsmParameters, receptance_direct


def harmonic_count(max_frequency_hz: float, samples_per_span: int, dt_s: float) -> int:
    """N_h with N_h - 1 = floor(f_max N dt): all harmonics at or below f_max (Paper D sec. 3.5)."""
    n_h = int(math.floor(max_frequency_hz * samples_per_span * dt_s + 1e-9)) + 1
    return max(1, min(n_h, samples_per_span // 2 + 1))


def reduce_harmonics(x: np.ndarray, n_harmonics: int) -> np.ndarray:
    """Keep harmonics 0..N_h-1 of a periodic sequence: W~ x of Paper D eq. (6), done by FFT."""
    spec = np.fft.rfft(x)
    spec[n_harmonics:] = 0.0
    return np.fft.irfft(spec, n=len(x))


@dataclass
class CirculantOperator:
    """A circulant N x N operator stored as its first column c: I(n, m) = c[(n - m) mod N]."""

    kernel: np.ndarray

    def __post_init__(self):
        self.kernel = np.ascontiguousarray(self.kernel, dtype=float)
        self.n = len(self.kernel)
        self._doubled = np.concatenate([self.kernel, self.kernel])

    def column(self, m: int) -> np.ndarray:
        """Column m as a view (no copy): the response of every sample to a force at sample m."""
        return self._doubled[self.n - m: 2 * self.n - m]

    def apply(self, f: np.ndarray) -> np.ndarray:
        """I f, a circular convolution evaluated by FFT."""
        return np.fft.irfft(np.fft.rfft(self.kernel) * np.fft.rfft(f), n=self.n)

    def dense(self) -> np.ndarray:
        """The N x N matrix I_cc(n, n_hat) = kernel[(n - n_hat) mod N] (Paper D eq. 1)."""
        idx = (np.arange(self.n)[:, None] - np.arange(self.n)[None, :]) % self.n
        return self.kernel[idx]


def asm_operator(cat: AsmParameters, speed_m_s: float, samples_per_span: int, dt_s: float,
                 n_harmonics: int) -> CirculantOperator:
    """I_cc of ASM2 from its FRF at w_k = 2 pi k / (N dt), k < N_h (Paper B eqs. 6-11)."""
    n = samples_per_span
    k = np.arange(n_harmonics)
    omega = 2 * np.pi * k / (n * dt_s)
    spec = np.zeros(n // 2 + 1, dtype=complex)
    spec[:n_harmonics] = receptance_direct(cat, omega, speed_m_s)
    spec[0] = spec[0].real  # H(0) is real for a real system; drop round-off
    return CirculantOperator(np.fft.irfft(spec, n=n))
