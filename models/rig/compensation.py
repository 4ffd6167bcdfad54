"""Compensation of the rig's dynamics at the kept harmonics, the generalisation of Paper D sec. 3.4.

The delay advance D makes a pure delay vanish at convergence: the height is commanded D samples
ahead. With the rig's responses G_z (command -> actuator height) and G_f (true -> measured force) at
the harmonics k < N_h that the catenary keeps (Paper D eqs. 4-8), the iteration commands
c = A z with A = G_z^-1 and feeds the catenary operator the true force f = B f_meas with
B = G_f^-1, harmonic by harmonic (both circulant over the span; harmonics at or above N_h pass
unchanged). At convergence the actuator then follows the catenary's height and the catenary
receives the true force at every kept harmonic; A = e^{i w D dt}, B = 1 is the delay advance.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


def _kernel(n: int, inverse_gains: np.ndarray) -> np.ndarray:
    spec = np.ones(n // 2 + 1, dtype=complex)
    spec[: len(inverse_gains)] = inverse_gains
    spec[0] = spec[0].real
    if n % 2 == 0 and len(inverse_gains) == n // 2 + 1:
        spec[-1] = spec[-1].real
    return np.fft.irfft(spec, n=n)


class HarmonicCompensation:
    """A = G_z^-1 and B = G_f^-1 at harmonics 0..N_h-1 of a span of N samples."""

    def __init__(self, samples_per_span: int, height_gains: np.ndarray, force_gains: np.ndarray):
        n = self.n = samples_per_span
        gz, gf = np.asarray(height_gains, complex), np.asarray(force_gains, complex)
        if len(gz) != len(gf) or len(gz) > n // 2 + 1:
            raise ValueError("rig compensation: height and force gains need one value per kept harmonic")
        if np.any(np.abs(gz) < 1e-6) or np.any(np.abs(gf) < 1e-6):
            raise ValueError("rig compensation: a gain of zero at a kept harmonic cannot be inverted")
        self.height_gains, self.force_gains = gz, gf
        a = _kernel(n, 1.0 / gz)
        self.b = _kernel(n, 1.0 / gf)
        ar = np.roll(a[::-1], 1)  # ar[j] = a[-j mod N]
        self._rows = np.concatenate([ar, ar])
        self._bcols = np.concatenate([self.b, self.b])

    def command(self, z: np.ndarray, target: int) -> float:
        """(A z)[target]: the height to command for sample `target`."""
        return float(self._rows[self.n - target: 2 * self.n - target] @ z)

    def commands(self, z: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """(A z) at each of `targets`."""
        windows = np.lib.stride_tricks.sliding_window_view(self._rows, self.n)  # row n - t is command(., t)
        return windows[self.n - np.asarray(targets)] @ z

    def force_column(self, m: int) -> np.ndarray:
        """Column m of B: the true-force estimate per unit measured force at sample m."""
        return self._bcols[self.n - m: 2 * self.n - m]

    def force_matrix(self) -> np.ndarray:
        """The force compensation as an N x N circulant matrix of its kernel."""
        idx = (np.arange(self.n)[:, None] - np.arange(self.n)[None, :]) % self.n
        return self.b[idx]

    def compensate_kernel(self, kernel: np.ndarray) -> np.ndarray:
        """Kernel of I B for a circulant I (the ASM string)."""
        return np.fft.irfft(np.fft.rfft(kernel) * np.fft.rfft(self.b), n=self.n)

    def compensate_rows(self, rows: np.ndarray) -> np.ndarray:
        """rows[m] is the response to a unit force at sample m (PFEM cc, dc): the same per unit measured
        force, sum_m B[m, n] rows[m]."""
        bmat = self.force_matrix()
        flat = rows.reshape(self.n, -1)
        return (bmat.T @ flat).reshape(rows.shape)


RESPONSE_FILE = "rig_response.csv"  # the rig's gains the catenary FMU carries in resources/


def write_response_csv(folder: Path, height_gains: np.ndarray, force_gains: np.ndarray) -> Path:
    """The gains at harmonics 0..N_h-1 as rig_response.csv (harmonic,height_re,height_im,force_re,force_im)."""
    gz, gf = np.asarray(height_gains, complex), np.asarray(force_gains, complex)
    table = np.column_stack([np.arange(len(gz)), gz.real, gz.imag, gf.real, gf.imag])
    np.savetxt(folder / RESPONSE_FILE, table, delimiter=",", comments="", fmt="%.17g",
               header="harmonic,height_re,height_im,force_re,force_im")
    return folder / RESPONSE_FILE


def read_response_csv(folder: Path, samples_per_span: int, n_harmonics: int) -> HarmonicCompensation:
    """The compensation of a staged rig_response.csv, which must hold harmonics 0..n_harmonics-1."""
    table = np.atleast_2d(np.loadtxt(Path(folder) / RESPONSE_FILE, delimiter=",", skiprows=1))
    if table.shape[0] != n_harmonics or not np.array_equal(table[:, 0], np.arange(n_harmonics)):
        raise ValueError(f"{RESPONSE_FILE} has {table.shape[0]} harmonics; the parameters keep {n_harmonics}")
    return HarmonicCompensation(samples_per_span, table[:, 1] + 1j * table[:, 2], table[:, 3] + 1j * table[:, 4])
