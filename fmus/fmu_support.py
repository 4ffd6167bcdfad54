"""The base of the pantohil FMUs: a pythonfmu slave whose parameters are checked at initialisation
(ranges, and the structural ones fixed at their built values), whose state can be taken, put back and
serialized, and whose get/set calls take the fast accessors (fmus/fast_accessors.py). The variables are
declared in fmus/variables.py.
"""
from __future__ import annotations

import copy
import math

from pythonfmu import Fmi2Slave, Integer, Real

from pantohil.fmus import state_codec
from pantohil.fmus.fast_accessors import accessor, hold_thread_state
from pantohil.fmus.fmu_state import INSTANCE_ATTRIBUTES, STATE_FORMAT, FmuState, SerializedFmuState, StateError


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
        return accessor(self, Real, vrs, False)(self)

    def get_integer(self, vrs):
        """fmi2GetInteger, as get_real."""
        hold_thread_state()
        return accessor(self, Integer, vrs, False)(self)

    def set_real(self, vrs, values):
        """fmi2SetReal: each value set on its variable's attribute, as pythonfmu's setter does."""
        hold_thread_state()
        accessor(self, Real, vrs, True)(self, values)

    def set_integer(self, vrs, values):
        """fmi2SetInteger, as set_real."""
        hold_thread_state()
        accessor(self, Integer, vrs, True)(self, values)

    def constants(self) -> dict[str, object]:
        """Name -> object fixed after initialisation: not copied into states."""
        return {}

    def _get_fmu_state(self) -> FmuState:
        skip = INSTANCE_ATTRIBUTES | set(self.transient)
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
        unknown = [k for k in items if not isinstance(k, str) or k in INSTANCE_ATTRIBUTES]
        if unknown:
            raise StateError(f"{type(self).__name__}: the state sets {unknown[0]!r}, which is not simulation state")
        return FmuState(owner, items, constants)
