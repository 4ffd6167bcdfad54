"""Wall-clock pacing of the master (FMI 2.0 has no notion of real time): step k starts at
t0 + k dt. Sleep until shortly before, then spin; record how late each step started and whether it
finished inside its slot."""
from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import gc
import os
import time

import numpy as np

SPIN_S = 0.0001  # spin (not sleep) for the last 0.1 ms: sleep wakes up ~60 us late. Spinning much longer
                 # starves a rig emulator or logger on the machine, and under SCHED_FIFO it runs into the
                 # kernel's RT throttling (95 % per second: a 50 ms stall every second, measured)


MCL_CURRENT = 1  # <sys/mman.h>


def set_realtime_priority(priority: int | None) -> str:
    """SCHED_FIFO at `priority` for this process if permitted (root or CAP_SYS_NICE); returns what it got.
    The process must sleep most of each step (the pacer does): the kernel's RT throttling still applies."""
    if not priority:
        return "normal"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return f"SCHED_FIFO {priority}"
    except (PermissionError, OSError, AttributeError):
        return "normal (SCHED_FIFO not permitted)"


def lock_memory() -> str:
    """Lock the process's pages in RAM (mlockall MCL_CURRENT) if permitted, so that no page fault stalls an
    answer; returns what it got. Pages mapped later are not locked (MCL_FUTURE could make a later
    allocation fail under a memory-lock limit)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        if libc.mlockall(MCL_CURRENT) == 0:
            return "memory locked"
        return f"memory not locked ({os.strerror(ctypes.get_errno())})"
    except (OSError, AttributeError, TypeError):
        return "memory not locked (no mlockall)"


def unlock_memory() -> None:
    """Undo lock_memory."""
    with contextlib.suppress(OSError, AttributeError, TypeError):
        ctypes.CDLL(ctypes.util.find_library("c")).munlockall()


def background_priority() -> None:
    """For helper processes (the logger): never compete with the stepping loop or a rig emulator."""
    with contextlib.suppress(OSError, AttributeError):
        os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
    with contextlib.suppress(OSError):
        os.nice(10)


class Pacer:
    """Paces a master at dt against the wall clock and records each step's lateness and duration."""
    def __init__(self, dt_s: float, capacity: int):
        self.dt = dt_s
        self.lateness_ns = np.zeros(capacity, dtype=np.int64)
        self.duration_ns = np.zeros(capacity, dtype=np.int64)
        self.misses = 0
        self.steps = 0
        self._t0 = None
        self._gc_was_enabled = gc.isenabled()

    def start(self) -> None:
        """Start the clock (the first step 2 ms from now) with the garbage collector off."""
        gc.collect()
        gc.disable()  # a collection pause would miss deadlines; the loop makes little garbage
        self._t0 = time.perf_counter_ns() + 2_000_000  # first step 2 ms from now

    def wait(self, k: int) -> None:
        """Wait until the deadline of step k: sleep, then spin over the last 0.1 ms."""
        target = self._t0 + int(round(k * self.dt * 1e9))
        while True:
            now = time.perf_counter_ns()
            left = (target - now) / 1e9
            if left <= 0:
                break
            if left > SPIN_S:
                time.sleep(left - SPIN_S)
        self.lateness_ns[k] = now - target
        self._started = now

    def done(self, k: int) -> None:
        """Step k is over: a deadline miss if it ended after its slot."""
        now = time.perf_counter_ns()
        self.duration_ns[k] = now - self._started
        if now > self._t0 + int(round((k + 1) * self.dt * 1e9)):
            self.misses += 1
        self.steps = k + 1

    def stop(self) -> None:
        """Turn the garbage collector back on if it was on."""
        if self._gc_was_enabled:
            gc.enable()

    def summary(self) -> dict:
        """Steps, deadline misses and lateness percentiles (p50, p99, max) [us] for summary.json."""
        late = self.lateness_ns[: self.steps] / 1000.0
        pct = (lambda q: float(np.percentile(late, q))) if self.steps else (lambda q: 0.0)
        return {"steps": self.steps, "dt_s": self.dt, "deadline_misses": self.misses,
                "deadline_miss_pct": 100.0 * self.misses / max(self.steps, 1),
                "lateness_us": {"p50": pct(50), "p99": pct(99), "max": float(late.max()) if self.steps else 0.0}}
