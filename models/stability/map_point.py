"""Spectral radius of the virtual HIL iteration at a point of a map, and the relaxation that minimises it
(Paper D sec. 4, Figs. 5-7: f_max, contact stiffness k_c and delay D; the best mu_c at every point).

The fastest exact construction is picked per point (models/stability/maps.py, models/stability/step_roots.py):
span-by-span on the range of I_cc; step-by-step with a circulant (ASM) operator by the roots of its
characteristic function, falling back to the dense one-step matrix when those fail their check; a
non-circulant (PFEM) operator in step-by-step by the dense span map.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from pantohil.models.hil.loop import HilSettings
from pantohil.models.pantograph.interface import linear_pantograph
from pantohil.models.pantograph.linear import LinearPantograph
from pantohil.models.pantograph.lumped import PantographParameters
from pantohil.models.stability.maps import (circulant_dense, circulant_range_basis, range_basis,
    reduced_span_parts, span_map, step_matrix)
from pantohil.models.stability.rig_map import (LOOP_CONNECTIONS, RigLoop, rig_span_maps, rig_span_parts, span_rate,
    step_rate)
from pantohil.models.stability.step_roots import step_loop, step_spectral_radius

# relaxations tried before the local refinement (the radius is not unimodal in mu everywhere)
RELAXATION_GRID = (0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.95)


@dataclass
class StabilityProblem:
    """One point of a map: the loop's operator, pantograph, strategy, latency and delay advance."""

    update: str
    pantograph: LinearPantograph
    latency_steps: int  # force sample -> height it produces (1 = the unavoidable step)
    delay_steps: int  # D, the advance of the commanded height (= latency when compensated)
    kernel: np.ndarray | None = None  # circulant I_cc (ASM): first column
    I_cc: np.ndarray | None = None  # dense I_cc (PFEM), or built from the kernel when needed
    basis: np.ndarray | None = None

    def __post_init__(self):
        if self.update not in ("step", "span"):
            raise ValueError(f"update must be 'step' or 'span', got {self.update!r}")
        if self.latency_steps < 1:
            raise ValueError(f"the loop latency must be at least one step, got {self.latency_steps}")
        if self.kernel is None and self.I_cc is None:
            raise ValueError("a stability problem needs the catenary operator")
        if self.update == "step" and self.kernel is not None:
            self._loop = step_loop(self.kernel, self.pantograph, self.delay_steps, self.latency_steps)
        if self.update == "span":
            if self.I_cc is None:
                self.I_cc = circulant_dense(self.kernel)
            if self.basis is None:
                self.basis = circulant_range_basis(self.kernel) if self.kernel is not None else range_basis(self.I_cc)
            self._span_parts = reduced_span_parts(self.I_cc, self.pantograph, self.delay_steps, self.latency_steps,
                                                  self.basis)

    def settings(self, mu: float) -> HilSettings:
        """The HIL settings of the problem at relaxation mu."""
        return HilSettings(self.update, mu, self.delay_steps)

    def spectral_radius(self, mu: float) -> float:
        """rho(A) of Paper D eq. (13) at relaxation mu."""
        if self.update == "span":
            return self._span_parts.at(mu).spectral_radius
        if self.kernel is not None:
            rho = step_spectral_radius(self._loop, mu)
            if math.isnan(rho):
                rho = step_matrix(self.kernel, self.pantograph, self.settings(mu), self.latency_steps).spectral_radius
            return rho
        return span_map(self.I_cc, self.pantograph, self.settings(mu), self.latency_steps).spectral_radius


@dataclass
class RigLoopProblem:
    """One point of a map for a case with a rig file: the loop of models/hil/rig_loop.py with the rig's chain
    in place of the pure delay (models/stability/rig_map.py); the same `spectral_radius(mu)` as
    StabilityProblem (the rate per span over the rig's pattern)."""

    update: str
    loop: RigLoop
    n_harmonics: int
    kernel: np.ndarray | None = None  # circulant I_cc (ASM): first column
    I_cc: np.ndarray | None = None  # dense I_cc (PFEM)

    def __post_init__(self):
        if self.update not in ("step", "span"):
            raise ValueError(f"update must be 'step' or 'span', got {self.update!r}")
        if self.update == "step" and self.kernel is None:
            raise ValueError("step-by-step updating with the rig's chain needs a circulant (ASM) operator")
        if self.update == "span":  # the plant's part of the span maps does not depend on mu: once
            I_cc = circulant_dense(self.kernel) if self.I_cc is None else self.I_cc
            self._parts = rig_span_parts(self.loop, I_cc, self.n_harmonics)

    def spectral_radius(self, mu: float) -> float:
        """The rate per span of Paper D eq. (13) with the rig's chain, at relaxation mu."""
        if self.update == "span":
            return span_rate(rig_span_maps(self._parts, mu))
        return step_rate(self.loop, self.kernel, mu)


def rig_problem_for(case, update: str, pantograph: PantographParameters, n_harmonics: int,
                    delay_steps: int | None = None, kernel: np.ndarray | None = None,
                    I_cc: np.ndarray | None = None) -> RigLoopProblem:
    """The stability problem of a case with a rig file at N_h harmonics: its chain in the loop, its response
    compensated at those harmonics if the case says so, and D = the case's advance unless given."""
    gz = gf = None
    if case.compensates_rig_response:
        gz, gf = case.rig_response(n_harmonics)
    d = case.delay_steps(LOOP_CONNECTIONS) if delay_steps is None else int(delay_steps)
    loop = RigLoop(linear_pantograph(pantograph, case.dt_s), case.rig_spec, case.dt_s, d, gz, gf, case.hold_steps)
    return RigLoopProblem(update, loop, n_harmonics, kernel=kernel, I_cc=I_cc)


def best_relaxation(problem: StabilityProblem, grid=RELAXATION_GRID, xatol: float = 2e-3) -> tuple[float, float]:
    """The mu_c in (0, 1) with the smallest spectral radius (Paper D Figs. 5b, 6b): a grid, then Brent's
    bounded search between the neighbours of the best grid point."""
    values = [problem.spectral_radius(mu) for mu in grid]
    i = int(np.argmin(values))
    lo = grid[i - 1] if i > 0 else grid[0] / 2
    hi = grid[i + 1] if i + 1 < len(grid) else 0.99
    res = minimize_scalar(problem.spectral_radius, bounds=(lo, hi), method="bounded", options={"xatol": xatol})
    if res.fun < values[i]:
        return float(res.x), float(res.fun)
    return float(grid[i]), float(values[i])


def with_contact_stiffness(params: PantographParameters, kc: float) -> PantographParameters:
    """The pantograph with penalty contact stiffness k_c (> 0) [N/m]."""
    if not kc > 0:
        raise ValueError(f"contact stiffness must be > 0, got {kc}")
    return dataclasses.replace(params, contact_stiffness_N_m=float(kc))


def contact_frequency_hz(params: PantographParameters, kc: np.ndarray) -> np.ndarray:
    """Natural frequency of the head on its contact spring against k_c (the red curve of Paper D Figs. 5-7)."""
    return np.sqrt((params.stiffnesses_N_m[0] + np.asarray(kc, dtype=float)) / params.masses_kg[0]) / (2 * np.pi)


def problem_for(update: str, pantograph: PantographParameters, dt_s: float, latency_steps: int, delay_steps: int,
                kernel: np.ndarray | None = None, I_cc: np.ndarray | None = None) -> StabilityProblem:
    """The stability problem of an update strategy, pantograph, latency and delay advance D.

    The operator is a circulant kernel (ASM) or a dense I_cc (PFEM).
    """
    return StabilityProblem(update, linear_pantograph(pantograph, dt_s), latency_steps, delay_steps, kernel=kernel,
                            I_cc=I_cc)
