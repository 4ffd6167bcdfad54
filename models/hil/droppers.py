"""The HIL iteration on PFEM operators with dropper slackening (Paper C sec. 5.3, eqs. 34-40; Paper D
sec. 3.2-3.7): the contact height z and the dropper elongations are updated at every step with the
relaxed force increment; then every dropper's correction force at its current instant is solved
from eq. (40) for the droppers that slacken; the height command is taken D samples ahead, from z
(step-by-step) or from the blend of the last two block snapshots (span-by-span, Paper D eq. 3).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from pantohil.models.hil.kernels import solve_small
from pantohil.models.hil.loop import UPDATES, HilSettings, commands_ahead, hold
from pantohil.models.catenary.pfem.operator_data import PfemOperators
from pantohil.models.catenary.pfem.steady_state import irfft_rows
from pantohil.models.catenary.receptance import reduce_harmonics


class PfemHil:
    """HIL iteration on PFEM operators with dropper slackening (Paper C sec. 5.3, Paper D eqs. 11-12)."""
    # fixed after construction (not part of an FMU state)
    CONSTANT_ATTRIBUTES = ("ops", "s", "z0", "_dc", "_dd", "_basis", "f0", "kd", "win", "_d", "_window_index",
                           "_basis_at", "_dd_at", "_slack_below", "comp")

    def __init__(self, ops: PfemOperators, settings: HilSettings, dropper_relaxation: float = 1.0,
                 droppers: bool = True, compensation=None):
        """`compensation` (a `HarmonicCompensation`, optional): the rig's dynamics compensated at the kept
        harmonics: the contact columns take measured forces (B), the command is A z."""
        if compensation is not None:
            ops = replace(ops, cc=compensation.compensate_rows(ops.cc), dc=compensation.compensate_rows(ops.dc))
        if settings.update not in UPDATES:
            raise ValueError(f"hil.update must be one of {UPDATES}, got {settings.update!r}")
        self.ops, self.s = ops, settings
        self.n = n = ops.n
        self.nd = ops.n_droppers if droppers else 0
        self.mu_d = dropper_relaxation
        self.z0 = reduce_harmonics(ops.z0, ops.settings.n_harmonics)
        self.z = self.z0.copy()
        self._z_older = self.z0.copy()
        self._z_block = self.z0.copy()
        self.k = 0
        self.force_relaxed = np.zeros(n)
        self.last_force = np.zeros(n)
        self.comp = compensation
        self.force_estimate = self.last_force if compensation is None else np.zeros(n)  # B f: the true force
        self._held: list = []  # commands in flight through the extra loop delay E
        jd = ops.settings.n_harmonics_dropper
        # elongations as the real and imaginary parts of their harmonics over the window index, so that
        # one step is a few small real products
        self.elongation = np.zeros((ops.n_droppers, 2 * jd))
        self._dc = np.concatenate([ops.dc.real, ops.dc.imag], axis=-1)
        self._dd = np.concatenate([ops.dd.real, ops.dd.imag], axis=-1)
        self._basis = irfft_rows(n, jd)  # irfft row i
        self.f0 = ops.dropper_tension_N
        self.kd = ops.dropper_stiffness_N_m
        self.win = ops.window_start
        self._d = np.arange(ops.n_droppers)
        # everything a step needs, by the phase n_bar of the step (each dropper has one instant per phase)
        self._window_index = (np.arange(n)[:, None] - self.win[None, :]) % n  # [n_bar, d]
        self._basis_at = self._basis[self._window_index]  # [n_bar, d, j]
        self._dd_at = self._dd[self._d[None, :], self._window_index] if ops.n_droppers else self._dd  # [n_bar, d, e, j]
        self.correction_at = np.zeros((n, ops.n_droppers))  # f_d in use, by the phase of its instant
        self._slack_below = -self.f0 / self.kd if ops.n_droppers else self.f0
        self.current_correction = np.zeros(ops.n_droppers)  # at this step's instant, per dropper

    @property
    def sample(self) -> int:
        """Label n_bar of the sample the next measured force belongs to."""
        return self.k % self.n

    @property
    def span(self) -> int:
        """Index b of the virtual span (block) the next measured force belongs to."""
        return self.k // self.n

    def command_at(self, z: np.ndarray, target: int) -> float:
        """The height to command for sample `target`: z there, or (A z) there with the rig compensated."""
        return float(z[target]) if self.comp is None else self.comp.command(z, target)

    def commands_at(self, z: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """command_at for an array of samples."""
        return z[targets] if self.comp is None else self.comp.commands(z, targets)

    def ahead(self, count: int) -> np.ndarray:
        """The commands of the next `count` steps as the iterate stands (`commands_ahead`): the current
        block blends its two snapshots, the next one the last snapshot and z, later ones z."""
        return commands_ahead(self, count, ((self._z_older, self._z_block), (self._z_block, self.z),
                                            (self.z, self.z)))

    def step(self, force: float) -> float:
        """Take the force measured at the current sample and return the height to command.

        The relaxed force increment updates z and the dropper elongations (Paper C eqs. 34-35, Paper D
        eq. 10); the slack droppers' correction forces are solved at their current instants (Paper C
        eq. 40); the command is taken D samples ahead, from z or from the blend of the last two blocks
        (Paper D eq. 3), and scaled by the initial ramp.
        """
        n_bar = self.k % self.n
        if not math.isnan(force):
            if self.comp is not None:
                self.force_estimate += (force - self.last_force[n_bar]) * self.comp.force_column(n_bar)
            self.last_force[n_bar] = force
            delta = self.s.relaxation * (force - self.force_relaxed[n_bar])  # Paper D eq. (10)
            if delta != 0.0:
                self.force_relaxed[n_bar] += delta
                self.z += delta * self.ops.cc[n_bar]  # Paper C eq. (34)
                if self.nd:
                    self.elongation += delta * self._dc[n_bar]  # eq. (35)
        if self.nd:
            self._correct(n_bar)
        if self.s.update == "step":
            command = self.command_at(self.z, (n_bar + self.s.delay_steps) % self.n)
        else:
            target = (n_bar + self.s.delay_steps) % self.n
            w_new = (n_bar + 1) / self.n
            command = ((1.0 - w_new) * self.command_at(self._z_older, target)
                       + w_new * self.command_at(self._z_block, target))
            if n_bar == self.n - 1:
                self._z_older, self._z_block = self._z_block, self.z.copy()
        self.k += 1
        if self.s.ramp_steps > 0 and self.k < self.s.ramp_steps:
            command *= self.k / self.s.ramp_steps
        return float(hold(self._held, command, self.s.hold_steps))

    @property
    def correction(self) -> np.ndarray:
        """Correction forces in use by dropper and window index."""
        out = np.zeros((self.ops.n_droppers, self.n))
        out[self._d[None, :], self._window_index] = self.correction_at
        return out

    def _correct(self, n_bar: int) -> None:
        """Eqs. (38)-(40) at each dropper's instant of phase n_bar, then eqs. (36)-(37). The sums of products are
        numpy's pairwise sums and the small system is `solve_small`, in the order the compiled block
        (models/hil/kernels.py `dropper_corrections`) repeats to the bit."""
        B = self._basis_at[n_bar]  # [d, j]
        dl = (B * self.elongation).sum(axis=1)
        old = self.correction_at[n_bar]
        self.current_correction = old  # a view: updated in place below
        slack = dl < self._slack_below  # eq. (38): k_d dL < -f_d0
        active = np.flatnonzero(slack | (old != 0.0))
        if len(active) == 1:  # the common case, without the small linear algebra
            a = active[0]
            col = self._dd_at[n_bar, a]  # [observed e, j]
            new = 0.0
            if slack[a]:
                daa = (col[a] * B[a]).sum()
                new = (-self.f0[a] - self.kd[a] * (dl[a] - daa * old[a])) / (1.0 + self.kd[a] * daa)
            change = self.mu_d * (new - old[a])
            old[a] += change
            self.z += change * self.ops.cd[n_bar, a]
            self.elongation += change * col
            return
        if not len(active):
            return
        cols = self._dd_at[n_bar, active]  # [active loaded d, observed e, j]
        old_a = old[active]
        new = np.zeros(len(active))
        s = np.flatnonzero(slack[active])
        if len(s):
            rows = active[s]
            # D[r, a]: elongation of slack dropper r per unit correction of active dropper a
            D = np.ascontiguousarray((cols[:, rows] * B[rows][None]).sum(axis=2).T)
            ks = self.kd[rows]
            rhs = -self.f0[rows] - ks * (dl[rows] - (D * old_a).sum(axis=1))
            if len(s) == 1:
                new[s] = rhs / (1.0 + ks[0] * D[0, s[0]])
            else:
                new[s] = solve_small(np.eye(len(s)) + ks[:, None] * D[:, s], rhs)  # eq. (40)
        change = self.mu_d * (new - old_a)
        old[active] += change  # a view: correction_at[n_bar]
        for i, a in enumerate(active):  # eqs. (36)-(37), dropper by dropper
            self.z += change[i] * self.ops.cd[n_bar, a]
            self.elongation += change[i] * cols[i]
