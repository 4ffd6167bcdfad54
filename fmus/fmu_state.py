"""An FMU's state as pythonfmu's state hooks take it (fmi2GetFMUstate) and as it is serialized
(fmi2SerializeFMUstate): the slave's attributes but the instance's identity, and what a serialized state
must name to be taken back."""
from __future__ import annotations

from dataclasses import dataclass

from pantohil.fmus import state_codec
from pantohil.models.errors import InputError

# Attributes of every pythonfmu slave that describe the instance, not the simulation
INSTANCE_ATTRIBUTES = frozenset({"vars", "log_queue", "instance_name", "resources", "visible", "guid", "author",
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
