"""Contact-force statistics of a periodic span (EN 50367 / EN 50318 style: mean, std, extremes,
and the same after a zero-phase 20 Hz low-pass)."""
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
    """Mean, standard deviation, maximum and minimum of a contact force [N]."""
    f = np.asarray(f, dtype=float)
    return {"mean_N": float(np.mean(f)), "std_N": float(np.std(f)),
            "max_N": float(np.max(f)), "min_N": float(np.min(f))}


def rms(x: np.ndarray) -> float:
    """Root mean square of a sequence."""
    return float(np.sqrt(np.mean(np.square(x))))
