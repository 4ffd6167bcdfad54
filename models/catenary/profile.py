"""Contact-wire height z0(x) along one span (Paper A sec. 5.1, Paper B sec. 2.2).

z0 is read from a CSV file or generated: the wire hangs in parabolas under its own weight between its
fixed points (supports and dropper clamps), whose design heights follow an optional pre-sag parabola.
A catenary file's form-found z0 (`[profile] source = "catenary"`) comes from models/catenary/fe.
"""
from __future__ import annotations

import csv
import io
import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pantohil.models.errors import InputError
from pantohil.models.input_files import InputFileError, read_input_text

GRAVITY_M_S2 = 9.81


class ProfileError(InputError):
    """A profile that cannot be built or read."""


@dataclass(frozen=True)
class DropperProfile:
    """Data for a generated profile. Dropper positions are measured from the span's first support."""

    span_m: float
    dropper_positions_m: tuple
    wire_mass_kg_m: float
    wire_tension_N: float
    presag_m: float = 0.0

    def heights(self, x: np.ndarray) -> np.ndarray:
        """z0(x) = design height (pre-sag parabola) + sag parabola w (x-a)(x-b)/(2T) between fixed points."""
        L = self.span_m
        x = np.mod(np.asarray(x, dtype=float), L)
        fixed = np.concatenate([[0.0], np.sort(self.dropper_positions_m), [L]])
        design = -4.0 * self.presag_m * fixed * (L - fixed) / L**2
        i = np.clip(np.searchsorted(fixed, x, side="right") - 1, 0, len(fixed) - 2)
        a, b = fixed[i], fixed[i + 1]
        s = (x - a) / (b - a)
        chord = design[i] * (1 - s) + design[i + 1] * s
        w = self.wire_mass_kg_m * GRAVITY_M_S2
        return chord - w * (x - a) * (b - x) / (2.0 * self.wire_tension_N)


@dataclass(frozen=True)
class TabulatedProfile:
    """z0 tabulated over one span (x from 0 to span), interpolated linearly and periodically."""

    span_m: float
    x_m: np.ndarray
    z_m: np.ndarray

    def heights(self, x: np.ndarray) -> np.ndarray:
        """z0 at any x, interpolated periodically over the span [m]."""
        return np.interp(np.mod(np.asarray(x, dtype=float), self.span_m), self.x_m, self.z_m, period=self.span_m)


MAX_PROFILE_ROWS = 1_000_000


def read_profile_csv(path: Path, span_m: float) -> TabulatedProfile:
    """Read `x_m,z0_m` rows; x must increase and lie within [0, span], every value finite."""
    path = Path(path)
    try:
        text = read_input_text(path, "profile file")
    except InputFileError as exc:
        raise ProfileError(str(exc)) from None
    try:
        rows = list(itertools.islice(csv.DictReader(io.StringIO(text, newline="")), MAX_PROFILE_ROWS + 1))
        if len(rows) > MAX_PROFILE_ROWS:
            raise ProfileError(f"profile file {path}: more than the limit of {MAX_PROFILE_ROWS} rows")
        x = np.array([float(r["x_m"]) for r in rows])
        z = np.array([float(r["z0_m"]) for r in rows])
    except (KeyError, ValueError, TypeError, csv.Error) as exc:
        if isinstance(exc, ProfileError):
            raise
        raise ProfileError(f"profile file {path}: expected numeric columns x_m,z0_m ({exc})") from None
    bad = np.flatnonzero(~(np.isfinite(x) & np.isfinite(z)))
    if len(bad):
        raise ProfileError(f"profile file {path}: row {bad[0] + 1} is not finite (x_m {x[bad[0]]!r}, "
                           f"z0_m {z[bad[0]]!r})")
    if len(x) < 2 or np.any(np.diff(x) <= 0) or x[0] < 0 or x[-1] > span_m:
        raise ProfileError(f"profile file {path}: x_m must increase within [0, {span_m}] m")
    return TabulatedProfile(span_m, x, z)


def write_profile_csv(path: Path, profile, n_points: int = 6501) -> None:
    """Write a profile's z0 at n_points along the span as `x_m,z0_m` CSV."""
    x = np.linspace(0.0, profile.span_m, n_points)
    z = profile.heights(x)
    with Path(path).open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["x_m", "z0_m"])
        w.writerows((f"{a:.6f}", f"{b:.9e}") for a, b in zip(x, z, strict=False))
