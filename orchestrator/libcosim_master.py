"""Drive the same FMUs and connections with the Open Simulation Platform's C++ master (libcosimpy).

libcosim's fixed-step algorithm is Jacobi-like, like JacobiMaster: every connection delays its
signal by one step, so the same catenary delay advance reproduces the same run.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from fmpy import read_model_description

from .master import RecordingMaster


class LibcosimMaster(RecordingMaster):
    """The JacobiMaster interface (step, values, records) over a libcosim execution."""

    def __init__(self, fmus: dict[str, Path], connections, parameters: dict[str, dict], dt: float,
                 capacity: int, realtime_factor: float | None = None):
        from libcosimpy.CosimConstants import success
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
        from libcosimpy.CosimObserver import CosimObserver
        from libcosimpy.CosimSlave import CosimLocalSlave

        log_output_level(CosimLogLevel.WARNING)
        self.dt = dt
        self.names = list(fmus)
        descriptions = {n: read_model_description(str(p)) for n, p in fmus.items()}
        self._vr = {n: {v.name: (v.valueReference, v.type) for v in d.modelVariables} for n, d in descriptions.items()}
        step_ns = int(round(dt * 1e9))
        if abs(step_ns * 1e-9 - dt) > 1e-12:
            raise ValueError(f"libcosim needs a step of whole nanoseconds; dt = {dt} s is not")
        ex = CosimExecution.from_step_size(step_size=step_ns)
        self._index = {}
        for name, path in fmus.items():
            self._index[name] = ex.add_local_slave(CosimLocalSlave(fmu_path=str(path), instance_name=name))
            if self._index[name] < 0:
                raise RuntimeError(f"libcosim could not load {path}")
        for name, values in parameters.items():
            for var, value in values.items():
                vr, kind = self._vr[name][var]
                setter = {"Real": ex.real_initial_value, "Integer": ex.integer_initial_value,
                          "Boolean": ex.boolean_initial_value}[kind]
                if not setter(self._index[name], vr, value):
                    raise RuntimeError(f"libcosim refused the initial value {name}.{var} = {value}")
        for src, out, dst, inp in connections:
            status = ex.connect_real_variables(self._index[src], self._vr[src][out][0], self._index[dst],
                                               self._vr[dst][inp][0])
            if status != success:
                raise RuntimeError(f"libcosim refused the connection {src}.{out} -> {dst}.{inp}")
        if realtime_factor:
            ex.real_time_simulation_enabled(True)
            ex.real_time_factor_target(realtime_factor)
        self._observer = CosimObserver.create_last_value()
        ex.add_observer(self._observer)
        self._ex = ex
        self._init_records(descriptions, connections, capacity)
        self._reads = [(n, self._index[n], [self._vr[n][v][0] for v in self.real_outputs[n]],
                        [self._vr[n][v][0] for v in self.int_outputs[n]],
                        [self._vr[n][v][0] for v in self.input_names.get(n, [])]) for n in self.names]
        self.values = {n: [0.0] * len(self.real_outputs[n]) for n in self.names}

    def advance(self, steps: int) -> None:
        """Step without recording (for a long lead-in)."""
        if steps > 0 and not self._ex.step(steps):
            raise RuntimeError("libcosim failed to step")
        self.k += steps

    def step(self) -> None:
        """Advance libcosim by one step and record the watched outputs and inputs of that step."""
        k, obs = self.k, self._observer
        row = k % self.capacity
        t0 = time.perf_counter_ns()
        if not self._ex.step():
            raise RuntimeError(f"libcosim step {k} failed")
        self.step_ns[self.names[0]][row] = time.perf_counter_ns() - t0
        for n, idx, reals, ints, inputs in self._reads:
            out = obs.last_real_values(idx, reals)
            self.values[n] = out
            self.record[n][row] = out
            if ints:
                self.record_int[n][row] = obs.last_integer_values(idx, ints)
            if inputs:
                self.record_in[n][row] = obs.last_real_values(idx, inputs)
        self.k = k + 1

    def per_step_us(self) -> dict[str, float]:
        """libcosim steps all FMUs in one call: one figure for the whole step."""
        held = min(self.k, self.capacity)
        return {"libcosim": float(np.median(self.step_ns[self.names[0]][:held])) / 1000.0} if self.k else {}

    def close(self) -> None:
        """Release the execution (its slaves are freed when it is collected; the FMU libraries stay loaded)."""
        self._ex = None  # the execution frees its slaves when collected


def run_libcosim(fmus: dict[str, Path], connections, dt: float, steps: int, parameters: dict[str, dict],
                 watch: list[tuple[str, str]], record_last: int | None = None) -> dict[tuple[str, str], np.ndarray]:
    """Step `steps` times; return each watched (fmu, variable) after each of the last `record_last`
    steps (all steps by default). Inputs are watched as (fmu, input name)."""
    record = steps if record_last is None else min(record_last, steps)
    master = LibcosimMaster(fmus, connections, parameters, dt, capacity=steps)
    try:
        master.advance(steps - record)
        for _ in range(record):
            master.step()
        out = {}
        for fmu, var in watch:
            if var in master.input_names.get(fmu, []):
                out[(fmu, var)] = master.record_in[fmu][steps - record:steps, master.input_names[fmu].index(var)]
            else:
                out[(fmu, var)] = master.column(fmu, var, steps - record, steps)
        return out
    finally:
        master.close()
