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
    """`fn` callable from compiled kernels (numba's register_jitable) and still a plain function."""
    numba = _numba() if jit_wanted() else None
    return fn if numba is None else numba.extending.register_jitable(fn)


def compiled(fn: Callable) -> Callable | None:
    """`fn` compiled in nopython mode (cached on disk; compiled on its first call), or None where kernels are
    not compiled (numba missing, PANTOHIL_JIT=0)."""
    if not jit_wanted():
        return None
    if fn not in _compiled:
        numba = _numba()
        _compiled[fn] = None if numba is None else numba.njit(cache=True, nogil=True)(fn)
    return _compiled[fn]
