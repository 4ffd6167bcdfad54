"""The cache of built FMUs: an entry's key hashes everything the FMU depends on (its script, the model
sources, the case parameters and data files, the pythonfmu version, the Python runtime), and an entry is
used only when its bytes hash to the digest stored beside it."""
from __future__ import annotations

import hashlib
import shutil
import sys
from pathlib import Path

import pythonfmu

from pantohil.models.input_files import InputFileError, read_input_bytes
from pantohil.models.storage import atomic_path, cache_folder, cache_root, write_text_atomic

from . import loader

BUILDER_VERSION = "16"
MAX_FMU_BYTES = 256 * 1024 * 1024  # a cache entry read to check its digest (a built FMU is about 4 MB)


def cache_key(name: str, script: Path, files: list[Path], experiment: tuple[float, float],
              runtime: loader.PythonRuntime) -> str:
    """The entry's key: a hash of the FMU's script, the loader's source and every staged file, with the versions."""
    h = hashlib.sha256()
    h.update(f"{BUILDER_VERSION} {pythonfmu.__version__} {name} {experiment!r} {runtime.key()}".encode())
    h.update(script.read_bytes())
    h.update(loader.SOURCE.read_bytes())
    for root in files:
        paths = sorted(p for p in ([root] if root.is_file() else root.rglob("*")) if p.is_file())
        for p in paths:
            h.update(p.name.encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:20]


def cache_entry(key: str, class_name: str) -> Path:
    """Where the FMU of a key is kept."""
    return cache_root() / "fmus" / key / f"{class_name}.fmu"


def _digest_path(cached: Path) -> Path:
    return cached.with_name(cached.name + ".sha256")


def _sha256(path: Path) -> str:
    return hashlib.sha256(read_input_bytes(path, "FMU cache entry", MAX_FMU_BYTES)).hexdigest()


def entry_is_whole(cached: Path) -> bool:
    """Whether an FMU cache entry is there and whole: its bytes hash to the digest stored beside it when it was
    made. A damaged entry (truncated, a bit flipped, no digest) is reported in one line and rebuilt."""
    if not cached.exists() and not cached.is_symlink():
        return False
    try:
        whole = _digest_path(cached).read_text().strip() == _sha256(cached)
    except (OSError, UnicodeDecodeError, InputFileError):
        whole = False
    if not whole:
        print(f"pantohil: the FMU cache entry {cached} does not match its digest (damaged or incomplete): "
              "rebuilding it", file=sys.stderr, flush=True)
    return whole


def store(fmu: Path, cached: Path) -> None:
    """Put a built FMU into the cache: written whole or not at all, its digest written after it."""
    cache_folder(cached.parent)
    with atomic_path(cached) as part:
        shutil.copy2(fmu, part)
    write_text_atomic(_digest_path(cached), _sha256(cached) + "\n")
