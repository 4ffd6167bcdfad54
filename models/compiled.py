"""Compiled kernels: functions written once in the plain arithmetic of numba's nopython mode and compiled by
numba where it is installed, with numba's compile cache in pantohil's cache (`$PANTOHIL_CACHE/numba`).

Where numba is missing, or `PANTOHIL_JIT=0`, `compiled(fn)` gives None and the caller runs its numpy path,
which does the same operations in the same order (the kernels and their numpy paths are equal to the bit;
tests/unit/test_compiled_kernels.py)."""
from __future__ import annotations

import os
from collections.abc import Callable

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

        os.environ["NUMBA_CACHE_DIR"] = str(cache_folder(cache_root() / "numba"))
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


def compiled(fn: Callable) -> Callable | None:
    """`fn` compiled in nopython mode (cached on disk; compiled on its first call), or None where kernels are
    not compiled (numba missing, PANTOHIL_JIT=0)."""
    if not jit_wanted():
        return None
    if fn not in _compiled:
        numba = _numba()
        if numba is not None:
            for helper in _helpers:
                if helper not in _registered:
                    numba.extending.register_jitable(helper)
                    _registered.add(helper)
        _compiled[fn] = None if numba is None else numba.njit(cache=True, nogil=True)(fn)
    return _compiled[fn]
