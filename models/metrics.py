"""Contact-force statistics of a periodic span (EN 50367 / EN 50318 style: mean, std, statistical and
actual extremes, contact loss, and the same after a zero-phase 20 Hz low-pass)."""
from __future__ import annotations

import numpy as np
from scipy import signal


LOWPASS_CUTOFF_HZ = 20.0  # EN 50317 / EN 50318 contact-force statistics
LOWPASS_ORDER = 4


def lowpass(x: np.ndarray, dt_s: float, cutoff_hz: float = LOWPASS_CUTOFF_HZ, order: int = LOWPASS_ORDER) -> np.ndarray:
    """Zero-phase Butterworth low-pass of a finite record: the filter as second-order sections, run
    forwards and backwards (scipy's sosfiltfilt, odd extension at the ends). The one filter of pantohil:
    HIL spans (through `lowpass_periodic`) and conventional FE sections use it alike."""
    nyq = 0.5 / dt_s
    if cutoff_hz >= nyq:
        return np.asarray(x, dtype=float).copy()
    sos = signal.butter(order, cutoff_hz / nyq, output="sos")
    return signal.sosfiltfilt(sos, np.asarray(x, dtype=float))


def lowpass_periodic(x: np.ndarray, dt_s: float, cutoff_hz: float = LOWPASS_CUTOFF_HZ,
                     order: int = LOWPASS_ORDER) -> np.ndarray:
    """`lowpass` of one period, padded with its own periodic copies (no edge effect)."""
    n = len(x)
    return lowpass(np.tile(x, 3), dt_s, cutoff_hz, order)[n:2 * n]


def force_statistics(f: np.ndarray) -> dict:
    """The contact-force statistics of EN 50367 / EN 50318 [N]: mean F_m, standard deviation sigma,
    statistical maximum and minimum F_m +- 3 sigma, actual maximum and minimum, and the percentage of
    samples without contact (force <= 0). One definition for HIL runs and FE sections, raw or low-passed."""
    f = np.asarray(f, dtype=float)
    mean, std = float(np.mean(f)), float(np.std(f))
    return {"mean_N": mean, "std_N": std, "stat_max_N": mean + 3 * std, "stat_min_N": mean - 3 * std,
            "max_N": float(np.max(f)), "min_N": float(np.min(f)),
            "contact_loss_pct": float(100 * np.mean(f <= 0.0))}


def rms(x: np.ndarray) -> float:
    """Root mean square of a sequence."""
    return float(np.sqrt(np.mean(np.square(x))))
