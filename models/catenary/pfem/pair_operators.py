"""The PFEM operators of two contact points (a pantograph pair, Paper A sec. 3.4 on the PFEM of Papers C-D):
the first point's operators (operators.py), the cross operators I_12, I_21 (offset_operator.py), and the
second point's own operators, which follow from the first's by a shift of the samples.

The second point runs at x + offset = x + s V dt + k span. Its load at sample m is the first point's load at
m + s, k N + s samples earlier (the moving load's response is quasi-periodic over the blocks), and its
height at n is the first point's position at n + s seen k N + s samples earlier, so with both the load and
the observation shifted:
    I_22[n, m] = I_11[n + s, m + s],   z0_2[n] = z0_1[n + s]   (indices mod N).
Each pantograph has its own set of droppers: the instances it passes, each with a correction window of N
instants centred on that pantograph's passage (Paper D sec. 3.7; the second's windows start s samples
earlier), so that every slackening of a dropper falls in a window; by the same shift
    dc_2[m, d, :] = dc_1[m + s, d, :],   cd_2[t, d, n] = cd_1[t + s, d, n + s],   dd_2 = dd_1.
What couples one pantograph's droppers to the other pantograph, several spans away, is left out: a slack
dropper's correction moves only its own pantograph's height, and each set's elongation is that of its own
pantograph's load. The linear coupling of the two points, droppers in tension, is whole in I_12 and I_21.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from pantohil.models.catenary.pfem.operator_data import PfemOperators, PfemSettings

PAIR_FILE = "pair_operators.npz"


def sample_shift(s: PfemSettings, offset_m: float) -> int:
    """s with offset = s V dt (mod span): the second point at sample m is where the first is at sample m + s.
    ValueError unless the offset is a whole number of samples."""
    step = s.speed_m_s * s.dt_s
    shift = np.mod(offset_m / step, s.samples_per_span)
    if abs(shift - round(shift)) > 1e-6:
        raise ValueError(f"the second contact point ({offset_m:g} m) must lie a whole number of samples ({step:g} m) "
                         "from the first")
    return int(round(shift)) % s.samples_per_span


@dataclass
class PfemPairOperators:
    """The first point's operators `first`, the second's `second`, and the cross operators I_12, I_21 (rows
    observed, columns loaded); `shift` s."""

    first: PfemOperators
    second: PfemOperators
    i12: np.ndarray
    i21: np.ndarray
    shift: int

    @property
    def z0(self) -> np.ndarray:
        """The static heights of both points (2, N) [m]."""
        return np.array([self.first.z0, self.second.z0])


def second_point_operators(ops: PfemOperators, shift: int) -> PfemOperators:
    """The second point's own operators and dropper set from the first's (module docstring)."""
    s = int(shift)
    return replace(ops, cc=np.ascontiguousarray(np.roll(ops.cc, (-s, -s), axis=(0, 1))),
                   dc=np.ascontiguousarray(np.roll(ops.dc, -s, axis=0)),
                   cd=np.ascontiguousarray(np.roll(ops.cd, (-s, -s), axis=(0, 2))), z0=np.roll(ops.z0, -s),
                   window_start=np.asarray(ops.window_start) - s, info={**ops.info, "pair_shift": s})


def pair_operators(ops: PfemOperators, i12: np.ndarray, i21: np.ndarray, shift: int) -> PfemPairOperators:
    """The pair's operators from the first point's and the cross operators."""
    return PfemPairOperators(ops, second_point_operators(ops, shift), np.asarray(i12, dtype=float),
                             np.asarray(i21, dtype=float), int(shift))


def save_cross_operators(path: Path, i12: np.ndarray, i21: np.ndarray, offset_m: float, shift: int) -> None:
    """The cross operators as an npz file (float64, no pickled objects)."""
    np.savez(path, i12=np.asarray(i12, dtype=float), i21=np.asarray(i21, dtype=float),
             offset_m=np.float64(offset_m), shift=np.int64(shift))


def load_cross_operators(path: Path, n: int, offset_m: float) -> tuple[np.ndarray, np.ndarray, int]:
    """(I_12, I_21, s) of a file written by save_cross_operators for N samples and this offset; ValueError
    naming what does not match."""
    with np.load(path, allow_pickle=False) as f:
        i12, i21, off, shift = f["i12"], f["i21"], float(f["offset_m"]), int(f["shift"])
    if i12.shape != (n, n) or i21.shape != (n, n):
        raise ValueError(f"{Path(path).name}: cross operators of shape {i12.shape}, expected ({n}, {n})")
    if abs(off - offset_m) > 1e-9 or not np.all(np.isfinite(i12)) or not np.all(np.isfinite(i21)):
        raise ValueError(f"{Path(path).name}: built for an offset of {off:g} m, not {offset_m:g} m, or not finite")
    return i12, i21, shift
