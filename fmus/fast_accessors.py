"""fmi2Get/fmi2Set of a list of variables by attribute name, made once per class and list of references,
and the Python thread state kept for the host's threads: the per-call costs of pythonfmu's own accessors
taken out of every step."""
from __future__ import annotations

import ctypes
import operator
import threading

from pythonfmu import Real

_ACCESSORS: dict = {}  # (class, type, direction, value references) -> reader or writer, shared by the instances


def accessor(slave, kind: type, vrs, write: bool):
    """The function that reads (slave) or writes (slave, values) the variables `vrs` of one type, by their
    attribute names, made once per class and list of references (a master asks for the same lists every
    step). TypeError names a reference of another type, as pythonfmu's own accessors do."""
    key = (type(slave), kind, write, tuple(vrs))
    found = _ACCESSORS.get(key)
    if found is not None:
        return found
    names = []
    for vr in key[3]:
        var = slave.vars[vr]
        if not isinstance(var, kind):
            raise TypeError(f"Variable with valueReference={vr} is not of type {kind.__name__}!")
        names.append(var.local_name)
    if write:
        def found(obj, values):
            for name, value in zip(names, values, strict=True):
                setattr(obj, name, value)
    elif not names:
        def found(obj):
            return []
    else:
        get, convert = operator.attrgetter(*names), float if kind is Real else int
        if len(names) == 1:
            def found(obj):
                return [convert(get(obj))]
        else:
            def found(obj):
                return [convert(v) for v in get(obj)]
    _ACCESSORS[key] = found
    return found


_HELD_THREADS: set[int] = set()


def hold_thread_state() -> None:
    """Keep this thread's Python thread state for the life of the thread.

    pythonfmu enters Python from the host's thread with PyGILState_Ensure and leaves with PyGILState_Release.
    In a thread Python did not start (the worker threads of libcosim or of a C host) the release destroys
    the thread state it made, so every call made a new one: a new frame stack (mmap, page faults, munmap),
    a large part of a step's cost. One Ensure never released keeps the state: the next calls reuse it."""
    ident = threading.get_ident()
    if ident not in _HELD_THREADS:
        _HELD_THREADS.add(ident)
        ctypes.pythonapi.PyGILState_Ensure()
