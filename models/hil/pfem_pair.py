"""The HIL iteration of two contact points on the PFEM with dropper slackening (Paper A sec. 3.4's pair on the
iteration of Paper C sec. 5.3 and Paper D sec. 3): each pantograph's point steps the single point's iteration
(models/hil/droppers.py) on its own operators and its own droppers (models/catenary/pfem/pair_operators.py),
and each point's relaxed force increment also moves the other point's heights through the cross operators,
z_i += mu_c I_ij(:, n_bar) (f_j - f_j,relaxed(n_bar)) (Paper D eqs. 2, 10 for the pair), before either
commands. Each point commands its own height advanced by its own delay D_i, as models/hil/pair.py; the
updating strategy, relaxation, ramp and hold E are the case's, for both points.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from pantohil.models.catenary.pfem.pair_operators import PfemPairOperators
from pantohil.models.hil.droppers import PfemHil
from pantohil.models.hil.loop import HilSettings


class PfemPairHil:
    """Two PfemHil, one per contact point, coupled through I_12 and I_21: `step((f_1, f_2))` returns both
    commands. `points[i]` is point i's iteration; `z` and `force_estimate` are (2, N)."""

    POINTS = 2

    def __init__(self, pair: PfemPairOperators, settings: HilSettings, delay_steps: tuple[int, int],
                 dropper_relaxation: float = 1.0, droppers: bool = True):
        self.points = tuple(PfemHil(ops, dataclasses.replace(settings, delay_steps=int(d)), dropper_relaxation,
                                    droppers) for ops, d in zip((pair.first, pair.second), delay_steps, strict=True))
        self.cross = (np.ascontiguousarray(pair.i21.T), np.ascontiguousarray(pair.i12.T))  # [m]: column m
        self.s = settings
        self.n = self.points[0].n
        self.nd = self.points[0].nd
        # fixed after construction (not part of an FMU state): the cross operators and each point's own constants,
        # named on this object so that the FMU's state codec keeps them by reference
        names = ["cross", "s"]
        for i, point in enumerate(self.points):
            for attribute in point.CONSTANT_ATTRIBUTES:
                setattr(self, f"_point{i}{attribute}", getattr(point, attribute))
                names.append(f"_point{i}{attribute}")
        self.CONSTANT_ATTRIBUTES = tuple(names)

    @property
    def delays(self) -> tuple[int, int]:
        """Each point's delay advance D_i."""
        return tuple(p.s.delay_steps for p in self.points)

    @property
    def k(self) -> int:
        """Steps taken."""
        return self.points[0].k

    @property
    def z(self) -> np.ndarray:
        """Both points' converging heights (2, N) [m]."""
        return np.array([p.z for p in self.points])

    @property
    def force_estimate(self) -> np.ndarray:
        """Both points' forces in use (2, N) [N]."""
        return np.array([p.force_estimate for p in self.points])

    @property
    def current_correction(self) -> np.ndarray:
        """The first pantograph's droppers' corrections at this step's instant."""
        return self.points[0].current_correction

    def dense_operators(self) -> list[list[np.ndarray]]:
        """I_11, I_12, I_21, I_22 as N x N matrices (rows observed, columns loaded) as this iteration applies
        them: the stability map's (models/stability/pair_map.py). With droppers that slacken the map holds
        while they stay in tension."""
        own = [np.asarray(p.ops.cc, dtype=float).T for p in self.points]  # ops.cc[m] is column m
        return [[own[0], self.cross[1].T], [self.cross[0].T, own[1]]]

    def dense_compensation(self) -> None:
        """None: the PFEM pair has no coupling compensation."""
        return None

    def ahead(self, count: int, point: int = 0) -> np.ndarray:
        """The commands of point `point`'s next `count` steps as the iterate stands."""
        return self.points[point].ahead(count)

    def step(self, forces) -> tuple[float, float]:
        """Take both points' forces at the current sample (NaN: not measured) and return both commands."""
        n_bar = self.k % self.n
        for j, force in enumerate(forces):
            if not math.isnan(force):
                delta = self.s.relaxation * (force - self.points[j].force_relaxed[n_bar])
                if delta != 0.0:
                    self.points[1 - j].z += delta * self.cross[j][n_bar]
        return tuple(p.step(f) for p, f in zip(self.points, forces, strict=True))
