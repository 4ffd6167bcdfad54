"""The HIL rig between the catenary model and the pantograph: delay, communication decimation with
the drive's linear ramp, servo, load-cell filter, force offset and measurement noise.

Paper B sec. 4: one height of every N_com is sent to the drive, which ramps linearly from the old to
the new reference until the next one arrives. Paper D sec. 2: the loop delay; sec. 5.1: a force
added to the measurement. Every element's latency is counted in whole steps so that the master
can set the catenary's delay advance (Paper D sec. 3.4).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from pantohil.models.schema import XS_INT_MAX, param


@dataclass(frozen=True)
class RigParameters:
    """The simulated rig's keys of a case's [rig] (the rig file's name apart); the defaults are an ideal rig."""

    delay_steps: int = param(0, "1", "pure delay of the height path [steps]", 0, 100_000, fmu="rig")
    comm_decimation: int = param(1, "1", "N_com: one height of every N_com reaches the drive (1: every height, "
                                         "no drive ramp)", 1, 10_000, fmu="rig")
    servo_bandwidth_hz: float = param(0.0, "Hz", "servo natural frequency (0: ideal tracking)", 0.0, 1e5, fmu="rig")
    servo_damping: float = param(0.7, "1", "servo damping ratio", 0.0, 100.0, low_open=True, fmu="rig")
    loadcell_cutoff_hz: float = param(0.0, "Hz", "load-cell low-pass cut-off (0: none)", 0.0, 1e5, fmu="rig")
    force_offset_N: float = param(0.0, "N", "force added to the measurement", -1e4, 1e4, fmu="rig")
    noise_std_N: float = param(0.0, "N", "measurement noise standard deviation", 0.0, 1e4, fmu="rig")
    noise_seed: int = param(0, "1", "seed of the measurement noise", 0, XS_INT_MAX, fmu="rig")

    def latency_steps(self, dt_s: float) -> int:
        """Whole steps from a commanded height to the actuator reaching it, plus the force path's lag.

        Pure delay + N_com (the drive reaches a reference one ramp later) + the low-frequency group
        delays of the servo (2 zeta / w_n) and of the load-cell filter (1 / w_c), rounded.
        """
        lag = float(self.delay_steps)
        if self.comm_decimation > 1:
            lag += self.comm_decimation
        if self.servo_bandwidth_hz > 0:
            lag += 2 * self.servo_damping / (2 * math.pi * self.servo_bandwidth_hz) / dt_s
        if self.loadcell_cutoff_hz > 0:
            lag += 1.0 / (2 * math.pi * self.loadcell_cutoff_hz) / dt_s
        return int(round(lag))


class _DiscreteFilter:
    """A continuous transfer function discretised (bilinear) and run one sample at a time (DF-II T)."""

    def __init__(self, num, den, dt_s: float, initial: float):
        from scipy import signal  # here: scipy.signal takes seconds to import, and validating a case needs none of it

        b, a, _ = signal.cont2discrete((num, den), dt_s, method="bilinear")
        b = np.atleast_1d(np.squeeze(b))
        self.b = [float(v) / a[0] for v in b]
        self.a = [float(v) / a[0] for v in a]
        zi = signal.lfilter_zi(self.b, self.a) * initial
        self.state = [float(v) for v in zi]

    def __call__(self, x: float) -> float:
        b, a, s = self.b, self.a, self.state
        y = b[0] * x + s[0]
        for i in range(len(s)):
            nxt = s[i + 1] if i + 1 < len(s) else 0.0
            s[i] = b[i + 1] * x - a[i + 1] * y + nxt
        return y


class Rig:
    """Discrete-time rig. `step(z_command, f_true)` returns (actuator height, measured force)."""

    def __init__(self, params: RigParameters, dt_s: float, initial_height: float = 0.0,
                 initial_force: float = 0.0):
        self.p = params
        self.dt = dt_s
        self._delay = deque([initial_height] * params.delay_steps, maxlen=params.delay_steps or None)
        self._ref_old = initial_height
        self._ref_new = initial_height
        self._count = 0
        self._servo = None
        if params.servo_bandwidth_hz > 0:
            wn = 2 * math.pi * params.servo_bandwidth_hz
            self._servo = _DiscreteFilter(
                [wn * wn], [1.0, 2 * params.servo_damping * wn, wn * wn], dt_s, initial_height
            )
        self._loadcell = None
        if params.loadcell_cutoff_hz > 0:
            wc = 2 * math.pi * params.loadcell_cutoff_hz
            self._loadcell = _DiscreteFilter([wc], [1.0, wc], dt_s, initial_force)
        self._rng = np.random.default_rng(params.noise_seed)

    def _delayed(self, z: float) -> float:
        if not self._delay.maxlen:
            return z
        out = self._delay[0]
        self._delay.append(z)
        return out

    def _drive(self, z_ref: float) -> float:
        n = self.p.comm_decimation
        if n <= 1:
            return z_ref
        if self._count % n == 0:  # a new reference reaches the drive
            self._ref_old, self._ref_new = self._ref_new, z_ref
        self._count += 1
        j = (self._count - 1) % n + 1
        return self._ref_old + (self._ref_new - self._ref_old) * j / n

    def height(self, z_command: float) -> float:
        """Height path: delay, decimation with the drive's ramp, servo."""
        z = self._drive(self._delayed(z_command))
        return z if self._servo is None else self._servo(z)

    def force(self, f_true: float) -> float:
        """Force path: load-cell filter, offset, noise."""
        f = f_true if self._loadcell is None else self._loadcell(f_true)
        f += self.p.force_offset_N
        if self.p.noise_std_N > 0:
            f += float(self._rng.normal(0.0, self.p.noise_std_N))
        return f

    def step(self, z_command: float, f_true: float) -> tuple[float, float]:
        """One sample of the rig: (actuator height, measured force) for a commanded height and a true force."""
        return self.height(z_command), self.force(f_true)
