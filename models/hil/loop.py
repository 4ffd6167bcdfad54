"""The periodic HIL iteration (Paper B sec. 3, Paper C sec. 4, Paper D sec. 3).

Each call to `step` receives the force measured at the current sample of the current virtual span
(block) and returns the height to command, advanced by `delay_steps` samples so that it is reached
when the pantograph gets there (Paper D sec. 3.4). Samples are labelled n = 0..N-1 within a block.
A NaN force means "not measured" (a lost datagram): that sample keeps its previous value.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

UPDATES = ("step", "span")
MAX_HORIZON_STEPS = 64  # heights an answer carries at most (docs/udp-protocol.md: 1100 bytes, one frame)
HORIZON_AUTO_S = 0.1  # link.horizon_steps = "auto": the steps of this time


@dataclass(frozen=True)
class HilSettings:
    """Settings of the HIL iteration: update, relaxation mu_c, delay advance D, ramp N_r (Paper D sec. 3)."""
    update: str = "step"  # "step": Paper D eq. (2); "span": Paper D eq. (3)
    relaxation: float = 0.1  # mu_c, Paper D eq. (9)-(10)
    delay_steps: int = 1  # D: 1 is the unavoidable one-step loop (Paper D Fig. 4)
    ramp_steps: int = 0  # N_r, Paper D sec. 3.6
    hold_steps: int = 0  # E: extra loop delay, the command leaves E steps after it is computed (Paper D sec. 4)


def ramp_factor(settings: HilSettings, steps_done) -> np.ndarray | float:
    """The initial ramp's scale of the command returned by the step that makes `steps_done` steps
    (Paper D sec. 3.6): steps_done / N_r below N_r, else 1."""
    if settings.ramp_steps <= 0:
        return np.ones_like(steps_done, dtype=float) if isinstance(steps_done, np.ndarray) else 1.0
    return np.where(steps_done < settings.ramp_steps, steps_done / settings.ramp_steps, 1.0)


def commands_ahead(hil, count: int, blocks) -> np.ndarray:
    """The commands the next `count` steps (k, k + 1, ...) return if the iterate no longer changes: the
    horizon sent to the rig (docs/udp-protocol.md). At convergence they are exactly what those steps
    return. The commands in flight through the extra loop delay E come first; then, per step j, the
    iterate at sample n_bar_j + D (step-by-step, Paper D eq. 2) or the blend of eq. (3) of the block
    vectors `blocks[min(b_j - b_k, 2)]` = (older, newer) (span-by-span), scaled by the ramp."""
    s, n, k = hil.s, hil.n, hil.k
    held = list(hil._held)
    if s.hold_steps > 0 and not held:  # before the first step: the first command fills the line
        held = [None] * s.hold_steps
    in_flight = min(len(held), count)
    j = k + np.arange(max(count - in_flight, 1) if held and held[0] is None else max(count - in_flight, 0))
    n_bar = j % n
    target = (n_bar + s.delay_steps) % n
    if s.update == "step":
        values = hil.commands_at(hil.z, target)
    else:
        offset = np.minimum(j // n - k // n, 2)
        w_new = (n_bar + 1) / n
        values = np.empty(len(j))
        for b in np.unique(offset):
            older, newer = blocks[b]
            m = offset == b
            values[m] = ((1.0 - w_new[m]) * hil.commands_at(older, target[m])
                         + w_new[m] * hil.commands_at(newer, target[m]))
    computed = values * ramp_factor(s, j + 1)
    if held and held[0] is None:
        held = [computed[0]] * len(held)
    return np.concatenate([np.asarray(held[:in_flight], dtype=float), computed[:count - in_flight]])


def hold(line: list, command: float, steps: int) -> float:
    """The command computed `steps` steps ago (the extra loop delay E of Paper D sec. 4, Fig. 7); `line`
    holds the commands in flight, filled with the first one."""
    if steps <= 0:
        return command
    if not line:
        line.extend([command] * steps)
    line.append(command)
    return line.pop(0)


class PeriodicHil:
    """Step-by-step or span-by-span updating of the periodic contact-point height.

    `operator` exposes `column(m)` (response to a unit force at sample m) and `apply(f)`;
    `z0` is the (frequency-reduced) wire height at the N samples.
    """

    CONSTANT_ATTRIBUTES = ("op", "z0", "s", "comp")  # fixed after construction (not part of an FMU state)

    def __init__(self, operator, z0: np.ndarray, settings: HilSettings, compensation=None):
        """`compensation` (a `HarmonicCompensation`, optional): the rig's dynamics compensated at the kept
        harmonics; `operator` must then already take measured forces (I B)."""
        if settings.update not in UPDATES:
            raise ValueError(f"hil.update must be one of {UPDATES}, got {settings.update!r}")
        self.op = operator
        self.z0 = np.asarray(z0, dtype=float)
        self.n = len(self.z0)
        self.s = settings
        self.k = 0  # global step counter
        self.force_relaxed = np.zeros(self.n)  # r f: the force vector in use (Paper D eq. 9)
        self.z = self.z0.copy()  # z^k (step) / latest block vector z^b (span)
        self._z_older = self.z0.copy()  # z^{b-1} while z holds z^b (span)
        self._block_force = np.zeros(self.n)
        self.last_force = np.zeros(self.n)  # the force in use at each sample (measured, or kept when lost)
        self.comp = compensation
        self.force_estimate = self.last_force if compensation is None else np.zeros(self.n)  # B f: the true force
        self._held: list = []  # commands in flight through the extra loop delay E

    @property
    def sample(self) -> int:
        """Label of the sample the next measured force belongs to."""
        return self.k % self.n

    @property
    def span(self) -> int:
        """Index b of the virtual span (block) the next measured force belongs to."""
        return self.k // self.n

    def step(self, force: float) -> float:
        """Take the force measured at the current sample and return the height to command.

        Step-by-step: z += mu_c I_cc(n_bar) (f - f_relaxed) (Paper D eqs. 2, 10) and the command is z at
        n_bar + D; span-by-span: the blend of the last two block snapshots (eq. 3). A NaN force keeps the
        sample's previous value. The command is scaled by the initial ramp (sec. 3.6).
        """
        n_bar = self.k % self.n
        mu = self.s.relaxation
        measured = not math.isnan(force)  # NaN: not measured; the sample keeps its previous value
        if measured:
            if self.comp is not None:
                self.force_estimate += (force - self.last_force[n_bar]) * self.comp.force_column(n_bar)
            self.last_force[n_bar] = force
        if self.s.update == "step":
            if measured:
                delta = mu * (force - self.force_relaxed[n_bar])  # Paper D eq. (10)
                self.force_relaxed[n_bar] += delta
                if delta != 0.0:
                    self.z += delta * self.op.column(n_bar)
            command = self.command_at(self.z, (n_bar + self.s.delay_steps) % self.n)
        else:
            if measured:
                self._block_force[n_bar] = force
            command = self._span_command(n_bar)
            if n_bar == self.n - 1:  # block complete: Paper D eq. (A.8)
                z_new = mu * (self.z0 + self.op.apply(self._block_force)) + (1 - mu) * self.z
                self.force_relaxed = mu * self._block_force + (1 - mu) * self.force_relaxed
                self._z_older, self.z = self.z, z_new
        self.k += 1
        if self.s.ramp_steps > 0 and self.k < self.s.ramp_steps:
            command *= self.k / self.s.ramp_steps
        return float(hold(self._held, command, self.s.hold_steps))

    def command_at(self, z: np.ndarray, target: int) -> float:
        """The height to command for sample `target`: z there, or (A z) there with the rig compensated."""
        return float(z[target]) if self.comp is None else self.comp.command(z, target)

    def commands_at(self, z: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """command_at for an array of samples."""
        return z[targets] if self.comp is None else self.comp.commands(z, targets)

    def ahead(self, count: int) -> np.ndarray:
        """The commands of the next `count` steps as the iterate stands (`commands_ahead`); beyond the
        current block both block vectors are the latest, z (the next block's z is what z is at
        convergence)."""
        return commands_ahead(self, count, ((self._z_older, self.z), (self.z, self.z), (self.z, self.z)))

    def _span_command(self, n_bar: int) -> float:
        """Linear blend of the two latest block vectors, Paper D eq. (3), with the delay rotation (A.11)."""
        target = (n_bar + self.s.delay_steps) % self.n
        w_new = (n_bar + 1) / self.n
        return (1.0 - w_new) * self.command_at(self._z_older, target) + w_new * self.command_at(self.z, target)


class ConvergenceMonitor:
    """Span-to-span change of the measured force: rms(f^b - f^(b-P)) / std(f^b), over the samples
    measured in span b only.

    P = 1, unless the rig's own clocks (decimation, sub-references) repeat only every P spans: the
    steady state then repeats every P spans, not every span. A sample that was not measured keeps the
    previous span's value in the iteration, so its change would be exactly 0: it is left out of the
    change, and a span with no measured sample has an infinite change (it is evidence of nothing)."""

    def __init__(self, samples_per_span: int, period_spans: int = 1):
        self.n = samples_per_span
        self.period = max(1, int(period_spans))
        self.history: list[dict] = []
        self._prev: list[np.ndarray] = []

    def close_span(self, span: int, force: np.ndarray, measured: np.ndarray | None = None) -> dict:
        """Record one finished span: its change rms(f^b - f^(b-1)) / std(f^b) over the samples measured in
        it (`measured`, a boolean mask; None: all), their count, mean, std, max and min."""
        std = float(np.std(force))
        count = len(force) if measured is None else int(np.count_nonzero(measured))
        if len(self._prev) < self.period or count == 0:
            change = float("inf")
        else:
            diff = force - self._prev[0] if measured is None else (force - self._prev[0])[measured]
            change = float(np.sqrt(np.mean(diff ** 2)) / max(std, 1e-12))
        if len(self._prev) >= self.period:
            self._prev.pop(0)
        self._prev.append(force.copy())
        rec = {"span": span, "change": change, "mean_N": float(np.mean(force)), "std_N": std,
               "max_N": float(np.max(force)), "min_N": float(np.min(force)), "measured": count}
        self.history.append(rec)
        return rec

    def diverging(self, window: int, threshold: float, first_span: int = 0) -> float | None:
        """Median change over the last `window` spans (from `first_span` on) if it exceeds `threshold` and has
        not fallen since the window before: an unstable iteration whose growth contact loss bounds settles in
        a limit cycle, not at the force limit, while a stable one's early transient decays."""
        changes = [h["change"] for h in self.history[first_span:]]
        if len(changes) < 2 * window:
            return None
        median = float(np.median(changes[-window:]))
        before = float(np.median(changes[-2 * window:-window]))
        return median if median > threshold and median >= before else None
