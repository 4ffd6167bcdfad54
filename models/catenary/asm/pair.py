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

from dataclasses import dataclass
from pathlib import Path

from pantohil.models.catenary.asm.string import AsmParameters, receptance_ahead, receptance_behind, receptance_direct
from pantohil.models.catenary.receptance import CirculantOperator

POSITIONS = ("trailing", "leading")  # where the second pantograph runs relative to the first
RECEPTANCE_FILE = "pantograph_receptance.csv"  # staged for the catenary FMU's coupling compensation


@dataclass(frozen=True)
class PairSpec:
    """The second contact point: its distance L from the first, where it runs, and whether the pair's coupling is
    compensated (with the pantograph receptance at the kept harmonics)."""

    spacing_m: float
    position: str
    compensated: bool = True


def second_offset_m(spacing_m: float, position: str) -> float:
    """The second pantograph's position relative to the first along the line: -L trailing, +L leading."""
    if position not in POSITIONS:
        raise ValueError(f"position must be one of {POSITIONS}, got {position!r}")
    return -spacing_m if position == "trailing" else spacing_m


def pair_operators(cat: AsmParameters, speed_m_s: float, samples_per_span: int, dt_s: float, n_harmonics: int,
                   spacing_m: float, position: str):
    """((I_11, I_12), (I_21, I_22)) at harmonics 0..n_harmonics-1, point 1 the first pantograph and point 2 the
    second (Paper A eqs. 15-17 sampled as in Paper B eqs. 6-11)."""
    return circulant_blocks(pair_spectra(cat, speed_m_s, samples_per_span, dt_s, n_harmonics, spacing_m, position),
                            samples_per_span)


def pair_spectra(cat: AsmParameters, speed_m_s: float, samples_per_span: int, dt_s: float, n_harmonics: int,
                 spacing_m: float, position: str) -> np.ndarray:
    """S[k] = [[H11, H12], [H21, H22]] at w_k = 2 pi k / (N dt), k < n_harmonics (Paper A eqs. 15-17), shape
    (n_harmonics, 2, 2): the pair's receptance matrix, point 1 the first pantograph."""
    omega = 2 * np.pi * np.arange(n_harmonics) / (samples_per_span * dt_s)
    direct = receptance_direct(cat, omega, speed_m_s)
    ahead = receptance_ahead(cat, omega, speed_m_s, spacing_m)  # at the point ahead, from the load behind
    behind = receptance_behind(cat, omega, speed_m_s, spacing_m)  # at the point behind, from the load ahead
    h12, h21 = (ahead, behind) if second_offset_m(spacing_m, position) < 0 else (behind, ahead)
    spectra = np.array([[direct, h12], [h21, direct]]).transpose(2, 0, 1)
    spectra[0] = spectra[0].real  # the response to constant forces is real; drop round-off
    return spectra


def circulant_blocks(spectra: np.ndarray, samples_per_span: int, beyond: np.ndarray | None = None):
    """((C_11, C_12), (C_21, C_22)): the circulant operators of 2 x 2 spectra given at the first harmonics,
    `beyond` (2 x 2, default 0) at the others."""
    full = np.zeros((samples_per_span // 2 + 1, 2, 2), dtype=complex)
    if beyond is not None:
        full[:] = beyond
    full[:len(spectra)] = spectra
    return tuple(tuple(CirculantOperator(np.fft.irfft(full[:, i, j], n=samples_per_span)) for j in range(2))
                 for i in range(2))


def coupling_compensation(spectra: np.ndarray, pantograph_receptance: np.ndarray) -> np.ndarray:
    """Q[k] = (I + D[k] / H_p) (I + S[k] / H_p)^-1, D the diagonal of S: the force residuals of the pair mapped
    so that the pair's iteration has the matrix of each contact point iterating alone (Q (I + S / H_p) =
    I + D / H_p: the pantographs' steady response f = -z / H_p, Paper A eq. 18). With the pantographs' model
    receptance H_p the cross coupling is compensated exactly; the fixed point does not depend on Q."""
    eye = np.eye(2)
    out = np.empty_like(spectra)
    for k, (s, hp) in enumerate(zip(spectra, pantograph_receptance, strict=True)):
        out[k] = (eye + np.diag(np.diag(s)) / hp) @ np.linalg.inv(eye + s / hp)
    return out


def pair_static_compliance_m_N(cat: AsmParameters, speed_m_s: float, spacing_m: float,
                               position: str) -> tuple[float, float]:
    """Each point's mean height per unit mean force of both (equal) forces, H_ii(0) + H_ij(0) [m/N]: where each
    pantograph is set so that its converged mean force is the uplift force."""
    static = pair_spectra(cat, speed_m_s, 1, 1.0, 1, spacing_m, position)[0].real  # the pair's receptance at w = 0
    return float(static[0].sum()), float(static[1].sum())


def write_receptance_csv(folder: Path, receptance_m_N: np.ndarray) -> Path:
    """The pantograph's receptance at harmonics 0..N_h-1 as pantograph_receptance.csv (harmonic,re_m_N,im_m_N)."""
    hp = np.asarray(receptance_m_N, dtype=complex)
    np.savetxt(folder / RECEPTANCE_FILE, np.column_stack([np.arange(len(hp)), hp.real, hp.imag]), delimiter=",",
               comments="", fmt="%.17g", header="harmonic,re_m_N,im_m_N")
    return folder / RECEPTANCE_FILE


def read_receptance_csv(folder: Path, n_harmonics: int) -> np.ndarray:
    """The receptance of a staged pantograph_receptance.csv, which must hold harmonics 0..n_harmonics-1."""
    table = np.atleast_2d(np.loadtxt(Path(folder) / RECEPTANCE_FILE, delimiter=",", skiprows=1))
    if table.shape != (n_harmonics, 3) or not np.array_equal(table[:, 0], np.arange(n_harmonics)):
        raise ValueError(f"{RECEPTANCE_FILE} does not hold harmonics 0..{n_harmonics - 1}")
    hp = table[:, 1] + 1j * table[:, 2]
    if not np.all(np.isfinite(hp)) or np.any(hp == 0):
        raise ValueError(f"{RECEPTANCE_FILE}: a receptance is not a finite non-zero number")
    return hp
