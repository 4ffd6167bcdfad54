"""Contact-force statistics of a periodic span (EN 50367 / EN 50318 style: mean, std, extremes,
and the same after a zero-phase 20 Hz low-pass)."""
from __future__ import annotations

import numpy as np
from scipy import signal


def lowpass_periodic(x: np.ndarray, dt_s: float, cutoff_hz: float = 20.0, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass (filtfilt) of one period, padded with its own periodic copies."""
    nyq = 0.5 / dt_s
    if cutoff_hz >= nyq:
        return np.asarray(x, dtype=float).copy()
    sos = signal.butter(order, cutoff_hz / nyq, output="sos")
    n = len(x)
    y = signal.sosfiltfilt(sos, np.tile(x, 3))
    return y[n:2 * n]


def force_statistics(f: np.ndarray) -> dict:
    """Mean, standard deviation, maximum and minimum of a contact force [N]."""
    f = np.asarray(f, dtype=float)
    return {"mean_N": float(np.mean(f)), "std_N": float(np.std(f)),
            "max_N": float(np.max(f)), "min_N": float(np.min(f))}


def rms(x: np.ndarray) -> float:
    """Root mean square of a sequence."""
    return float(np.sqrt(np.mean(np.square(x))))
