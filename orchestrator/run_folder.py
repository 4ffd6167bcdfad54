"""Run folders: a run writes only into a new or empty folder (or replaces one whole when asked), holds a
lock on it while it runs, and default folder names stay under runs/; reading a finished one's summary
and span files."""
from __future__ import annotations

import fcntl
import io
import os
import re
import shutil
import warnings
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from datetime import datetime
from pathlib import Path

import numpy as np

from pantohil.models.case import CaseError
from pantohil.models.errors import ExitCode, PantohilError
from pantohil.models.input_files import InputFileError, load_json, open_regular, read_input_text

LOCK_NAME = ".pantohil-run.lock"
SUMMARY = "summary.json"
STEADY_SPAN = "steady_span.csv"  # t_s, z0_m, z_m, f_N, x_m of the converged span (HIL runs)
CENTRAL_SPANS = "central_spans.csv"  # span, t_s, f_N, f_lowpass_N of a fem-sim section
RUNS_ROOT = Path("runs")
MAX_SUMMARY_BYTES = 64 * 1024 * 1024  # a summary of 10000 spans is about 2 MB
MAX_TABLE_BYTES = 256 * 1024 * 1024  # about 40 bytes a row: 6 million rows, 60 central spans of 100,000 samples


class RunFolderError(CaseError):
    """A run folder that cannot be used; one line naming it."""


def safe_name(name: str) -> str:
    """A case name as one folder name: no separators, no leading dots, only [A-Za-z0-9._-]."""
    cleaned = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._-")
    return cleaned[:80] or "case"


def default_run_folder(case_name: str, root: Path = RUNS_ROOT, now: datetime | None = None) -> Path:
    """runs/<case>-<date>-<time>, with a counter if that folder is already taken."""
    stem = f"{safe_name(case_name)}-{(now or datetime.now()):%Y%m%d-%H%M%S}"
    folder, n = root / stem, 1
    while folder.exists():
        n += 1
        folder = root / f"{stem}-{n}"
    return folder


def _clear(folder: Path) -> None:
    for entry in folder.iterdir():
        if entry.name == LOCK_NAME:
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry)
        else:
            entry.unlink()


def _lock(folder: Path) -> int:
    """An exclusive lock on the folder: flock on its lock file, held by the file that is under the lock
    name. A holder unlinks the file before it lets go, so a lock taken on a file that is no longer under
    that name (opened just before it was unlinked) is worth nothing: drop it and take the new file."""
    path = folder / LOCK_NAME
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise RunFolderError(f"run folder {folder}: cannot write into it ({exc.strerror})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise RunFolderError(f"run folder {folder}: another run is writing into it") from None
        if _names_the_same_file(fd, path):
            return fd
        os.close(fd)


def _names_the_same_file(fd: int, path: Path) -> bool:
    try:
        return os.path.samestat(os.fstat(fd), os.stat(path))
    except FileNotFoundError:
        return False


@contextmanager
def claimed_run_folder(folder: Path, overwrite: bool = False, resume: bool = False) -> Iterator[Path]:
    """Create or take `folder` for one run, locked until the run is done. A folder with anything in it
    is refused unless `overwrite`, which empties it first, or `resume` (the run continues the one in it).
    A folder created here and refused is removed."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise RunFolderError(f"run folder {folder}: exists and is not a folder")
    created = not folder.exists()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RunFolderError(f"run folder {folder}: cannot create it ({exc.strerror})") from None
    fd = _lock(folder)
    try:
        if not resume and any(e.name != LOCK_NAME for e in folder.iterdir()):
            if not overwrite:
                raise RunFolderError(f"run folder {folder}: exists and is not empty (overwrite replaces it whole)")
            _clear(folder)
        os.write(fd, f"{os.getpid()}\n".encode())
    except BaseException:
        _release(folder, fd)
        if created:
            shutil.rmtree(folder, ignore_errors=True)
        raise
    try:
        yield folder
    except PantohilError as exc:  # bad input or a missing tool found on the way: nothing half-written stays
        if exc.exit_code == ExitCode.BAD_INPUT:
            if created:
                shutil.rmtree(folder, ignore_errors=True)
            elif not resume:
                _clear(folder)
        raise
    finally:
        _release(folder, fd)


def _release(folder: Path, fd: int) -> None:
    """Unlink the lock file while it is still locked, then let go (see _lock)."""
    with suppress(OSError):
        os.unlink(folder / LOCK_NAME)
    os.close(fd)


def read_summary(folder: Path) -> dict:
    """The summary of a run folder (a JSON object in a regular file, bounded); CaseError with one line if it
    has none or it is not one."""
    path = Path(folder) / SUMMARY
    if not path.exists() and not path.is_symlink():
        raise CaseError(f"{folder}: not a run folder (no {SUMMARY})")
    try:
        return load_json(path, "run summary", MAX_SUMMARY_BYTES)
    except InputFileError as exc:
        raise CaseError(str(exc)) from None


def read_table(folder: Path, name: str) -> np.ndarray:
    """A CSV file of a run folder (one header line) as a 2-D array of numbers; CaseError with one line if it
    is not a regular file of at most MAX_TABLE_BYTES holding such a table."""
    path = Path(folder) / name
    try:
        text = read_input_text(path, "run table", MAX_TABLE_BYTES)
    except InputFileError as exc:
        raise CaseError(str(exc)) from None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # an empty table is refused below, without numpy's warning
            table = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, ndmin=2)
    except ValueError as exc:
        reason = str(exc).splitlines()[0] if str(exc) else "unreadable"
        raise CaseError(f"run table {path} is not a table of numbers ({reason})") from None
    if table.size == 0:
        raise CaseError(f"run table {path} has no rows")
    return table


def run_is_alive(folder: Path) -> bool:
    """Whether a process holds the folder's run lock now (a run killed without cleaning up holds none). The
    lock file is opened as a regular file without waiting (a FIFO in its place is no lock)."""
    try:
        fd = open_regular(Path(folder) / LOCK_NAME, "run lock")
    except InputFileError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False
