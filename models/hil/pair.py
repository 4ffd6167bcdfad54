"""The periodic HIL iteration for two contact points (the HIL extension of Paper A sec. 3.4; Paper C sec. 7
names it as the PFEM's future work).

Both pantographs' samples are periodic with the span, so the span-to-span iteration of Paper D sec. 3
applies to the pair: the heights z_i (i = 1, 2) at the N samples of each point are updated from both
points' forces through the four operators I_ij (the height at i from a unit force at j),
    step-by-step:  z_i += mu_c I_ij(:, n_bar) (f_j - f_j,relaxed(n_bar))  for j = 1, 2  (Paper D eqs. 2, 10)
    span-by-span:  z_i^(b+1) = mu_c (z0_i + sum_j I_ij f_j^b) + (1 - mu_c) z_i^b       (Paper D eq. A.8)
and each point commands its own height advanced by its own delay D_i (Paper D sec. 3.4): a pantograph on
the rig behind the rig's latency, a virtual one behind the master's connections. The relaxation, the
initial ramp and the extra loop delay E are the case's, for both points.

The cross coupling of the two points can make that iteration diverge where each point alone converges (the
leading pantograph's wave reaches the trailing one almost undamped at low harmonics). With a coupling
compensation Q (models/catenary/asm/pair.py `coupling_compensation`), the force residuals r_j = f_j -
f_j,relaxed are applied through Q: f_relaxed += mu_c Q r and z = z0 + I f_relaxed, so that, with the
pantographs' model receptance in Q, the pair iterates as two contact points alone; the fixed point is the
same with or without Q.
"""
from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np

from .loop import UPDATES, HilSettings, commands_ahead, hold


class PairedHil:
    """Step-by-step or span-by-span updating of the heights at two contact points.

    `operators[i][j]` exposes `column(m)` (the heights at point i from a unit force at point j at sample m)
    and `apply(f)`; `z0` holds the (frequency-reduced) static heights of both points, shape (2, N);
    `delay_steps` the advance D of each point (settings.delay_steps is not used)."""

    CONSTANT_ATTRIBUTES = ("ops", "z0", "s", "delays", "q", "iq")
    POINTS = 2

    def __init__(self, operators, z0: np.ndarray, settings: HilSettings, delay_steps: tuple[int, int],
                 compensation: tuple | None = None):
        """`compensation` (Q, I Q), each 2 x 2 operators as `operators`: the coupling compensation."""
        if settings.update not in UPDATES:
            raise ValueError(f"hil.update must be one of {UPDATES}, got {settings.update!r}")
        self.ops = operators
        self.z0 = np.array(z0, dtype=float).reshape(self.POINTS, -1)
        self.n = self.z0.shape[1]
        self.s = settings
        self.delays = tuple(int(d) for d in delay_steps)
        self.k = 0
        self.force_relaxed = np.zeros((self.POINTS, self.n))
        self.z = self.z0.copy()
        self._z_older = self.z0.copy()
        self._block_force = np.zeros((self.POINTS, self.n))
        self.last_force = np.zeros((self.POINTS, self.n))  # the force in use at each sample of each point
        self.force_estimate = self.last_force
        self._held: tuple[list, list] = ([], [])
        self.q, self.iq = compensation if compensation is not None else (None, None)

    @property
    def sample(self) -> int:
        """Label of the sample the next measured forces belong to."""
        return self.k % self.n

    @property
    def span(self) -> int:
        """Index b of the virtual span the next measured forces belong to."""
        return self.k // self.n

    def dense_operators(self) -> list[list[np.ndarray]]:
        """I_ij as N x N matrices (rows observed at point i, columns loaded at point j): the stability map's."""
        return [[self.ops[i][j].dense() for j in range(self.POINTS)] for i in range(self.POINTS)]

    def dense_compensation(self) -> tuple[list, list] | None:
        """(Q, I Q) as N x N matrices per pair of points, or None without the coupling compensation."""
        if self.q is None:
            return None
        return ([[self.q[i][j].dense() for j in range(self.POINTS)] for i in range(self.POINTS)],
                [[self.iq[i][j].dense() for j in range(self.POINTS)] for i in range(self.POINTS)])

    def ahead(self, count: int, point: int = 0) -> np.ndarray:
        """The commands of the next `count` steps at `point` as the iterate stands (`commands_ahead`): the horizon
        sent to the rig that carries that point's pantograph."""
        older, newer = self._z_older[point], self.z[point]
        view = SimpleNamespace(s=dataclasses.replace(self.s, delay_steps=self.delays[point]), n=self.n, k=self.k,
                               _held=self._held[point], commands_at=lambda z, targets: z[targets], z=newer)
        return commands_ahead(view, count, ((older, newer), (newer, newer), (newer, newer)))

    def step(self, forces) -> tuple[float, float]:
        """Take both points' forces measured at the current sample (NaN: not measured, the sample keeps its
        previous value) and return the heights to command at both, each advanced by its own D and scaled by
        the initial ramp."""
        n_bar = self.k % self.n
        mu = self.s.relaxation
        measured = [not math.isnan(f) for f in forces]
        for j in range(self.POINTS):
            if measured[j]:
                self.last_force[j, n_bar] = forces[j]
        if self.s.update == "step":
            self._update_step(n_bar, forces, measured, mu)
            commands = [self.z[i, (n_bar + self.delays[i]) % self.n] for i in range(self.POINTS)]
        else:
            for j in range(self.POINTS):
                if measured[j]:
                    self._block_force[j, n_bar] = forces[j]
            commands = [self._span_command(i, n_bar) for i in range(self.POINTS)]
            if n_bar == self.n - 1:
                self._update_span(mu)
        self.k += 1
        if self.s.ramp_steps > 0 and self.k < self.s.ramp_steps:
            commands = [c * self.k / self.s.ramp_steps for c in commands]
        return tuple(float(hold(self._held[i], commands[i], self.s.hold_steps)) for i in range(self.POINTS))

    def _update_step(self, n_bar: int, forces, measured, mu: float) -> None:
        """Paper D eqs. (2), (10) for both points' residuals at once, through the operators they drive (and Q)."""
        deltas = [mu * (forces[j] - self.force_relaxed[j, n_bar]) if measured[j] else 0.0
                  for j in range(self.POINTS)]
        for j, delta in enumerate(deltas):
            if delta == 0.0:
                continue
            if self.q is None:
                self.force_relaxed[j, n_bar] += delta
            for i in range(self.POINTS):
                if self.q is None:
                    self.z[i] += delta * self.ops[i][j].column(n_bar)
                else:
                    self.force_relaxed[i] += delta * self.q[i][j].column(n_bar)
                    self.z[i] += delta * self.iq[i][j].column(n_bar)

    def _update_span(self, mu: float) -> None:
        """Paper D eq. (A.8) for the pair, at the end of a block: f_relaxed += mu_c Q (f - f_relaxed), and
        z = z0 + I f_relaxed."""
        residual = self._block_force - self.force_relaxed
        if self.q is not None:
            residual = np.array([sum(self.q[i][j].apply(residual[j]) for j in range(self.POINTS))
                                 for i in range(self.POINTS)])
        self.force_relaxed = self.force_relaxed + mu * residual
        z_new = np.array([self.z0[i] + sum(self.ops[i][j].apply(self.force_relaxed[j]) for j in range(self.POINTS))
                          for i in range(self.POINTS)])
        self._z_older, self.z = self.z, z_new

    def _span_command(self, i: int, n_bar: int) -> float:
        """Linear blend of point i's two latest block vectors, Paper D eq. (3), advanced by its D."""
        target = (n_bar + self.delays[i]) % self.n
        w_new = (n_bar + 1) / self.n
        return (1.0 - w_new) * self._z_older[i, target] + w_new * self.z[i, target]
