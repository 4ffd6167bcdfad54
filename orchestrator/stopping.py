"""Stopping a run is a state, not an exception: SIGINT and SIGTERM set a request that the master
checks between steps, so no KeyboardInterrupt is ever raised inside an FMU's code."""
from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequest:
    """Set by the first stop signal; `count` counts every signal that arrived."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self.count = 0
        self._interruptible = False

    @property
    def requested(self) -> bool:
        """Whether a stop was asked for."""
        return self.signum is not None

    @property
    def signal_name(self) -> str | None:
        """Name of the signal that asked for the stop (None if none did)."""
        return signal.Signals(self.signum).name if self.signum is not None else None

    def request(self, signum: int = signal.SIGINT) -> None:
        """Ask for a stop (the first signal is the one reported); counts the requests."""
        if self.signum is None:
            self.signum = int(signum)
        self.count += 1

    def on_signal(self, signum: int, _frame) -> None:
        """Signal handler: ask for a stop, and interrupt at once where that is safe."""
        self.request(signum)
        if self._interruptible:
            raise KeyboardInterrupt

    @contextmanager
    def interruptible(self) -> Iterator[None]:
        """Inside, a stop signal also raises KeyboardInterrupt at once: for long pure-Python/numpy work
        (an operator build) that no FMU is part of and that leaves nothing half-written."""
        if self.requested:
            raise KeyboardInterrupt
        self._interruptible = True
        try:
            yield
        finally:
            self._interruptible = False


@contextmanager
def stop_on_signals(stop: StopRequest | None = None) -> Iterator[StopRequest]:
    """While inside, SIGINT and SIGTERM set `stop` instead of interrupting; the previous handlers come
    back afterwards. Outside the main thread signals cannot be caught: the request is only returned."""
    stop = stop if stop is not None else StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    previous = {s: signal.signal(s, stop.on_signal) for s in STOP_SIGNALS}
    try:
        yield stop
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
