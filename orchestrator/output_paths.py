"""Every command's output, checked before any work and never left half-written.

A file or folder named on the command line (`--out`, `--stats`, `--ssp`) is checked first: a folder
where a file is asked for, a file where a folder is asked for, a file on the way to it, a file whose
folder does not exist, a folder that is not empty (a finished run in it above all): one line naming it,
exit 2, nothing done. A command's output folder is written as a hidden sibling (`.NAME.part-PID`) and
renamed into place when complete; an interrupted or failed command removes its part folder, and a part
folder left by a killed process is removed by the next command writing beside it. Writes that fail for
lack of room (a full disk, a file size limit) end a command with one line (`write_failure`).
"""
from __future__ import annotations

import errno
import os
import re
import shutil
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from pantohil.models.scratch import pid_alive

from .run_folder import SUMMARY, RunFolderError, run_is_alive
from .stopping import shielded

PART_PATTERN = re.compile(r"^\.(?P<name>.+)\.(?:part|old)-(?P<pid>\d+)$")
NO_ROOM = {errno.ENOSPC: "the disk is full", errno.EFBIG: "a file size limit was reached",
           errno.EDQUOT: "the disk quota is used up", errno.EIO: "the disk failed"}


def write_failure(exc: BaseException) -> str | None:
    """One line for a write that failed for lack of room or a failing disk (ENOSPC, EFBIG, EDQUOT, EIO,
    anywhere in the chain of causes); None for any other error."""
    seen = exc
    while seen is not None:
        if isinstance(seen, OSError) and seen.errno in NO_ROOM:
            return f"{NO_ROOM[seen.errno]} ({seen.strerror}); stopped, and the files already written stay readable"
        seen = seen.__cause__ or seen.__context__
    return None


def _first_existing(path: Path) -> Path:
    """`path` or its nearest ancestor that exists (a file on the way is returned as it is)."""
    probe = path
    while not os.path.lexists(probe) and probe != probe.parent:
        probe = probe.parent
    return probe


def check_output_file(path: Path, option: str) -> Path:
    """A file a command will write (and replace if it exists): its folder exists, it is not a folder."""
    path = Path(path)
    if path.is_dir():
        raise RunFolderError(f"{option} {path}: is a folder; give a file name")
    if os.path.lexists(path) and not path.is_file():
        raise RunFolderError(f"{option} {path}: exists and is not a regular file")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        what = "is not a folder" if os.path.lexists(parent) else "does not exist"
        raise RunFolderError(f"{option} {path}: its folder {parent} {what}")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise RunFolderError(f"{option} {path}: cannot write into {parent} (permission denied)")
    return path


def check_output_folder(path: Path, option: str, overwrite: bool = False, keep_if: str | None = None) -> Path:
    """A folder a command will fill: new, or empty, or (with `overwrite`) replaced whole; `keep_if` names a
    file whose presence makes a used folder acceptable (a sweep's sweep.json: the same sweep continues)."""
    path = Path(path)
    if os.path.lexists(path) and not path.is_dir():
        raise RunFolderError(f"{option} {path}: exists and is not a folder")
    base = _first_existing(path)
    if not base.is_dir():
        raise RunFolderError(f"{option} {path}: {base} is a file, not a folder")
    if not os.access(base, os.W_OK | os.X_OK):
        raise RunFolderError(f"{option} {path}: cannot write into {base} (permission denied)")
    if path.is_dir() and any(path.iterdir()):
        if run_is_alive(path):
            raise RunFolderError(f"{option} {path}: a run is writing into it")
        if keep_if is not None and (path / keep_if).exists():
            return path
        if not overwrite:
            what = "holds a finished run" if (path / SUMMARY).exists() else "exists and is not empty"
            remedy = "--overwrite replaces it whole" if keep_if is None else f"it holds no {keep_if}: use a new folder"
            raise RunFolderError(f"{option} {path}: {what} ({remedy})")
    return path


def sweep_dead_parts(folder: Path) -> None:
    """Remove the part folders (`.NAME.part-PID`, `.NAME.old-PID`) that killed processes left in `folder`."""
    with suppress(OSError):
        for entry in folder.iterdir():
            match = PART_PATTERN.match(entry.name)
            if match and int(match["pid"]) != os.getpid() and not pid_alive(int(match["pid"])):
                shutil.rmtree(entry, ignore_errors=True)


@contextmanager
def atomic_output_folder(path: Path, option: str = "--out", overwrite: bool = False) -> Iterator[Path]:
    """The checked output folder `path`, to be written as a hidden part folder beside it (yielded) and
    renamed into place when the block ends normally; removed if the block raises or is interrupted."""
    path = check_output_folder(path, option, overwrite)
    path.parent.mkdir(parents=True, exist_ok=True)
    sweep_dead_parts(path.parent)
    part = path.parent / f".{path.name}.part-{os.getpid()}"
    shutil.rmtree(part, ignore_errors=True)
    try:  # mkdir inside: a signal handled on its way back from mkdir still removes the folder
        part.mkdir()
        yield part
        with shielded():
            _move_into_place(part, path, option, overwrite)
    finally:
        shutil.rmtree(part, ignore_errors=True)


def _move_into_place(part: Path, path: Path, option: str, overwrite: bool) -> None:
    """Rename the complete part folder to `path` (an empty folder there is replaced; a used one only with
    `overwrite`, moved aside first, then removed)."""
    old = None
    if path.is_dir() and any(path.iterdir()):
        if not overwrite:
            raise RunFolderError(f"{option} {path}: was filled by another process meanwhile; nothing replaced")
        old = path.parent / f".{path.name}.old-{os.getpid()}"
        os.rename(path, old)
    elif path.is_dir():
        os.rmdir(path)
    try:
        os.rename(part, path)
    except OSError as exc:
        if old is not None:
            os.rename(old, path)
        raise RunFolderError(f"{option} {path}: cannot put the output in place ({exc.strerror})") from None
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
