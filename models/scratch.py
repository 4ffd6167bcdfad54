"""Temporary files of a pantohil process (extracted FMUs, FMU builds) live in one folder of that process,
`$TMPDIR/pantohil-scratch-PID-*`, removed when it exits; a process that was killed cannot remove its own,
so each new one removes the folders of owners that are no longer running."""
from __future__ import annotations

import atexit
import os
import re
import shutil
import tempfile
from pathlib import Path

PREFIX = "pantohil-scratch-"
_OWNER = re.compile(rf"^{PREFIX}(\d+)-")
_mine: dict[int, Path] = {}  # pid -> its folder (a forked child makes its own)


def pid_alive(pid: int) -> bool:
    """Whether a process with this id exists (one of another user counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def sweep_dead(base: Path) -> list[Path]:
    """Remove the scratch folders under `base` whose owner process is gone; the folders removed."""
    removed = []
    try:
        entries = list(Path(base).iterdir())
    except OSError:
        return removed
    for entry in entries:
        match = _OWNER.match(entry.name)
        if match and int(match[1]) != os.getpid() and not pid_alive(int(match[1])):
            shutil.rmtree(entry, ignore_errors=True)
            removed.append(entry)
    return removed


def process_scratch() -> Path:
    """This process's scratch folder, made (and the dead owners' swept) on first use, removed at exit."""
    pid = os.getpid()
    if pid not in _mine:
        base = Path(tempfile.gettempdir())
        sweep_dead(base)
        _mine[pid] = Path(tempfile.mkdtemp(prefix=f"{PREFIX}{pid}-", dir=base))
        atexit.register(_remove, pid)
    return _mine[pid]


def _remove(pid: int) -> None:
    if os.getpid() == pid:
        shutil.rmtree(_mine.pop(pid), ignore_errors=True)


def scratch_dir(prefix: str) -> Path:
    """A new folder in this process's scratch folder."""
    return Path(tempfile.mkdtemp(prefix=prefix, dir=process_scratch()))
