"""A fixed-step Jacobi co-simulation master over fmpy (the semantics of libcosim's fixed-step
algorithm): at step k every FMU gets the outputs of step k-1, then all FMUs step, then all outputs
are read. Each connection therefore delays its signal by one step."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from pantohil.builder.system import HORIZON_OUTPUTS

from .fmu_runtime import FmuInstance


class RecordingMaster:
    """What every master records: each FMU's real and integer outputs and the inputs it was given,
    step by step, plus the wall time of each FMU's step (where the master can tell).

    The records are rings of `capacity` steps: step k is row k % capacity, so a run of any length
    keeps the last `capacity` steps (what the caller logs and summarises), never more."""

    steps_a_span_at_once = False  # True: the master has `run_steps(count, stop, force_limit, height_limit)`
    steps_per_check = 1  # steps between the run's checks of its limits (records up to date at least as often)

    def step_block(self, count: int) -> None:
        """`count` steps, recorded."""
        for _ in range(count):
            self.step()

    def sync(self) -> None:
        """Bring the records up to date (a master that records as it steps has nothing to do)."""

    def _init_records(self, descriptions: dict, connections, capacity: int) -> None:
        self.capacity = capacity
        connected = {(c[0], c[1]) for c in connections}
        self.real_outputs = {n: [v.name for v in d.modelVariables if v.causality == "output" and v.type == "Real"
                                 and (v.name not in HORIZON_OUTPUTS or (n, v.name) in connected)]
                             for n, d in descriptions.items()}  # an unconnected horizon is not read
        self.int_outputs = {n: [v.name for v in d.modelVariables if v.causality == "output" and v.type == "Integer"]
                            for n, d in descriptions.items()}
        self._in_map, self.input_names = {}, {}
        for n in self.names:
            wires = [(c[3], c[0], self.real_outputs[c[0]].index(c[1])) for c in connections if c[2] == n]
            if wires:
                self.input_names[n] = [w[0] for w in wires]
                self._in_map[n] = [(w[1], w[2]) for w in wires]
        self.record = {n: np.zeros((capacity, len(self.real_outputs[n]))) for n in self.names}
        self.record_int = {n: np.zeros((capacity, len(self.int_outputs[n])), dtype=np.int64)
                           for n in self.names if self.int_outputs[n]}
        self.record_in = {n: np.zeros((capacity, len(m))) for n, m in self._in_map.items()}
        self.step_ns = {n: np.zeros(capacity, dtype=np.int64) for n in self.names}
        self.k = 0

    def rows(self, start: int, stop: int):
        """Ring rows of steps start..stop-1 (a slice unless they wrap); only the last `capacity` steps
        are kept."""
        count = max(stop - start, 0)
        if count and (start < self.k - self.capacity or count > self.capacity):
            raise IndexError(f"steps {start}..{stop} are no longer recorded (the last {self.capacity} are)")
        first = start % self.capacity if count else 0
        if first + count <= self.capacity:
            return slice(first, first + count)
        return np.arange(start, stop) % self.capacity

    def column(self, fmu: str, output: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """The recorded values of an FMU output over steps start..stop."""
        stop = self.k if stop is None else stop
        if output in self.real_outputs[fmu]:
            return self.record[fmu][self.rows(start, stop), self.real_outputs[fmu].index(output)]
        return self.record_int[fmu][self.rows(start, stop), self.int_outputs[fmu].index(output)]

    def input_column(self, fmu: str, src: str, output: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """The recorded values an FMU received from output `output` of `src` over steps start..stop."""
        stop = self.k if stop is None else stop
        j = self._in_map[fmu].index((src, self.real_outputs[src].index(output)))
        return self.record_in[fmu][self.rows(start, stop), j]

    def int_value(self, fmu: str, output: str, k: int) -> int:
        """An integer output after step k (one of the last `capacity` steps)."""
        return int(self.record_int[fmu][k % self.capacity, self.int_outputs[fmu].index(output)])

    record_start = 0  # first step recorded (a resumed run records from its checkpoint's span on)

    def per_step_us(self) -> dict[str, float]:
        """Median time per step of each FMU over the recorded steps still held [us]."""
        first = max(self.record_start, self.k - self.capacity)
        if self.k <= first:
            return {}
        steps = self.rows(first, self.k)
        return {n: float(np.median(self.step_ns[n][steps])) / 1000.0 for n in self.step_ns}


class JacobiMaster(RecordingMaster):
    """Steps named FMUs connected by (src, output, dst, input) tuples and records every real output."""

    def __init__(self, fmus: dict[str, Path], connections, parameters: dict[str, dict], dt: float,
                 capacity: int, logging: bool = False):
        self.dt = dt
        self.names = list(fmus)
        self.instances = {}
        try:
            for name in self.names:
                self.instances[name] = FmuInstance(name, fmus[name], logging)
            for name, inst in self.instances.items():
                inst.setup(0.0, parameters.get(name, {}))
        except Exception:
            self.close()
            raise
        self._init_records({n: i.description for n, i in self.instances.items()}, connections, capacity)
        self._out = {n: self.instances[n].port(self.real_outputs[n]) for n in self.names}
        self._out_int = {n: self.instances[n].port(self.int_outputs[n]) for n in self.names if self.int_outputs[n]}
        self._in = {n: self.instances[n].port(names) for n, names in self.input_names.items()}
        self.values = {n: self._out[n].read() for n in self.names}  # outputs after initialisation
        self._steps = self._plan()

    def _plan(self):
        """Per FMU: (name, instance, input port, input wiring, output port, int port, records) in step order."""
        plan = []
        for n in self.names:
            plan.append((n, self.instances[n], self._in.get(n), self._in_map.get(n, []), self._out[n],
                         self._out_int.get(n), self.record[n], self.record_int.get(n), self.record_in.get(n),
                         self.step_ns[n]))
        return plan

    def step(self) -> None:
        """One communication step of length dt (Jacobi)."""
        k = self.k
        row = k % self.capacity
        t = k * self.dt
        values, clock = self.values, time.perf_counter_ns
        new_values = {}
        for n, inst, in_port, wiring, out_port, int_port, rec, rec_int, rec_in, ns in self._steps:
            t0 = clock()
            if in_port is not None:
                u = [values[src][j] for src, j in wiring]
                in_port.write(u)
                rec_in[row] = u
            inst.do_step(t, self.dt)
            out = out_port.read()
            if int_port is not None:
                rec_int[row] = int_port.read()
            ns[row] = clock() - t0
            new_values[n] = out
            rec[row] = out
        self.values = new_values
        self.k = k + 1

    def serialize_states(self) -> dict[str, bytes]:
        """Every FMU's serialized state, by instance name (a checkpoint of the system)."""
        return {n: inst.serialize_state() for n, inst in self.instances.items()}

    def deserialize_states(self, states: dict[str, bytes]) -> None:
        """Put back every FMU's state from serialize_states."""
        for n, inst in self.instances.items():
            inst.deserialize_state(states[n])

    def close(self) -> None:
        """Close every FMU instance."""
        for inst in self.instances.values():
            inst.close()
