"""Where pantohil keeps its caches, and its one way of writing a file: atomically, so that a file under
its final name is always complete (an interrupted write leaves at most a hidden `.part` file)."""
from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path


def cache_root() -> Path:
    """The cache of built FMUs, PFEM operators and catenary analyses: $PANTOHIL_CACHE or ~/.cache/pantohil."""
    return Path(os.environ.get("PANTOHIL_CACHE", Path.home() / ".cache" / "pantohil"))


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
