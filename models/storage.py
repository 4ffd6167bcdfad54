"""Where pantohil keeps its caches, and its one way of writing a file: atomically, so that a file under
its final name is always complete (an interrupted write leaves at most a hidden `.part` file)."""
from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

from pantohil.models.input_files import InputFileError


class CacheError(InputFileError):
    """A cache folder that cannot be used (a file, under a file, not writable); one line naming it."""


def cache_root() -> Path:
    """The cache of built FMUs, PFEM operators and catenary analyses: $PANTOHIL_CACHE or ~/.cache/pantohil.
    CacheError if it, or the nearest of its folders that exists, is not a folder."""
    root = Path(os.environ.get("PANTOHIL_CACHE", Path.home() / ".cache" / "pantohil"))
    if "\0" in str(root):
        raise CacheError(f"cache {str(root)!r} (PANTOHIL_CACHE): a path cannot hold a NUL character")
    existing = next((p for p in (root, *root.parents) if p.exists()), None)
    if existing is not None and not existing.is_dir():
        where = "is a file" if existing == root else f"lies under {existing}, which is a file"
        raise CacheError(f"cache {root} (PANTOHIL_CACHE) {where}, not a folder")
    return root


def cache_folder(path: Path) -> Path:
    """A folder of the cache, created if needed; CacheError (one line) if it cannot be."""
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CacheError(f"cache folder {path}: cannot create it ({exc.strerror})") from None
    return Path(path)


@contextlib.contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """A temporary sibling of `path` to write to (same suffix, so writers that go by it still work); it
    replaces `path` when the block ends normally and is removed when it raises."""
    path = Path(path)
    part = path.with_name(f".{path.stem}.{os.getpid()}.part{path.suffix}")
    try:
        yield part
        os.replace(part, path)
    finally:
        part.unlink(missing_ok=True)


def write_text_atomic(path: Path, text: str) -> None:
    """Write `text` to `path` atomically."""
    with atomic_path(path) as part:
        part.write_text(text)
