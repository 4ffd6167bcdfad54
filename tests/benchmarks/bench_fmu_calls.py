"""Where a step of the FMU path goes, call by call: each FMI call the fmpy master makes per step on the
default case's three FMUs (set inputs, doStep, get reals, get integers), timed on the live instances
mid-run, beside the same calls on a trivial pythonfmu FMU (one real input copied to one real output)
and the model work alone (the step functions the FMUs' doStep call). Prints medians; not a timed test.

    python tests/benchmarks/bench_fmu_calls.py [--calls 20000] [--repeats 5]

The trivial FMU's set+doStep+get is the least a step of any pythonfmu FMU costs through fmpy; three of
them are the floor of a Jacobi step of the three FMUs whatever their models do.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import statistics
import tempfile
import textwrap
import time
from pathlib import Path

TRIVIAL = textwrap.dedent('''
    from pythonfmu import Fmi2Causality, Fmi2Slave, Real


    class Trivial(Fmi2Slave):
        """One real input copied to one real output at each step."""
        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            self.u = 0.0
            self.y = 0.0
            self.register_variable(Real("u", causality=Fmi2Causality.input))
            self.register_variable(Real("y", causality=Fmi2Causality.output))

        def do_step(self, current_time, step_size):
            self.y = self.u
            return True
''')


def _median_us(fn, calls: int, repeats: int) -> float:
    """Median over repeats of the mean time of one call [us]."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        times.append((time.perf_counter() - t0) / calls * 1e6)
    return statistics.median(times)


def _calls(master, name: str, calls: int, repeats: int) -> dict[str, float]:
    """The master's per-step calls on one FMU instance, each timed alone [us]."""
    inst, dt = master.instances[name], master.dt
    out = {}
    if name in master._in:
        port, values = master._in[name], master.values
        u = [values[src][j] for src, j in master._in_map[name]]
        out[f"set {len(u)} real"] = _median_us(lambda: port.write(u), calls, repeats)
    t = master.k * dt
    out["doStep"] = _median_us(lambda: inst.do_step(t, dt), calls, repeats)
    out[f"get {master._out[name].n} real"] = _median_us(master._out[name].read, calls, repeats)
    if name in master._out_int:
        out[f"get {master._out_int[name].n} integer"] = _median_us(master._out_int[name].read, calls, repeats)
    return out


def _trivial(tmp: Path, calls: int, repeats: int) -> dict[str, float]:
    import pythonfmu

    from pantohil.orchestrator.fmu_runtime import FmuInstance

    script = tmp / "trivial.py"
    script.write_text(TRIVIAL)
    with contextlib.redirect_stdout(io.StringIO()):
        fmu = pythonfmu.FmuBuilder.build_FMU(script, dest=tmp / "trivial")
    inst = FmuInstance("trivial", fmu)
    inst.setup(0.0, {})
    set_port, get_port = inst.port(["u"]), inst.port(["y"])
    out = {"set 1 real": _median_us(lambda: set_port.write([1.0]), calls, repeats),
           "doStep": _median_us(lambda: inst.do_step(0.0, 0.001), calls, repeats),
           "get 1 real": _median_us(get_port.read, calls, repeats)}
    inst.close()
    return out


def _models(case, delay: int, calls: int, repeats: int) -> dict[str, float]:
    """The model work of a step alone: the FMU classes' own models, created in this process."""
    from pantohil.orchestrator.inprocess import create_slaves

    slaves = create_slaves(case, {"catenary": {"delay_steps": delay}})
    hil, rig, pan = (slaves["catenary"].stepped_iteration, slaves["rig"].stepped_rig,
                     slaves["pantograph"].stepped_pantograph)
    return {"catenary iteration step": _median_us(lambda: hil.step(100.0), calls, repeats),
            "rig step": _median_us(lambda: rig.step(0.0, 100.0), calls, repeats),
            "pantograph step": _median_us(lambda: pan.step(0.0), calls, repeats)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=20000, help="calls per timing")
    ap.add_argument("--repeats", type=int, default=5, help="timings per call (median printed)")
    args = ap.parse_args()
    from pantohil.builder.build_fmus import build_case_fmus
    from pantohil.models.case import load_case
    from pantohil.orchestrator.run_topology import VIRTUAL, delay_plan
    from pantohil.orchestrator.master import JacobiMaster

    case = load_case(None, [])
    delay = delay_plan(case)["delay_steps"]
    with tempfile.TemporaryDirectory() as tmp:
        fmus = build_case_fmus(case, Path(tmp) / "fmus", delay, VIRTUAL.fmus, ("127.0.0.1", 47800))
        master = JacobiMaster(fmus, VIRTUAL.connections, {"catenary": {"delay_steps": delay}}, case.dt_s,
                              12 * case.samples_per_span)
        for _ in range(2 * case.samples_per_span):  # mid-run
            master.step()
        steps = 5 * case.samples_per_span
        t0 = time.perf_counter()
        for _ in range(steps):
            master.step()
        step_us = (time.perf_counter() - t0) / steps * 1e6
        per_fmu = {name: _calls(master, name, args.calls, args.repeats) for name in master.names}
        models = _models(case, delay, args.calls, args.repeats)
        master.close()
        trivial = _trivial(Path(tmp), args.calls, args.repeats)
    print(f"default case through the fmpy master: {step_us:.1f} us per step ({1e3 * case.dt_s / step_us * 1e3:.1f}x "
          f"real time at dt = {case.dt_s * 1e3:g} ms), master and records included, no logging")
    total = 0.0
    for name, calls in per_fmu.items():
        total += sum(calls.values())
        print(f"  {name:<11s} " + "; ".join(f"{k} {v:.2f} us" for k, v in calls.items())
              + f"; sum {sum(calls.values()):.2f} us")
    print(f"  the FMI calls of a step, each timed alone: {total:.1f} us; the rest of the step (master, records): "
          f"{step_us - total:.1f} us")
    print("model work alone: " + "; ".join(f"{k} {v:.2f} us" for k, v in models.items())
          + f"; sum {sum(models.values()):.2f} us")
    floor = sum(trivial.values())
    print("trivial pythonfmu FMU: " + "; ".join(f"{k} {v:.2f} us" for k, v in trivial.items())
          + f"; set+doStep+get {floor:.2f} us")
    print(f"floor of a step of three pythonfmu FMUs (3 x trivial set+doStep+get): {3 * floor:.1f} us = "
          f"{1e3 * case.dt_s / (3 * floor) * 1e3:.0f}x real time at dt = {case.dt_s * 1e3:g} ms")


if __name__ == "__main__":
    main()
