"""Drive the same FMUs and connections with the Open Simulation Platform's C++ master (libcosimpy).

libcosim's fixed-step algorithm is Jacobi-like, like JacobiMaster: every connection delays its
signal by one step, so the same catenary delay advance reproduces the same run.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from fmpy import read_model_description

from pantohil.builder.system import HORIZON_OUTPUTS

from .master import RecordingMaster

CHECK_INTERVAL_S = 0.02  # the run's limits and link state are checked at least this often
MAX_CHECK_STEPS = 256
HORIZON_VARIABLES = frozenset(HORIZON_OUTPUTS)  # the catenary's outputs and the adapter's inputs


class LibcosimMaster(RecordingMaster):
    """The JacobiMaster interface (step, values, records) over a libcosim execution.

    libcosim moves the connected values itself; Python only reads back what is recorded, through a
    time-series observer of those variables alone (the horizon's heights are connected, never read), a
    block of steps at a time: a last-value observer would read every variable of every FMU at every step,
    and one read per variable per step would cost more than the step. The records are brought up to date
    before any of them is read (`values`, `column`, `int_value`, ...), at the latest every
    `steps_per_check` steps."""

    def __init__(self, fmus: dict[str, Path], connections, parameters: dict[str, dict], dt: float,
                 capacity: int, realtime_factor: float | None = None):
        from libcosimpy.CosimConstants import success
        from libcosimpy.CosimEnums import CosimVariableType
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
        self._ex = ex
        self._init_records(descriptions, connections, capacity)
        self.steps_per_check = max(1, min(MAX_CHECK_STEPS, round(CHECK_INTERVAL_S / dt)))
        self._observer = CosimObserver.create_time_series(buffer_size=2 * self.steps_per_check + 8)
        ex.add_observer(self._observer)  # before any series is started
        self._series = []  # (kind, slave, reference, record array, column) of every recorded variable
        for n in self.names:
            wanted = [("Real", self.real_outputs[n], self.record[n]), ("Integer", self.int_outputs[n],
                                                                        self.record_int.get(n)),
                      ("Real", self.input_names.get(n, []), self.record_in.get(n))]
            for kind, names, rec in wanted:
                for j, var in enumerate(names):
                    if var in HORIZON_VARIABLES:
                        continue  # connected inside libcosim; never read (the column stays 0)
                    vtype = CosimVariableType.REAL if kind == "Real" else CosimVariableType.INTEGER
                    if not self._observer.start_time_series(self._index[n], self._vr[n][var][0], vtype):
                        raise RuntimeError(f"libcosim cannot observe {n}.{var}")
                    self._series.append((kind, self._index[n], self._vr[n][var][0], rec, j))
        self._values = {n: [0.0] * len(self.real_outputs[n]) for n in self.names}
        self._synced = 0  # steps whose values are in the records

    @property
    def values(self) -> dict[str, list[float]]:
        """Each FMU's real outputs after the latest step."""
        self.sync()
        return self._values

    def advance(self, steps: int) -> None:
        """Step without recording (for a long lead-in)."""
        if steps > 0 and not self._ex.step(steps):
            raise RuntimeError("libcosim failed to step")
        self.k += steps
        self._synced = self.k

    def step(self) -> None:
        """Advance libcosim by one step (recorded at the next `sync`)."""
        self.step_block(1)

    def step_block(self, count: int) -> None:
        """Advance libcosim by `count` steps in one call, recording them."""
        while count > 0:
            n = min(count, self.steps_per_check - (self.k - self._synced))
            t0 = time.perf_counter_ns()
            if not self._ex.step(n):
                raise RuntimeError(f"libcosim step {self.k} failed")
            per_step = (time.perf_counter_ns() - t0) // n
            self.step_ns[self.names[0]][self.rows(self.k, self.k + n)] = per_step
            self.k += n
            count -= n
            if self.k - self._synced >= self.steps_per_check:
                self.sync()

    def sync(self) -> None:
        """Read the recorded variables of the steps not yet read into the records."""
        first, count = self._synced, self.k - self._synced
        if count <= 0:
            return
        obs, rows = self._observer, self.rows(first, self.k)
        for kind, slave, ref, rec, j in self._series:
            read = obs.time_series_real_samples if kind == "Real" else obs.time_series_integer_samples
            _, steps, samples = read(slave, ref, first + 1, count)  # libcosim numbers our step k as k + 1
            if len(samples) != count or steps[0] != first + 1:
                raise RuntimeError(f"libcosim's observer lost steps {first + 1}..{self.k} (got {len(samples)})")
            rec[rows, j] = samples
        last = (self.k - 1) % self.capacity
        self._values = {n: self.record[n][last].tolist() for n in self.names}
        self._synced = self.k

    def column(self, fmu: str, output: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """As RecordingMaster.column, the records brought up to date first."""
        self.sync()
        return super().column(fmu, output, start, stop)

    def input_column(self, fmu: str, src: str, output: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """As RecordingMaster.input_column, the records brought up to date first."""
        self.sync()
        return super().input_column(fmu, src, output, start, stop)

    def int_value(self, fmu: str, output: str, k: int) -> int:
        """As RecordingMaster.int_value, the records brought up to date first."""
        self.sync()
        return super().int_value(fmu, output, k)

    def per_step_us(self) -> dict[str, float]:
        """libcosim steps all FMUs in one call: one figure for the whole step."""
        held = min(self.k, self.capacity)
        return {"libcosim": float(np.median(self.step_ns[self.names[0]][:held])) / 1000.0} if self.k else {}

    def close(self) -> None:
        """Release the execution (its slaves are freed when it is collected; the FMU libraries stay loaded)."""
        self._ex = None  # the execution frees its slaves when collected
