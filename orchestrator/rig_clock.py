"""The rig controller's own clock for the rig-paced emulator, and streaming percentiles.

A real controller (Paper D sec. 2: the CompactRIO's 2 ms main loop) ticks on its own oscillator,
which drifts against the model computer's: tick k is due at t0 + k dt (1 + drift) + jitter_k. A
slow-motion clock (factor s > 1) is due at t0 + k s dt (1 + drift) + jitter_k while the rig still
counts dt per tick: the link's logic is tested without a 1 ms deadline on the machine.
"""
from __future__ import annotations

import math
import random

import numpy as np


class RigClock:
    """Tick times of a free-running loop: nominal period dt_s, drift in ppm, uniform jitter, and a
    slow-motion factor on the wall-clock period (1: real time)."""

    def __init__(self, dt_s: float, start_ns: int, drift_ppm: float = 0.0, jitter_us: float = 0.0,
                 seed: int = 0, slow_motion: float = 1.0):
        self.dt_s = dt_s
        self.period_ns = dt_s * 1e9 * slow_motion * (1.0 + drift_ppm * 1e-6)
        self.jitter_ns = min(jitter_us * 1e3, 0.45 * self.period_ns)  # ticks never swap places
        self.start_ns = start_ns
        self._rng = random.Random(seed)
        self.tick = 0  # the last tick done
        self.due_ns = self._due(1)

    def _due(self, k: int) -> int:
        jitter = self._rng.uniform(-self.jitter_ns, self.jitter_ns) if self.jitter_ns else 0.0
        return int(self.start_ns + k * self.period_ns + jitter)

    def advance(self) -> int:
        """Take the due tick; returns its number and schedules the next one."""
        self.tick += 1
        self.due_ns = self._due(self.tick + 1)
        return self.tick

    def rig_time_ns(self, k: int) -> int:
        """The rig's own idea of tick k's time (its oscillator counts dt per tick)."""
        return int(round(k * self.dt_s * 1e9))


class Percentiles:
    """Streaming percentiles of positive durations in bins 1 % wide (memory independent of the count);
    the maximum is exact."""

    RATIO = 1.01
    LOWEST_US = 0.1

    def __init__(self, highest_us: float = 1e8):
        self.counts = np.zeros(int(math.log(highest_us / self.LOWEST_US, self.RATIO)) + 2, dtype=np.int64)
        self.n = 0
        self.max_us = 0.0

    def add(self, us: float) -> None:
        """Count one value [us] into its logarithmic bin."""
        self.n += 1
        self.max_us = max(self.max_us, us)
        i = 0 if us <= self.LOWEST_US else int(math.log(us / self.LOWEST_US, self.RATIO)) + 1
        self.counts[min(i, len(self.counts) - 1)] += 1

    def quantile(self, q: float) -> float:
        """The upper edge of the bin holding the q-quantile (within 1 % above the true value)."""
        if self.n == 0:
            return math.nan
        i = int(np.searchsorted(np.cumsum(self.counts), q * self.n))
        return min(self.LOWEST_US * self.RATIO ** i, self.max_us)

    def summary(self) -> dict:
        """p50, p99, max [us] and count of the values added."""
        return {"p50": self.quantile(0.5), "p99": self.quantile(0.99), "max": self.max_us, "n": self.n}
