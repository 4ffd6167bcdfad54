"""Declarative FMU variables: one table per FMU gives names, units, descriptions and ranges; the
same table registers the variables with pythonfmu and lets the builder decorate modelDescription.xml.
The variables that carry case keys are derived from the declarations in models/parameters.py
(`case_variables`), named by its naming rule; a table adds only what the FMU itself defines.

Case values reach the FMU through `resources/parameters.json`, read when the slave is created, so the
FMU alone (in any master) reproduces the case; a master may still set parameters before initialising.
"""
from __future__ import annotations

import copy
import ctypes
import json
import math
import operator
import threading
from dataclasses import dataclass
from pathlib import Path

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real, String

from pantohil.fmus import state_codec
from pantohil.models.errors import InputError
from pantohil.models.parameters import AUTO, Key, fmu_keys, fmu_variable_names

PARAMETERS_FILE = "parameters.json"
REQUIREMENTS_FILE = "requirements.txt"  # what `pythonfmu deploy` installs on a host
REQUIREMENTS = ("numpy>=1.26", "scipy>=1.11")

# SI base-unit exponents of every unit used by the FMUs (FMI 2.0 <BaseUnit>).
UNITS = {
    "m": {"m": 1}, "s": {"s": 1}, "kg": {"kg": 1}, "N": {"kg": 1, "m": 1, "s": -2},
    "m/s": {"m": 1, "s": -1}, "Hz": {"s": -1}, "1/s": {"s": -1}, "kg/m": {"kg": 1, "m": -1},
    "N/m": {"kg": 1, "s": -2}, "N/m2": {"kg": 1, "m": -1, "s": -2}, "N.s/m": {"kg": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2}, "1": {},
}
# Display units offered to tools: name -> (factor, of unit); display = factor * value
DISPLAY_UNITS = {"m": ("mm", 1000.0), "m/s": ("km/h", 3.6), "N/m": ("kN/m", 1e-3)}


@dataclass(frozen=True)
class Var:
    """One FMU variable: name, type, causality, unit, description, start value and range."""
    name: str
    kind: str  # "real" | "integer" | "boolean" | "string"
    causality: str  # "parameter" | "input" | "output"
    unit: str
    description: str
    start: float | int | bool = 0
    min: float | None = None
    max: float | None = None


def _key_variables(key: Key) -> list[Var]:
    p = key.param
    names = fmu_variable_names(key)
    if p.choices and isinstance(p.choices[0], str):
        listed = ", ".join(f"{i}: {c}" for i, c in enumerate(p.choices))
        return [Var(names[0], "integer", "parameter", "1", f"{p.description} ({listed})", 0, 0, len(p.choices) - 1)]
    if key.type is bool:
        described = f"{p.description} (1: true, 0: false)"
        return [Var(names[0], "integer", "parameter", "1", described, int(key.default), 0, 1)]
    kind = "integer" if key.type is int else "real"
    if p.fmu_items:
        starts = list(key.default) + [0.0] * (p.fmu_items - len(key.default))
        return [Var(n, kind, "parameter", p.unit, f"{p.description}: item {i + 1}", starts[i], p.low, p.high)
                for i, n in enumerate(names)]
    no_number = key.default is AUTO or not isinstance(key.default, (int, float))
    start = p.fmu_start if p.fmu_start is not None and no_number else key.default
    return [Var(names[0], kind, "parameter", p.unit, p.description, start, p.low, p.high)]


def case_variables(fmu: str) -> list[Var]:
    """The FMU parameters that carry case keys, from their declarations (models/parameters.py)."""
    return [v for key in fmu_keys(fmu) for v in _key_variables(key)]


def load_parameters(resources: str | None) -> dict:
    """The case values an FMU carries in resources/parameters.json (empty if there are none)."""
    if not resources:
        return {}
    path = Path(resources) / PARAMETERS_FILE
    return json.loads(path.read_text()) if path.exists() else {}


def register_all(slave, variables: list[Var]) -> None:
    """Set each variable's attribute (case value or start) and register it with pythonfmu."""
    given = load_parameters(slave.resources)
    slave._declared = {v.name: v for v in variables if v.causality == "parameter"}
    slave._built = given
    for var in variables:
        value = given.get(var.name, var.start) if var.causality == "parameter" else var.start
        if not isinstance(getattr(type(slave), var.name, None), property):  # a property computes its value
            setattr(slave, var.name, {"real": float, "integer": int, "boolean": bool, "string": str}[var.kind](value))
        causality = getattr(Fmi2Causality, var.causality)
        desc = f"{var.description} [{var.unit}]" if var.unit != "1" else var.description
        if var.causality == "parameter":
            kw = dict(causality=causality, variability=Fmi2Variability.fixed)
        elif var.causality == "input":
            kw = dict(causality=causality,
                      variability=Fmi2Variability.continuous if var.kind == "real" else Fmi2Variability.discrete)
        else:
            kw = dict(causality=causality, initial=Fmi2Initial.exact,
                      variability=Fmi2Variability.continuous if var.kind == "real" else Fmi2Variability.discrete)
        cls = {"real": Real, "integer": Integer, "boolean": Boolean, "string": String}[var.kind]
        slave.register_variable(cls(var.name, description=desc, **kw), nested=False)


# Attributes of every pythonfmu slave that describe the instance, not the simulation
_INSTANCE_ATTRIBUTES = frozenset({"vars", "log_queue", "instance_name", "resources", "visible", "guid", "author",
                                  "license", "version", "copyright", "modelName", "description",
                                  "default_experiment", "_declared", "_built"})


class StateError(InputError):
    """A serialized FMU state that this FMU cannot take back."""


STATE_FORMAT = state_codec.FORMAT


@dataclass
class FmuState:
    """A state taken by fmi2GetFMUstate: copies of the slave's attributes, and (not copied) the constants
    they refer to, by name."""
    owner: str
    items: dict
    constants: dict


@dataclass
class SerializedFmuState:
    """A state read by fmi2DeSerializeFMUstate, resolved against the instance's constants when set."""
    data: bytes


_ACCESSORS: dict = {}  # (class, type, direction, value references) -> reader or writer, shared by the instances


def _accessor(slave, kind: type, vrs, write: bool):
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


class PantohilSlave(Fmi2Slave):
    """An FMU whose whole state can be taken and put back (fmi2GetFMUstate/fmi2SetFMUstate) and serialized
    (fmi2SerializeFMUstate/fmi2DeSerializeFMUstate), through pythonfmu's state hooks.

    The state is every attribute of the slave except the instance's identity, `transient` attributes
    (sockets) and objects that `constants()` names: data fixed at initialisation (operators, profiles),
    shared between the live instance and its states and left out of serialized states, so that a
    state is small and a serialized one is taken back only by an instance initialised with the same
    case. pythonfmu calls the (de)serialization hooks on the class, hence the static methods."""

    transient: tuple[str, ...] = ()
    structural: tuple[str, ...] = ()  # parameters the built resources depend on: fixed at the built values

    def check_parameters(self) -> None:
        """At the end of initialisation, before anything is built: every parameter a finite number within its
        declared range, and every structural one at the value the FMU was built with (a master that sets the
        speed of a built operator would get wrong physics). ValueError naming the parameter: the host logs it
        and the initialisation fails."""
        for name, var in getattr(self, "_declared", {}).items():
            value = getattr(self, name)
            number = var.kind in ("real", "integer")
            if number and (not math.isfinite(value) or (var.min is not None and value < var.min)
                           or (var.max is not None and value > var.max)):
                raise ValueError(f"{type(self).__name__}: parameter {name} = {value!r} is outside its range "
                                     f"[{var.min}, {var.max}]")
            if name in self.structural and name in self._built and value != type(value)(self._built[name]):
                raise ValueError(f"{type(self).__name__}: parameter {name} = {value!r} differs from the "
                                 f"{self._built[name]!r} this FMU was built with, and its built resources depend "
                                 "on it: build the FMU for the new value (pantohil build)")

    def get_real(self, vrs):
        """fmi2GetReal: the values and errors of pythonfmu's, read by attribute name without its
        per-variable closures (a fraction of the cost per call)."""
        hold_thread_state()
        return _accessor(self, Real, vrs, False)(self)

    def get_integer(self, vrs):
        """fmi2GetInteger, as get_real."""
        hold_thread_state()
        return _accessor(self, Integer, vrs, False)(self)

    def set_real(self, vrs, values):
        """fmi2SetReal: each value set on its variable's attribute, as pythonfmu's setter does."""
        hold_thread_state()
        _accessor(self, Real, vrs, True)(self, values)

    def set_integer(self, vrs, values):
        """fmi2SetInteger, as set_real."""
        hold_thread_state()
        _accessor(self, Integer, vrs, True)(self, values)

    def constants(self) -> dict[str, object]:
        """Name -> object fixed after initialisation: not copied into states."""
        return {}

    def _get_fmu_state(self) -> FmuState:
        skip = _INSTANCE_ATTRIBUTES | set(self.transient)
        items = {k: v for k, v in self.__dict__.items() if k not in skip}
        constants = self.constants()
        return FmuState(type(self).__name__, copy.deepcopy(items, {id(o): o for o in constants.values()}), constants)

    def _set_fmu_state(self, state) -> None:
        if isinstance(state, SerializedFmuState):
            state = self._resolve(state)
        constants = self.constants()
        self.__dict__.update(copy.deepcopy(state.items, {id(o): o for o in constants.values()}))

    @staticmethod
    def _fmu_state_to_bytes(state: FmuState) -> bytes:
        by_id = {id(obj): name for name, obj in state.constants.items()}
        return state_codec.encode({"owner": state.owner, "items": state.items}, by_id)

    @staticmethod
    def _fmu_state_from_bytes(data: bytes) -> SerializedFmuState:
        data = bytes(data)
        if not data.startswith(STATE_FORMAT):
            raise StateError(f"not a pantohil FMU state (format {STATE_FORMAT!r} expected)")
        return SerializedFmuState(data)

    def _resolve(self, state: SerializedFmuState) -> FmuState:
        """A serialized state as data (fmus/state_codec.py: nothing in it is executed), checked to be this
        FMU's."""
        constants = self.constants()
        try:
            tree = state_codec.decode(state.data, constants)
        except state_codec.StateDataError as exc:
            raise StateError(f"{type(self).__name__}: {exc}") from None
        owner, items = (tree.get("owner"), tree.get("items")) if isinstance(tree, dict) else (None, None)
        if owner != type(self).__name__ or not isinstance(items, dict):
            raise StateError(f"{type(self).__name__}: the state is of a {owner} FMU")
        unknown = [k for k in items if not isinstance(k, str) or k in _INSTANCE_ATTRIBUTES]
        if unknown:
            raise StateError(f"{type(self).__name__}: the state sets {unknown[0]!r}, which is not simulation state")
        return FmuState(owner, items, constants)
