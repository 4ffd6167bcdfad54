"""The one reader of input files (case, catenary, sweep and rig TOML files, profile CSVs).

Only regular files are read (not a directory, a device such as /dev/zero, or a FIFO), at most
`MAX_INPUT_BYTES`, as UTF-8; a TOML file whose numbers are not all finite (`nan`, `inf`, also inside
lists and tables) is refused. Every refusal is an `InputFileError` of one line naming the file and
what is wrong.
"""
from __future__ import annotations

import math
import os
import stat
import tomllib
from pathlib import Path

MAX_INPUT_BYTES = 4 * 1024 * 1024


class InputFileError(ValueError):
    """An input file that cannot be read; one line naming the file."""


def read_input_bytes(path: Path, what: str, max_bytes: int = MAX_INPUT_BYTES) -> bytes:
    """The bytes of a regular file of at most max_bytes bytes (a FIFO or a device is refused, never
    waited on)."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # O_NONBLOCK: opening a FIFO must not hang
    except FileNotFoundError:
        raise InputFileError(f"{what} {path} does not exist") from None
    except (OSError, ValueError) as exc:  # ValueError: a NUL in the path
        raise InputFileError(f"{what} {path}: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise InputFileError(f"{what} {path} is a directory, not a file")
        if not stat.S_ISREG(info.st_mode):
            raise InputFileError(f"{what} {path} is not a regular file")
        if info.st_size > max_bytes:
            raise InputFileError(f"{what} {path} is {info.st_size} bytes, above the limit of {max_bytes} bytes")
        with os.fdopen(fd, "rb", closefd=False) as fh:
            data = fh.read(max_bytes + 1)
    except OSError as exc:
        raise InputFileError(f"{what} {path}: {exc.strerror}") from None
    finally:
        os.close(fd)
    if len(data) > max_bytes:
        raise InputFileError(f"{what} {path} is larger than the limit of {max_bytes} bytes")
    return data


def read_input_text(path: Path, what: str, max_bytes: int = MAX_INPUT_BYTES) -> str:
    """The text of a regular UTF-8 file of at most max_bytes bytes."""
    data = read_input_bytes(path, what, max_bytes)
    if b"\0" in data:
        raise InputFileError(f"{what} {path} is binary (it holds NUL bytes), not text")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputFileError(f"{what} {path} is not UTF-8 text (byte {exc.start})") from None


def first_non_finite(value, where: str = "") -> str | None:
    """The dotted key (with [i] for list items) of the first NaN or infinite number, or None."""
    if isinstance(value, float):
        return None if math.isfinite(value) else where
    if isinstance(value, dict):
        for k, v in value.items():
            found = first_non_finite(v, f"{where}.{k}" if where else str(k))
            if found is not None:
                return found
    elif isinstance(value, list):
        for i, v in enumerate(value):
            found = first_non_finite(v, f"{where}[{i}]")
            if found is not None:
                return found
    return None


def load_toml(path: Path, what: str, max_bytes: int = MAX_INPUT_BYTES) -> dict:
    """A TOML file as a dict, every number in it finite."""
    text = read_input_text(path, what, max_bytes)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputFileError(f"{what} {path} is not valid TOML: {exc}") from None
    bad = first_non_finite(raw)
    if bad is not None:
        raise InputFileError(f"{what} {path}: {bad} must be a finite number")
    return raw
