"""Drive the same FMUs and connections with the Open Simulation Platform's C++ master (libcosimpy).

libcosim's fixed-step algorithm is Jacobi-like, like JacobiMaster: every connection delays its
signal by one step, so the same catenary delay advance reproduces the same run.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from fmpy import read_model_description


def run_libcosim(fmus: dict[str, Path], connections, dt: float, steps: int, parameters: dict[str, dict],
                 watch: list[tuple[str, str]], record_last: int | None = None) -> dict[tuple[str, str], np.ndarray]:
    """Step `steps` times; return each watched (fmu, real variable) after each of the last `record_last`
    steps (all steps by default)."""
    from libcosimpy.CosimConstants import success
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    vrs = {name: {v.name: (v.valueReference, v.type) for v in read_model_description(str(p)).modelVariables}
           for name, p in fmus.items()}
    log_output_level(CosimLogLevel.WARNING)
    step_ns = int(round(dt * 1e9))
    if abs(step_ns * 1e-9 - dt) > 1e-12:
        raise ValueError(f"dt = {dt} s is not a whole number of nanoseconds")
    execution = CosimExecution.from_step_size(step_size=step_ns)
    index = {}
    for name, path in fmus.items():
        index[name] = execution.add_local_slave(CosimLocalSlave(fmu_path=str(path), instance_name=name))
        if index[name] < 0:
            raise RuntimeError(f"libcosim could not load {path}")
    for name, values in parameters.items():
        for var, value in values.items():
            vr, kind = vrs[name][var]
            setter = {"Real": execution.real_initial_value, "Integer": execution.integer_initial_value,
                      "Boolean": execution.boolean_initial_value}[kind]
            if not setter(index[name], vr, value):
                raise RuntimeError(f"libcosim refused the initial value {name}.{var} = {value}")
    for src, out, dst, inp in connections:
        status = execution.connect_real_variables(index[src], vrs[src][out][0], index[dst], vrs[dst][inp][0])
        if status != success:
            raise RuntimeError(f"libcosim refused the connection {src}.{out} -> {dst}.{inp}")
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    record = steps if record_last is None else min(record_last, steps)
    if steps > record and not execution.step(steps - record):
        raise RuntimeError("libcosim failed to step")
    out = {w: np.zeros(record) for w in watch}
    for k in range(record):
        if not execution.step():
            raise RuntimeError(f"libcosim step {steps - record + k} failed")
        for fmu, var in watch:
            out[(fmu, var)][k] = observer.last_real_values(index[fmu], [vrs[fmu][var][0]])[0]
    return out
