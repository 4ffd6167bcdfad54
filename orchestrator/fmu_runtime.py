"""One FMU instance driven through fmpy with preallocated ctypes buffers (the hot path of the master)."""
from __future__ import annotations

import shutil
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2Boolean, fmi2Integer, fmi2Real, fmi2ValueReference
from pantohil.models.errors import FmuFailure
from pantohil.models.scratch import scratch_dir

STATUS_NAMES = {0: "OK", 1: "warning", 2: "discard", 3: "error", 4: "fatal", 5: "pending"}


class FmuError(FmuFailure):
    """An FMU returned an error status; the message names the FMU and the call."""


class Port:
    """A fixed set of variables of one type, read or written in one FMI call."""

    _ctype = {"Real": fmi2Real, "Integer": fmi2Integer, "Boolean": fmi2Boolean}

    def __init__(self, fmu: FmuInstance, kind: str, names: list[str]):
        self.fmu, self.kind, self.names = fmu, kind, list(names)
        self.n = len(names)
        self.vr = (fmi2ValueReference * self.n)(*[fmu.vr[name] for name in names])
        self.values = (self._ctype[kind] * self.n)()
        self._get = fmu.raw(f"fmi2Get{kind}")
        self._set = fmu.raw(f"fmi2Set{kind}")

    def read(self) -> list:
        """Get the port's variables from the FMU in one call."""
        self.fmu.check(self._get(self.fmu.component, self.vr, self.n, self.values), f"get {self.names}")
        return self.values[:]

    def write(self, values) -> None:
        """Set the port's variables in the FMU in one call."""
        self.values[:] = values
        self.fmu.check(self._set(self.fmu.component, self.vr, self.n, self.values), f"set {self.names}")


class FmuInstance:
    """Extract, instantiate and initialise an FMU; set parameters; step it."""

    def __init__(self, name: str, path: Path, logging: bool = False):
        self.name = name
        self.description = read_model_description(str(path))
        self._dir = str(scratch_dir(f"{name}_"))  # removed by the next run if this process is killed
        extract(str(path), self._dir)
        self.vr = {v.name: v.valueReference for v in self.description.modelVariables}
        self.types = {v.name: v.type for v in self.description.modelVariables}
        self.messages: list[str] = []
        self.slave = FMU2Slave(guid=self.description.guid, unzipDirectory=self._dir,
                               modelIdentifier=self.description.coSimulation.modelIdentifier, instanceName=name)
        self.slave.instantiate(loggingOn=logging, callbacks=None)
        self.component = self.slave.component
        self._do_step = self.raw("fmi2DoStep")

    def raw(self, function: str):
        """The FMI function `function` of the loaded library, for calls fmpy does not wrap."""
        return self.slave._functions[function]

    def check(self, status: int, what: str) -> None:
        """Raise FmuError naming the FMU and the call if an FMI status is worse than fmi2Warning."""
        if status > 1:
            raise FmuError(f"FMU {self.name}: {what} returned {STATUS_NAMES.get(status, status)}")

    def setup(self, start_time: float, parameters: dict) -> None:
        """Set up the experiment at start_time, set the parameters, enter and exit initialisation."""
        self.slave.setupExperiment(startTime=start_time)
        self.set_values(parameters)
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()

    def set_values(self, values: dict) -> None:
        """Set variables by name (FmuError for a name the FMU does not have)."""
        for name, value in values.items():
            if name not in self.vr:
                raise FmuError(f"FMU {self.name} has no variable {name!r}")
            kind = self.types[name]
            getattr(self.slave, f"set{kind}")([self.vr[name]], [value])

    def get_values(self, names: list[str]) -> dict:
        """Get variables by name."""
        return {n: getattr(self.slave, f"get{self.types[n]}")([self.vr[n]])[0] for n in names}

    def port(self, names: list[str]) -> Port:
        """A Port that gets or sets these variables (all of one type) in one FMI call."""
        kinds = {self.types[n] for n in names}
        if len(kinds) != 1:
            raise ValueError(f"a port takes variables of one type, got {kinds}")
        return Port(self, kinds.pop(), names)

    def serialize_state(self) -> bytes:
        """The FMU's whole state, serialized (fmi2GetFMUstate + fmi2SerializeFMUstate)."""
        state = self.slave.getFMUstate()
        try:
            return bytes(self.slave.serializeFMUstate(state))
        finally:
            self.slave.freeFMUstate(state)

    def deserialize_state(self, data: bytes) -> None:
        """Put back a state serialized by an instance of the same FMU (fmi2DeSerializeFMUstate + fmi2SetFMUstate)."""
        state = self.slave.deSerializeFMUstate(data)
        try:
            self.slave.setFMUstate(state)
        finally:
            self.slave.freeFMUstate(state)

    def do_step(self, t: float, dt: float) -> None:
        """fmi2DoStep from t over dt; FmuError if the FMU refuses."""
        self.check(self._do_step(self.component, t, dt, 1), f"doStep at t={t:.6f} s")

    def close(self) -> None:
        """Terminate and free the instance, keeping the FMU library loaded (unloading it is not safe)."""
        try:
            self.slave.terminate()
            # not slave.freeInstance(), which also unloads the library: pythonfmu's binary owns Python
            # objects that can outlive the instance, and unloading it can crash the interpreter at exit
            self.slave.fmi2FreeInstance(self.component)
        except Exception:  # already failed: still remove the extracted files
            pass
        shutil.rmtree(self._dir, ignore_errors=True)
