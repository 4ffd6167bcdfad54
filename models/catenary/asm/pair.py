"""ASM2 with two contact points a distance L apart (Paper A secs. 3.4 and 5): the four periodic receptance
operators of the pair and the static height each point sees.

The first pantograph runs at x = v t, the second at x = v t - L (trailing) or v t + L (leading). Over the
samples n of a span both points are periodic with the span, so each operator is circulant (Paper B eqs.
6-11): I_ij(n, n_hat) = c_ij[(n - n_hat) mod N], the height at point i at sample n from a unit force at
point j at sample n_hat, with c_ij the inverse DFT of the string's receptance at w_k = 2 pi k / (N dt):
H11 = H22 (Paper A eq. 17), the point ahead's response to the load behind, H12 (eq. 15), and the point
behind's response to the load ahead, H21 (eq. 16).
"""
from __future__ import annotations

import numpy as np

from pantohil.models.catenary.asm.string import AsmParameters, receptance_ahead, receptance_behind, receptance_direct
from pantohil.models.catenary.receptance import CirculantOperator

POSITIONS = ("trailing", "leading")  # where the second pantograph runs relative to the first


def second_offset_m(spacing_m: float, position: str) -> float:
    """The second pantograph's position relative to the first along the line: -L trailing, +L leading."""
    if position not in POSITIONS:
        raise ValueError(f"position must be one of {POSITIONS}, got {position!r}")
    return -spacing_m if position == "trailing" else spacing_m


def _circulant(spectrum: np.ndarray, samples_per_span: int) -> CirculantOperator:
    spec = np.zeros(samples_per_span // 2 + 1, dtype=complex)
    spec[:len(spectrum)] = spectrum
    spec[0] = spec[0].real  # the response to a constant force is real; drop round-off
    return CirculantOperator(np.fft.irfft(spec, n=samples_per_span))


def pair_operators(cat: AsmParameters, speed_m_s: float, samples_per_span: int, dt_s: float, n_harmonics: int,
                   spacing_m: float, position: str) -> tuple[tuple[CirculantOperator, CirculantOperator],
                                                              tuple[CirculantOperator, CirculantOperator]]:
    """((I_11, I_12), (I_21, I_22)) at harmonics 0..n_harmonics-1, point 1 the first pantograph and point 2 the
    second (Paper A eqs. 15-17 sampled as in Paper B eqs. 6-11)."""
    omega = 2 * np.pi * np.arange(n_harmonics) / (samples_per_span * dt_s)
    direct = receptance_direct(cat, omega, speed_m_s)
    ahead = receptance_ahead(cat, omega, speed_m_s, spacing_m)  # at the point ahead, from the load behind
    behind = receptance_behind(cat, omega, speed_m_s, spacing_m)  # at the point behind, from the load ahead
    second_behind = second_offset_m(spacing_m, position) < 0
    h12, h21 = (ahead, behind) if second_behind else (behind, ahead)
    d = _circulant(direct, samples_per_span)
    return ((d, _circulant(h12, samples_per_span)), (_circulant(h21, samples_per_span), d))


def pair_static_compliance_m_N(cat: AsmParameters, speed_m_s: float, spacing_m: float,
                               position: str) -> tuple[float, float]:
    """Each point's mean height per unit mean force of both (equal) forces, H_ii(0) + H_ij(0) [m/N]: where each
    pantograph is set so that its converged mean force is the uplift force."""
    direct = float(np.real(receptance_direct(cat, 0.0, speed_m_s)))
    ahead = float(np.real(receptance_ahead(cat, 0.0, speed_m_s, spacing_m)))
    behind = float(np.real(receptance_behind(cat, 0.0, speed_m_s, spacing_m)))
    second_behind = second_offset_m(spacing_m, position) < 0
    return (direct + ahead, direct + behind) if second_behind else (direct + behind, direct + ahead)
