"""The variables of a catenary design (Paper D sec. 5.3, after its reference [16]): the contact-wire heights at
the droppers (OC1) or the dropper positions (OC2), both keeping the span symmetric, and the limits a designer
sets on them. A design is a catenary file's parsed TOML with the variables written in; form-finding
(models/catenary/fe/model.py) finds the dropper lengths and tensions that hold it, and says in one line when
none do.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from pantohil.models.catenary.fe.definition import CatenaryDefinition
from pantohil.models.errors import InputError
from pantohil.models.schema import param


@dataclass(frozen=True)
class DesignLimits:
    """What a design may do: the geometric limits a designer sets (`pantohil optimise` options)."""

    max_height_deviation_m: float = param(0.1, "m", "largest change of a contact-wire height at a dropper from "
                                                    "the nominal design", 0.0, 1.0, low_open=True)
    min_dropper_length_m: float = param(0.3, "m", "shortest dropper", 0.0, 10.0)
    min_dropper_spacing_m: float = param(3.0, "m", "shortest distance between droppers, and from a dropper to a "
                                                   "support or to the stitch wire's clamp", 0.0, 100.0,
                                         low_open=True)


class DesignSpace(Protocol):
    """One kind of design variable (a registry entry of `DESIGNS`)."""

    name: str

    def variables(self, cat: CatenaryDefinition) -> list[str]:
        """The names of the free variables (the first half of the span's droppers)."""

    def start(self, cat: CatenaryDefinition) -> np.ndarray:
        """The nominal design's values."""

    def bounds(self, cat: CatenaryDefinition, limits: DesignLimits) -> list[tuple[float, float]]:
        """Lower and upper bound of each variable."""

    def apply(self, raw: dict, cat: CatenaryDefinition, x: np.ndarray) -> dict:
        """A copy of the catenary file's TOML with the design x written in."""


def half(n: int) -> int:
    """Free droppers of a symmetric span of n: the first half; a middle one stays at mid-span (positions) or is
    free (heights)."""
    return n // 2


def mirror(values: np.ndarray, n: int, middle: float | None) -> list[float]:
    """The n values of a symmetric span from its first half (and its middle value, n odd)."""
    first = [float(v) for v in values[:n // 2]]
    centre = [float(middle)] if n % 2 else []
    return first + centre + first[::-1]


def mirrored_positions(first_half: np.ndarray, span_m: float, n: int) -> list[float]:
    """Dropper positions of a symmetric span from its first half (a middle dropper at mid-span)."""
    first = [float(v) for v in first_half]
    centre = [span_m / 2] if n % 2 else []
    return first + centre + [span_m - v for v in first[::-1]]


def check_symmetric(cat: CatenaryDefinition) -> None:
    """The designs keep the span symmetric: the nominal one must be."""
    x = np.array(cat.dropper_positions_m)
    if np.abs(x + x[::-1] - cat.span_m).max() > 1e-6:
        raise InputError("catenary.dropper_positions_m: the span is not symmetric; the designs keep it so",
                         key="catenary.dropper_positions_m")
    h = cat.design_height(x)
    if np.abs(h - h[::-1]).max() > 1e-9:
        raise InputError("catenary.contact_wire_heights_m: the heights are not symmetric; the designs keep them so",
                         key="catenary.contact_wire_heights_m")


class HeightsDesign:
    """OC1: the contact-wire heights at the droppers (the middle one too), the dropper positions kept."""

    name = "heights"

    def variables(self, cat):
        """h_1 .. h_k, k = ceil(n / 2)."""
        return [f"height_{i + 1}_m" for i in range((len(cat.dropper_positions_m) + 1) // 2)]

    def start(self, cat):
        """The nominal heights (the pre-sag parabola's at the droppers, or the file's)."""
        return cat.design_height(np.array(cat.dropper_positions_m))[:len(self.variables(cat))]

    def bounds(self, cat, limits):
        """The nominal heights +- max_height_deviation_m."""
        d = limits.max_height_deviation_m
        return [(float(h - d), float(h + d)) for h in self.start(cat)]

    def apply(self, raw, cat, x):
        """contact_wire_heights_m written, presag_m removed."""
        n = len(cat.dropper_positions_m)
        out = copy.deepcopy(raw)
        c = out["catenary"]
        c.pop("presag_m", None)
        c.pop("presag_between", None)
        c["contact_wire_heights_m"] = mirror(np.asarray(x), n, x[-1] if n % 2 else None)
        return out


class SpacingDesign:
    """OC2: the dropper positions (a middle dropper stays at mid-span), each dropper kept on the wire it hangs
    from (the stitch wire or the messenger); the contact-wire design (pre-sag or heights) kept by dropper."""

    name = "spacing"

    def variables(self, cat):
        """x_1 .. x_k, k = floor(n / 2)."""
        return [f"position_{i + 1}_m" for i in range(half(len(cat.dropper_positions_m)))]

    def start(self, cat):
        """The nominal positions."""
        return np.array(cat.dropper_positions_m[:half(len(cat.dropper_positions_m))], dtype=float)

    def bounds(self, cat, limits):
        """Each dropper within its nominal interval: from half-way to its neighbour (or the support) to
        half-way to the next, min_dropper_spacing_m / 2 inside both, and on the wire it hangs from (the stitch
        wire's clamp min_dropper_spacing_m / 2 away). Disjoint boxes: every design keeps the droppers apart."""
        s, L = limits.min_dropper_spacing_m, cat.span_m
        x = np.array(cat.dropper_positions_m, dtype=float)
        edges = np.concatenate([[-x[0]], x, [2 * L - x[-1]]])  # mirrored supports: the first box starts at s / 2 ...
        clamp = cat.stitch_length_m / 2 if cat.stitch is not None else None
        out = []
        for i in range(len(self.variables(cat))):
            lo, hi = 0.5 * (edges[i] + edges[i + 1]) + s / 2, 0.5 * (edges[i + 1] + edges[i + 2]) - s / 2
            lo = max(lo, s)  # ... and at least s from the support
            if clamp is not None:
                lo, hi = (lo, min(hi, clamp - s / 2)) if x[i] < clamp else (max(lo, clamp + s / 2), hi)
            if not lo < hi:
                raise InputError(f"--min-dropper-spacing: {s:g} m leaves dropper {i + 1} no room to move",
                                 key="--min-dropper-spacing")
            out.append((float(lo), float(hi)))
        return out

    def apply(self, raw, cat, x):
        """dropper_positions_m written (dropper_spacing_m removed); given heights stay with their droppers."""
        out = copy.deepcopy(raw)
        c = out["catenary"]
        c.pop("dropper_spacing_m", None)
        c["dropper_positions_m"] = mirrored_positions(np.asarray(x), cat.span_m, len(cat.dropper_positions_m))
        return out


DESIGNS: dict[str, DesignSpace] = {"heights": HeightsDesign(), "spacing": SpacingDesign()}


def design_space(name: str) -> DesignSpace:
    """The registered design space `name`; InputError naming --vary otherwise."""
    if name not in DESIGNS:
        raise InputError(f"--vary: unknown design variable {name!r} (choose from {', '.join(DESIGNS)})", key="--vary")
    return DESIGNS[name]
