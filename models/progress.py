"""Progress of long work: a bar (tqdm) in a terminal, and where stderr is a log (a file, a pipe) one line
every LOG_INTERVAL_S seconds and one at the end, never a carriage return."""
from __future__ import annotations

import sys
import time

from tqdm import tqdm

LOG_INTERVAL_S = 10.0


def progress(total: float, desc: str, unit: str, enabled: bool = True, initial: int = 0, leave: bool = False,
             interval_s: float = LOG_INTERVAL_S, stream=None):
    """A progress indicator with tqdm's interface (update, set_postfix, n, total, refresh, close, `with`):
    a bar on a terminal, lines in a log, nothing if not `enabled`."""
    stream = stream if stream is not None else sys.stderr
    if not enabled:
        return tqdm(total=total, disable=True)
    if getattr(stream, "isatty", lambda: False)():
        return tqdm(total=total, desc=desc, unit=unit, initial=initial, leave=leave, file=stream)
    return LineProgress(total, desc, unit, initial, interval_s, stream)


class LineProgress:
    """tqdm's interface, written as whole lines: `desc: n/total unit (p %), t s[, postfix]`, at most every
    `interval_s` seconds and once at the end."""

    def __init__(self, total: float, desc: str, unit: str, initial: int, interval_s: float, stream):
        self.total, self.desc, self.unit, self.n = total, desc, unit, initial
        self.interval_s, self.stream = interval_s, stream
        self.start = self._last = time.monotonic()
        self.postfix = ""
        self._closed = False

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:  # the error says what happened; no last line of progress before it
            self._closed = True

    def update(self, count: float = 1) -> None:
        """Count `count` more units done; a line if the interval has passed."""
        self.n += count
        self.refresh(due_only=True)

    def set_postfix(self, **values) -> None:
        """Values shown after the count (as tqdm's postfix)."""
        self.postfix = ", ".join(f"{k}={v}" for k, v in values.items())

    def refresh(self, due_only: bool = True) -> None:
        """Write the line now if the interval has passed (or always, with due_only False)."""
        now = time.monotonic()
        if due_only and now - self._last < self.interval_s:
            return
        self._last = now
        share = f" ({100 * self.n / self.total:.0f} %)" if self.total else ""
        tail = f", {self.postfix}" if self.postfix else ""
        print(f"{self.desc}: {self.n:g}/{self.total:g} {self.unit}{share}, {now - self.start:.0f} s{tail}",
              file=self.stream, flush=True)

    def close(self) -> None:
        """The last line (once)."""
        if not self._closed:
            self._closed = True
            self.refresh(due_only=False)
