"""Independent tasks on Dask (`dask.distributed`): a LocalCluster of worker processes by default, or an
existing scheduler, so that a sweep or a stability map written for this machine runs on a cluster."""
from __future__ import annotations

import ctypes
import logging
import os
from contextlib import contextmanager
from collections.abc import Callable, Iterable

from pantohil.models.case import CaseError

CONNECT_TIMEOUT_S = 5


@contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None):
    """A connected Client; `scheduler` is an address such as tcp://127.0.0.1:8786."""
    from distributed import Client, LocalCluster

    if workers is not None and workers < 1:
        raise CaseError(f"workers: must be >= 1 (got {workers})")
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise CaseError(f"Dask scheduler: cannot reach the Dask scheduler at {scheduler} "
                            f"within {CONNECT_TIMEOUT_S} s ({type(exc).__name__})") from None
        try:
            yield client
        finally:
            client.close()
        return
    n = workers or max(1, min(os.cpu_count() or 1, 2))
    # the workers' own loggers at CRITICAL: a task's failure reaches the client as its exception, and what a
    # worker logs as an error is the heartbeat that meets the closing scheduler (with a traceback) at the end
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.CRITICAL)
    client = Client(cluster)
    try:
        yield client
    finally:
        with _quiet_teardown():
            client.close()
            cluster.close()


@contextmanager
def _quiet_teardown():
    """While the client and the cluster close, after every result was taken: the connections that the
    closing workers drop (CommClosedError) are logged by distributed and tornado as errors with a
    traceback, on a run that succeeded. Only CRITICAL passes while closing."""
    loggers = [logging.getLogger(name) for name in ("distributed", "tornado", "asyncio")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)


def tune_worker_allocator() -> None:
    """Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536, which pins glibc's mmap threshold at
    128 KB: every numpy temporary above it is mapped, faulted in and unmapped again, which doubled the time
    of a stability map (half of it in the kernel). Raise both thresholds in this worker (glibc mallopt:
    M_TRIM_THRESHOLD = -1, M_MMAP_THRESHOLD = -3); harmless elsewhere."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 64 << 20)
        libc.mallopt(-1, 256 << 20)
    except (OSError, AttributeError):
        pass


def worker_count(client) -> int:
    """Number of workers the Dask scheduler of `client` has."""
    return len(client.scheduler_info().get("workers", {}))


def _as_completed_interruptible(completed, poll_s: float = 0.2):
    """The futures of a distributed `as_completed` as they finish, waiting in slices of `poll_s`: the kernel
    may hand a Ctrl-C to one of the client's threads, and a main thread blocked without a timeout would
    then never raise it (measured: a sweep whose workers were stopped ignored SIGINT for good)."""
    import threading

    pause = threading.Event()
    while not completed.is_empty():
        batch = completed.next_batch(block=False)
        if not batch:
            pause.wait(poll_s)
        yield from batch


def run_tasks(client, fn: Callable, items: list, keys: Iterable[str], on_result: Callable, progress: bool = True,
              desc: str = "tasks", unit: str = "pt", weight: Callable = lambda item: 1) -> None:
    """Submit fn(item) for every item and call on_result(item, result, error) as each finishes; the progress
    counts `weight(item)` units (points) per item.

    On Ctrl-C the outstanding tasks are cancelled and the interrupt propagates after the results already
    handed over have been kept by the caller."""
    from distributed import as_completed

    from pantohil.models.progress import progress as progress_bar

    futures = client.map(fn, items, key=list(keys), pure=False)
    item_of = {f.key: item for f, item in zip(futures, items, strict=False)}
    try:
        with progress_bar(sum(weight(item) for item in items), desc, unit, progress, leave=True) as bar:
            for fut in _as_completed_interruptible(as_completed(futures)):
                result, error = None, None
                try:
                    result = fut.result()
                except Exception as exc:  # a failed point is recorded, the others go on
                    error = f"{type(exc).__name__}: {exc}"
                on_result(item_of[fut.key], result, error)
                bar.update(weight(item_of[fut.key]))
    finally:
        client.cancel([f for f in futures if not f.done()])
