"""Actuator motion limits: a command never leaves the stroke, the velocity or the acceleration limit.

LinMot PS10-70x240U (Paper D sec. 2): 5.4 m/s and 1650 N; the acceleration limit is the force limit
over the moving mass. The limiter clips the stroke and ramps the rest, one sample at a time. A wanted
height that is not a number holds the actuator where it is; its state and output are always finite.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pantohil.models.schema import param


@dataclass(frozen=True)
class ActuatorLimits:
    """[actuator] of a case, [limits] of a rig file: the limits every command is kept within (LinMot
    PS10-70x240U: 5.4 m/s, 1650 N)."""

    stroke_min_m: float = param(-0.12, "m", "lowest actuator position", -10.0, 10.0, fmu="adapter")
    stroke_max_m: float = param(0.12, "m", "highest actuator position", -10.0, 10.0, fmu="adapter")
    max_velocity_m_s: float = param(5.4, "m/s", "velocity limit", 0.0, 100.0, low_open=True, fmu="adapter")
    max_acceleration_m_s2: float = param(300.0, "m/s2", "acceleration limit (force limit / moving mass: ~1650 N "
                                                        "over a 5.5 kg slider and pantograph head)",
                                         0.0, 1e5, low_open=True, fmu="adapter")

    def __post_init__(self):
        if not self.stroke_min_m < self.stroke_max_m:
            raise ValueError("actuator stroke: the minimum must be below the maximum")
        if not (self.max_velocity_m_s > 0 and self.max_acceleration_m_s2 > 0):  # also refuses NaN
            raise ValueError("actuator limits: velocity and acceleration must be > 0")
        if not all(math.isfinite(x) for x in (self.stroke_min_m, self.stroke_max_m, self.max_velocity_m_s,
                                              self.max_acceleration_m_s2)):
            raise ValueError("actuator limits: every limit must be a finite number")


class Limiter:
    """Turns wanted heights into feasible ones; counts the samples it had to change. A NaN start is 0 m
    (within the stroke), a NaN wanted height keeps the current one: NaN never enters the state."""

    def __init__(self, limits: ActuatorLimits, dt_s: float, z0: float = 0.0):
        self.lim = limits
        self.dt = dt_s
        self.z = min(max(z0 if not math.isnan(z0) else 0.0, limits.stroke_min_m), limits.stroke_max_m)
        self.v = 0.0
        self.limited = 0

    def preview(self, wanted) -> tuple[np.ndarray, np.ndarray]:
        """The heights and velocities the limiter would give for the wanted heights that follow, from its
        present state, which it leaves unchanged: a horizon within the limits at every step. A horizon the
        limits do not touch (the usual case) is checked at once; otherwise it is limited step by step."""
        w = np.asarray(wanted, dtype=float)
        if self._passes(w):
            return w, np.diff(w, prepend=self.z) / self.dt
        saved = self.z, self.v, self.limited
        try:
            out = np.array([self(x) for x in w], dtype=float).reshape(-1, 2)
        finally:
            self.z, self.v, self.limited = saved
        return out[:, 0], out[:, 1]

    def _passes(self, w: np.ndarray) -> bool:
        """Whether the limiter would pass every wanted height unchanged: finite, within the stroke, and
        within the velocity, acceleration and braking limits of __call__, step after step."""
        lim, dt = self.lim, self.dt
        low, high = float(w.min(initial=self.z)), float(w.max(initial=self.z))  # NaN compares False below
        if not (lim.stroke_min_m <= low and high <= lim.stroke_max_m):
            return False
        v = np.diff(w, prepend=self.z) / dt
        dv_all = np.diff(v, prepend=self.v)
        a, dv = lim.max_acceleration_m_s2, lim.max_acceleration_m_s2 * dt
        v_max = float(np.abs(v).max())
        if float(np.abs(dv_all).max()) > dv * (1 - 1e-9) or v_max > lim.max_velocity_m_s * (1 - 1e-9):
            return False
        if min(lim.stroke_max_m - high, low - lim.stroke_min_m) > v_max ** 2 / a + 2 * (v_max + dv) * dt:
            return True  # far from both stroke ends: braking cannot bind
        z_prev = np.concatenate(([self.z], w[:-1]))
        v_prev = v - dv_all
        def brake(d):
            return np.maximum(0.0, np.sqrt(np.maximum(2 * a * d + (a * dt / 2) ** 2, 0.0)) - a * dt / 2)
        up = brake(lim.stroke_max_m - z_prev - v * dt)
        down = brake(z_prev + v * dt - lim.stroke_min_m)
        return bool(np.all(v <= np.maximum(up, v_prev - dv) * (1 - 1e-9) + 1e-15)
                    and np.all(v >= np.minimum(-down, v_prev + dv) * (1 - 1e-9) - 1e-15))

    def __call__(self, wanted: float) -> tuple[float, float]:
        lim, dt = self.lim, self.dt
        not_a_number = math.isnan(wanted)
        if not_a_number:  # min/max would pass NaN on and keep it as the state
            wanted = self.z
        target = min(max(wanted, lim.stroke_min_m), lim.stroke_max_m)
        v = (target - self.z) / dt
        dv = lim.max_acceleration_m_s2 * dt
        v = min(max(v, self.v - dv), self.v + dv)
        v = min(max(v, -lim.max_velocity_m_s), lim.max_velocity_m_s)
        # braking: the velocity towards an end must let the actuator stop before it (discrete bound)
        a = lim.max_acceleration_m_s2
        def brake(d):
            return max(0.0, ((2 * a * d + (a * dt / 2) ** 2) ** 0.5 - a * dt / 2))
        v = min(v, max(brake(lim.stroke_max_m - self.z - v * dt), self.v - dv))
        v = max(v, min(-brake(self.z + v * dt - lim.stroke_min_m), self.v + dv))
        z = min(max(self.z + v * dt, lim.stroke_min_m), lim.stroke_max_m)  # a safety net only
        v = (z - self.z) / dt
        if not_a_number or abs(z - wanted) > 1e-12:
            self.limited += 1
        self.z, self.v = z, v
        return z, v
