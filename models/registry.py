"""One registry per kind of model: the built-in implementations and those other packages declare under
an entry-point group (`pantohil.pantographs`, ...), by name.

The names are known without importing anything (the entry points' names), so the case schema's choices
and the FMUs' integer codes can come from a registry at import time; an implementation is loaded on
first use. A model's integer code (its FMU parameter) is its index in `names()`: the built-ins in their
order, then the other packages' names sorted, the same in every process of one environment.
"""
from __future__ import annotations

import functools
import importlib.metadata
import sys
from collections.abc import Callable
from typing import Generic, TypeVar

from pantohil.models.errors import InputError

T = TypeVar("T")


@functools.lru_cache(maxsize=64)
def _group_entry_points(group: str, path: tuple[str, ...]) -> dict[str, importlib.metadata.EntryPoint]:
    """The entry points of `group` in the distributions on `path` (sys.path): scanning them takes about 10 ms,
    and a run asks a few dozen times; a package installed later is found by a new process, or a new path."""
    return {ep.name: ep for ep in importlib.metadata.entry_points(group=group)}


class Registry(Generic[T]):
    """The implementations of one kind, by name: `builtins` (name -> factory) and the entry points of
    `group` (name -> "module:attribute", an instance or a class called with no arguments)."""

    def __init__(self, kind: str, group: str, builtins: dict[str, Callable[[], T]]):
        self.kind, self.group = kind, group
        self._builtins = dict(builtins)
        self._loaded: dict[str, T] = {}

    def _entry_points(self) -> dict[str, importlib.metadata.EntryPoint]:
        found = _group_entry_points(self.group, tuple(sys.path))
        return {name: found[name] for name in sorted(found) if name not in self._builtins}

    def builtin_names(self) -> tuple[str, ...]:
        """The names pantohil itself provides, in their fixed order."""
        return tuple(self._builtins)

    def names(self) -> tuple[str, ...]:
        """Every registered name: the built-ins, then the other packages' sorted (their codes follow)."""
        return (*self._builtins, *self._entry_points())

    def get(self, name: str, key: str = "") -> T:
        """The implementation registered as `name`; InputError naming `key` for an unknown name."""
        if name not in self._loaded:
            if name in self._builtins:
                self._loaded[name] = self._builtins[name]()
            else:
                eps = self._entry_points()
                if name not in eps:
                    raise InputError(f"{key or self.kind}: {name!r} is not a {self.kind} (registered: "
                                     f"{', '.join(self.names())})", key=key or None)
                obj = eps[name].load()
                self._loaded[name] = obj() if isinstance(obj, type) else obj
        return self._loaded[name]

    def code(self, name: str) -> int:
        """The model's integer code (its FMU parameter value): its index in `names()`."""
        return self.names().index(name)

    def name_of(self, code: int, key: str = "") -> str:
        """The name of a code; InputError for a code no model has."""
        names = self.names()
        if not 0 <= int(code) < len(names):
            raise InputError(f"{key or self.kind}: code {code} names no {self.kind} (0 .. {len(names) - 1})",
                             key=key or None)
        return names[int(code)]
