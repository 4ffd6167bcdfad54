"""Ctrl-C (SIGINT) and SIGTERM while a master steps: the handler only notes the signal, and the stepping
loop stops between two steps. Raised where it arrives, the interrupt would land inside an FMU's embedded
Python most of the time (the FMUs run in the master's interpreter) and come back as an FMU error, with
no summary written."""
from __future__ import annotations

import signal
import threading


class StopRequests:
    """Context manager: while active, `requested` is the number of the first stop signal received."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.requested: int | None = None
        self._previous: dict = {}

    def _note(self, signum, frame) -> None:
        if self.requested is None:
            self.requested = signum

    def __enter__(self) -> StopRequests:
        if threading.current_thread() is threading.main_thread():  # signals reach the main thread only
            for s in self.SIGNALS:
                self._previous[s] = signal.signal(s, self._note)
        return self

    def __exit__(self, *exc) -> None:
        for s, handler in self._previous.items():
            signal.signal(s, handler)
        self._previous.clear()
