"""One signal and exit-code path for every command. SIGINT, SIGTERM and SIGHUP (a closed terminal) stop a
command; it exits with 128 + the signal: 130, 143, 129.

For `run`, stopping is a state, not an exception: the signal sets a request that the master checks
between steps, so no KeyboardInterrupt is ever raised inside an FMU's code. Every other command is
interrupted at once (`Interrupted`, a KeyboardInterrupt), except inside a `shielded()` block (a message
half-sent to a writer process, a folder being renamed into place), where the signal waits for the block's
end. Only the first signal interrupts: a second one cannot break the clean-up of the first."""
from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def exit_code(signum: int | None) -> int:
    """The exit code of a command stopped by `signum`: 128 + the signal (SIGINT 130, SIGTERM 143, SIGHUP 129)."""
    return 128 + int(signum if signum is not None else signal.SIGINT)


class Interrupted(KeyboardInterrupt):
    """A stop signal that ended a command; `signum` is the signal."""

    def __init__(self, signum: int = signal.SIGINT) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)


def signal_of(exc: BaseException) -> int:
    """The signal of an interrupt (a plain KeyboardInterrupt is a Ctrl-C: SIGINT)."""
    return getattr(exc, "signum", int(signal.SIGINT))


class StopRequest:
    """Set by the first stop signal; `count` counts every signal that arrived. `raising`: a signal also
    raises Interrupted at once (outside shielded blocks), once."""

    def __init__(self, raising: bool = False) -> None:
        self.signum: int | None = None
        self.count = 0
        self._interruptible = raising
        self._shield = 0
        self._raised = False

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
        self._raise_if_due()

    def _raise_if_due(self) -> None:
        if self.requested and self._interruptible and not self._shield and not self._raised:
            self._raised = True
            raise Interrupted(self.signum)

    def defer(self) -> None:
        """From now on a signal only sets the request (a run checks it between steps)."""
        self._interruptible = False

    @contextmanager
    def interruptible(self) -> Iterator[None]:
        """Inside, a stop signal also raises Interrupted at once: for long pure-Python/numpy work
        (an operator build) that no FMU is part of and that leaves nothing half-written."""
        if self.requested:
            raise Interrupted(self.signum)
        before, self._interruptible = self._interruptible, True
        try:
            yield
        finally:
            self._interruptible = before

    @contextmanager
    def shielded(self) -> Iterator[None]:
        """Inside, a stop signal is only noted; it interrupts when the outermost shielded block ends."""
        self._shield += 1
        try:
            yield
        finally:
            self._shield -= 1
        self._raise_if_due()


_active: list[StopRequest] = []  # the request of the signal handlers in place (main thread)


@contextmanager
def shielded() -> Iterator[None]:
    """A block that a stop signal does not cut in two (a message on a pipe, a rename): the signal takes
    effect at its end. Without handlers in place (a worker thread, a library caller) it does nothing."""
    if not _active:
        yield
        return
    with _active[-1].shielded():
        yield


@contextmanager
def stop_on_signals(stop: StopRequest | None = None, raising: bool = False) -> Iterator[StopRequest]:
    """While inside, SIGINT, SIGTERM and SIGHUP set `stop` (and raise Interrupted if `raising`) in place of
    their default actions; the previous handlers come back afterwards. Outside the main thread signals
    cannot be caught: the request is only returned."""
    stop = stop if stop is not None else StopRequest(raising)
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    previous = {s: signal.signal(s, stop.on_signal) for s in STOP_SIGNALS}
    _active.append(stop)
    try:
        yield stop
    finally:
        _active.remove(stop)
        for s, handler in previous.items():
            signal.signal(s, handler)
