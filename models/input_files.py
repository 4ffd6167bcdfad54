"""The one reader of input files (case, catenary, sweep and rig TOML files, profile CSVs, the JSON files
of a run folder).

Only regular files are read (not a directory, a device such as /dev/zero, or a FIFO), at most
`MAX_INPUT_BYTES`, as UTF-8. A TOML or JSON document is refused if it nests deeper than `MAX_NESTING`
tables or lists, holds a number that is not finite (`nan`, `inf`, also inside lists and tables), an
integer outside TOML's 64-bit range, or a NUL character in a string or a key (a file name must not
carry one). Every refusal is an `InputFileError` of one line naming the file, the key and what is wrong.
"""
from __future__ import annotations

import json
import math
import os
import re
import stat
import tomllib
from pathlib import Path

from pantohil.models.errors import InputError

MAX_INPUT_BYTES = 4 * 1024 * 1024
MAX_NESTING = 32  # tables and lists inside each other; the shipped files nest at most 4 deep
INT_MIN, INT_MAX = -(2**63), 2**63 - 1  # TOML's integers are 64-bit signed (the spec: refuse beyond)
# what opens or closes a level of nesting in TOML text, strings and comments skipped whole
_TOML_TOKEN = re.compile(r'"""(?:[^\\]|\\.)*?"""|\'\'\'.*?\'\'\'|"(?:[^"\\\n]|\\.)*"|\'[^\'\n]*\'|#[^\n]*|[\[\]{}]',
                         re.S)


class InputFileError(InputError):
    """An input file that cannot be read; one line naming the file."""


class TomlSyntaxError(InputFileError):
    """Text that is not TOML at all (as opposed to TOML holding a value pantohil refuses)."""


def open_regular(path: Path, what: str) -> int:
    """A descriptor of a regular file, opened without waiting (a FIFO, a device or a directory is refused)."""
    path = Path(path)
    if "\0" in str(path):
        raise InputFileError(f"{what} {str(path)!r}: a file name cannot hold a NUL character")
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # O_NONBLOCK: opening a FIFO must not hang
    except FileNotFoundError:
        raise InputFileError(f"{what} {path} does not exist") from None
    except OSError as exc:
        raise InputFileError(f"{what} {path}: {exc.strerror}") from None
    try:
        mode = os.fstat(fd).st_mode
    except OSError as exc:
        os.close(fd)
        raise InputFileError(f"{what} {path}: {exc.strerror}") from None
    if not stat.S_ISREG(mode):
        os.close(fd)
        kind = "is a directory, not a file" if stat.S_ISDIR(mode) else "is not a regular file"
        raise InputFileError(f"{what} {path} {kind}")
    return fd


def read_input_chunk(path: Path, what: str, offset: int, max_bytes: int) -> bytes:
    """At most max_bytes of a regular file from offset (a file that grows while it is read, such as a log)."""
    fd = open_regular(path, what)
    try:
        return os.pread(fd, max_bytes, offset)
    except OSError as exc:
        raise InputFileError(f"{what} {path}: {exc.strerror}") from None
    finally:
        os.close(fd)


def read_input_bytes(path: Path, what: str, max_bytes: int = MAX_INPUT_BYTES) -> bytes:
    """The bytes of a regular file of at most max_bytes bytes (not a directory, a device or a FIFO)."""
    fd = open_regular(path, what)
    try:
        size = os.fstat(fd).st_size
        if size > max_bytes:
            raise InputFileError(f"{what} {path} is {size} bytes, above the limit of {max_bytes} bytes")
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


def _value_problem(value) -> str | None:
    """What is wrong with one scalar of a parsed document, or None."""
    if isinstance(value, float) and not math.isfinite(value):
        return "must be a finite number"
    if isinstance(value, int) and not isinstance(value, bool) and not INT_MIN <= value <= INT_MAX:
        return f"is an integer beyond the 64-bit range [{INT_MIN}, {INT_MAX}]"
    if isinstance(value, str) and "\0" in value:
        return "holds a NUL character"
    return None


def _children(value, where: str):
    """The (dotted key, value) items inside a table or a list; a key with NUL is reported as a value."""
    if isinstance(value, dict):
        return [(f"{where}.{k}" if where else str(k), k if "\0" in str(k) else v) for k, v in value.items()]
    if isinstance(value, list):
        return [(f"{where}[{i}]", v) for i, v in enumerate(value)]
    return []


def first_problem(document) -> tuple[str, str] | None:
    """(dotted key, what is wrong) of the first bad value of a parsed document, or None: nested deeper than
    MAX_NESTING, a number that is not finite, an integer beyond 64 bits, a NUL in a string or a key.
    Iterative: a deep document cannot exhaust the stack."""
    stack = [("", document, 0)]
    while stack:
        where, value, depth = stack.pop()
        if depth > MAX_NESTING:
            return where, f"nests deeper than {MAX_NESTING} tables or lists"
        problem = _value_problem(value)
        if problem is not None:
            return where.replace("\0", "\\0"), problem
        stack.extend((w, v, depth + 1) for w, v in reversed(_children(value, where)))
    return None


def _first_line(exc: Exception) -> str:
    return str(exc).split(";")[0].splitlines()[0] if str(exc) else type(exc).__name__


def toml_nesting(text: str, limit: int = MAX_NESTING) -> tuple[int, int]:
    """The deepest nesting of lists and inline tables in TOML text (strings and comments skipped), counted up
    to the first level above limit, and the line (from 1) where it is reached."""
    depth = deepest = 0
    where = 0
    for token in _TOML_TOKEN.finditer(text):
        t = token.group()
        if t in "[{":
            depth += 1
            if depth > deepest:
                deepest, where = depth, token.start()
            if deepest > limit:
                break
        elif t in "]}":
            depth = max(0, depth - 1)
    return deepest, text.count("\n", 0, where) + 1


def loads_toml(text: str, what: str) -> dict:
    """TOML text as a dict, checked as `first_problem` says; InputFileError names `what` and the key."""
    depth, line = toml_nesting(text)
    if depth > MAX_NESTING:
        raise InputFileError(f"{what}: line {line} nests deeper than {MAX_NESTING} lists or tables")
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise TomlSyntaxError(f"{what} is not valid TOML: {exc}") from None
    except RecursionError:  # a bound the nesting scan missed: still one line
        raise InputFileError(f"{what}: nests too deeply") from None
    except ValueError as exc:  # an integer of more digits than Python converts (4300)
        raise InputFileError(f"{what}: holds an integer too long to read ({_first_line(exc)})") from None
    bad = first_problem(raw)
    if bad is not None:
        raise InputFileError(f"{what}: {bad[0]} {bad[1]}")
    return raw


def load_toml(path: Path, what: str, max_bytes: int = MAX_INPUT_BYTES) -> dict:
    """A TOML file as a dict, checked as `loads_toml` says."""
    return loads_toml(read_input_text(path, what, max_bytes), f"{what} {path}")


def load_json(path: Path, what: str, max_bytes: int = MAX_INPUT_BYTES, kind: type = dict):
    """A JSON file (of a run folder) as `kind` (a dict unless asked), checked as `first_problem` says."""
    text = read_input_text(path, what, max_bytes)
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputFileError(f"{what} {path} is not valid JSON: {exc.msg} (line {exc.lineno})") from None
    except RecursionError:
        raise InputFileError(f"{what} {path}: nests too deeply") from None
    except ValueError as exc:  # an integer of more digits than Python converts (4300)
        raise InputFileError(f"{what} {path}: holds an integer too long to read ({_first_line(exc)})") from None
    if not isinstance(value, kind):
        raise InputFileError(f"{what} {path}: expected a JSON {'object' if kind is dict else kind.__name__}, "
                             f"got {type(value).__name__}")
    bad = first_problem(value)
    if bad is not None:
        raise InputFileError(f"{what} {path}: {bad[0] or 'the document'} {bad[1]}")
    return value
