"""Compiled kernels: functions written once in the plain arithmetic of numba's nopython mode and compiled by
numba where it is installed, with numba's compile cache in pantohil's cache (`$PANTOHIL_CACHE/numba`).

Where numba is missing, or `PANTOHIL_JIT=0`, `compiled(fn)` gives None and the caller runs its numpy path,
which does the same operations in the same order (the kernels and their numpy paths are equal to the bit;
tests/unit/test_compiled_kernels.py)."""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import sys
from collections.abc import Callable
from pathlib import Path

JIT_ENV = "PANTOHIL_JIT"  # "0": never compile (the numpy paths), whatever is installed

_compiled: dict[Callable, Callable | None] = {}
_helpers: list[Callable] = []  # `inlined` functions, registered with numba when a kernel is first compiled
_registered: set[Callable] = set()


def jit_wanted() -> bool:
    """Whether kernels may be compiled: not when PANTOHIL_JIT is "0"."""
    return os.environ.get(JIT_ENV, "1").strip() != "0"


def _numba():
    """numba, imported with its cache under pantohil's cache; None where it is not installed."""
    if "NUMBA_CACHE_DIR" not in os.environ:  # numba reads it when first imported
        from pantohil.models.storage import cache_folder, cache_root

        # numba keys an entry on its function's source file only: a folder per version of this module, whose
        # compile options and helper registration shape every kernel, keeps a change here from loading old code
        version = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:12]
        os.environ["NUMBA_CACHE_DIR"] = str(cache_folder(cache_root() / "numba" / version))
    try:
        import numba
        import numba.extending
    except ImportError:
        return None
    return numba


def inlined(fn: Callable) -> Callable:
    """Mark `fn` as callable from compiled kernels; it stays the plain function (numba is not imported here:
    the Python paths, the FMUs' among them, never load the compiler). `compiled` registers the marked
    functions with numba (register_jitable) before it compiles a kernel."""
    _helpers.append(fn)
    return fn


class _Kernel:
    """A compiled kernel: numba's dispatcher, which loads the kernel from the compile cache (or compiles it) on
    its first call. Before that call the cache's entries of the kernel's module are checked against the digests
    written when they were last loaded (`_CacheDigests`): an entry that does not match, or that numba cannot load,
    is removed and the kernel compiled again. Nothing is stepped before the kernel is loaded, so a retry starts
    clean."""

    def __init__(self, fn: Callable, numba):
        self.fn, self.numba = fn, numba
        self.digests = _CacheDigests(_entry_folder(numba, fn), Path(fn.__code__.co_filename).stem)
        self.dispatcher = None

    def _new(self):
        # error_model "numpy": a division by zero gives inf or nan, as the numpy path's arithmetic does
        return self.numba.njit(cache=True, nogil=True, error_model="numpy")(self.fn)

    def __call__(self, *args):
        if self.dispatcher is not None and self.dispatcher.overloads:
            return self.dispatcher(*args)
        self.digests.check()
        self.dispatcher = self._new()
        try:
            out = self.dispatcher(*args)
        except Exception as exc:  # noqa: BLE001 (any failure to load a cache entry; see below)
            if self.dispatcher.overloads:  # loaded, then failed while running: not the cache's
                raise
            self.digests.discard(f"cannot be loaded ({type(exc).__name__})")
            self.dispatcher = self._new()
            out = self.dispatcher(*args)
        self.digests.record()
        return out


def _entry_folder(numba, fn: Callable) -> Path:
    """The folder of the compile cache where numba keeps the entries of `fn`'s source file (one per installed
    copy of the file)."""
    source = fn.__code__.co_filename
    try:
        from numba.core.caching import _CacheLocator

        return Path(os.environ["NUMBA_CACHE_DIR"]) / _CacheLocator.get_suitable_cache_subpath(source)
    except (ImportError, AttributeError):  # another numba: all the module's entries, wherever they are
        return Path(os.environ["NUMBA_CACHE_DIR"])


class _CacheDigests:
    """SHA-256 digests of the compile cache's entries of one module (numba's `<module>.*.nbi` and `.nbc` files),
    in `<module>.sha256` beside them (the folder of one installed copy of the module), as the FMU cache keeps
    its entries' digests."""

    def __init__(self, folder: Path, stem: str):
        self.folder, self.stem = folder, stem
        self.manifest = folder / f"{stem}.sha256"

    def _entries(self) -> list[Path]:
        return sorted(p for p in self.folder.rglob(f"{self.stem}.*") if p.suffix in (".nbi", ".nbc"))

    def _digests(self) -> dict[str, str]:
        return {str(p.relative_to(self.folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in self._entries()}

    def check(self) -> None:
        """Remove the entries if any does not match its recorded digest (or none is recorded)."""
        if not self._entries():
            return
        try:
            recorded = json.loads(self.manifest.read_text())
        except (OSError, ValueError):
            recorded = None
        if recorded is None:  # written by a process still compiling, or stopped before it recorded them
            self.discard()
        elif recorded != self._digests():
            self.discard("do not match their digests (damaged or incomplete)")

    def discard(self, why: str = "") -> None:
        """Remove the entries and their digests, with one line saying why (if given)."""
        if why:
            print(f"pantohil: the compile cache entries of {self.stem} in {self.folder} {why}: compiling again",
                  file=sys.stderr, flush=True)
        for entry in self._entries():
            entry.unlink(missing_ok=True)
        self.manifest.unlink(missing_ok=True)

    def record(self) -> None:
        """Write the digests of the entries as they are now (atomically)."""
        from pantohil.models.storage import write_text_atomic

        with contextlib.suppress(OSError):  # a read-only cache: checked, and compiled, again next time
            write_text_atomic(self.manifest, json.dumps(self._digests(), sort_keys=True))


def compiled(fn: Callable) -> Callable | None:
    """`fn` compiled in nopython mode (cached on disk; loaded or compiled on its first call), or None where
    kernels are not compiled (numba missing, PANTOHIL_JIT=0)."""
    if not jit_wanted():
        return None
    if fn not in _compiled:
        numba = _numba()
        if numba is not None:
            for helper in _helpers:
                if helper not in _registered:
                    numba.extending.register_jitable(helper)
                    _registered.add(helper)
        _compiled[fn] = None if numba is None else _Kernel(fn, numba)
    return _compiled[fn]
