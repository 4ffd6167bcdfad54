"""PFEM budgets: operator build time of the benchmark-like case (limit 10 s on this 2-core machine,
issue 21; the thesis reports about 30 min), with the build's profile (where the time goes), load from the
cache (limit 2 s), and the catenary FMU's do_step with droppers (limit 50 us median; the thesis reports
0.15 ms). Also writes the contact force of the nonlinear (dropper slackening) and linear runs overlaid.
Prints medians; not a timed test. `--build-only` stops after the operator builds and loads.

    python tests/benchmarks/bench_pfem.py [--builds 3] [--loads 5] [--case pfem_benchmark_250] [--build-only]
"""
from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
CASES = ROOT / "models" / "data" / "cases"
BUDGET_S = {"pfem_benchmark_250": 10, "pfem_stitched_250": 60}  # issue 21; Paper D's issue


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--builds", type=int, default=3, help="cold builds of the operators")
    ap.add_argument("--loads", type=int, default=5, help="loads from the cache")
    ap.add_argument("--spans", type=int, default=10, help="converged spans replayed through the FMU")
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "bench_pfem")
    ap.add_argument("--case", default="pfem_benchmark_250", help="case file in models/data/cases (without .toml)")
    ap.add_argument("--build-only", action="store_true", help="only the operator builds and loads")
    args = ap.parse_args()
    case_file = CASES / f"{args.case}.toml"
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["PANTOHIL_CACHE"] = str(Path(tmp) / "cache")
        from pantohil.models.catenary.pfem import operator_cache as ob
        from pantohil.models.case import load_case
        from pantohil.models.catenary.pfem.operator_file import load_operators

        case = load_case(case_file)
        builds, cpu = [], []
        load_before = os.getloadavg()
        for _ in range(args.builds):
            for f in (Path(tmp) / "cache" / "operators").glob("*.npz") if (Path(tmp) / "cache").exists() else []:
                f.unlink()
            c0 = time.process_time()
            b = ob.case_operators(case, progress=False)
            cpu.append(time.process_time() - c0)
            builds.append(b.build_s)
        load_after = os.getloadavg()
        loads = []
        for _ in range(args.loads):
            t0 = time.perf_counter()
            b = ob.case_operators(case, progress=False)
            loads.append(time.perf_counter() - t0)
        ops = load_operators(b.path)
        print(f"{args.case}: N = {case.samples_per_span}, {ops.n_droppers} droppers, "
              f"{b.n_frequencies} frequencies, {ops.info.get('modes', '?')} modes, file {b.bytes / 1e6:.1f} MB")
        print(f"operator build:   median {statistics.median(builds):.1f} s over {len(builds)} "
              f"({', '.join(f'{t:.1f}' for t in builds)}; limit {BUDGET_S.get(args.case, '-')} s; "
              "form-finding, build_operators, file)")
        print(f"  build_operators: {ops.info['build_s']:.2f} s in the last build, "
              f"{ops.info.get('chunks', '?')} chunks, "
              f"{ops.info.get('modes_one_by_one', '?')} modes one by one + {ops.info.get('virtual_modes', '?')} "
              "virtual in the contact functional; profile:")
        for phase, seconds in ops.info.get("profile_s", {}).items():
            print(f"    {phase:<72s} {seconds:6.2f} s")
        print(f"  CPU time of the process (both threads): median {statistics.median(cpu):.1f} s; load average "
              f"{load_before[0]:.1f} before the builds, {load_after[0]:.1f} after (2 cores)")
        print(f"load from cache:  median {statistics.median(loads):.2f} s over {len(loads)} (limit 2 s)")
        if args.build_only:
            return

        from pantohil.orchestrator.hil_run import run_case
        from pantohil.orchestrator.report import plot_force_comparison

        args.out.mkdir(parents=True, exist_ok=True)
        runs = {}
        for name, extra in (("dropper slackening", []), ("linear (no slackening)", ["pfem.droppers=false"])):
            c = load_case(case_file, extra)
            s = run_case(c, Path(tmp) / name.split()[0], progress=False)
            span = np.loadtxt(Path(tmp) / name.split()[0] / "steady_span.csv", delimiter=",", skiprows=1)
            runs[name] = (s, span[:, 3])
            print(f"{name:<24s} {s.status} after {s.spans} spans, std {s.contact_force.std_N:.2f} N, "
                  f"catenary set+doStep+get median {s.timing.per_step_us['catenary']:.1f} us")
        plot_force_comparison(args.out / "pfem_linear_vs_nonlinear.png", case.dt_s,
                              {k: v[1] for k, v in runs.items()},
                              f"{args.case}: converged span, with and without dropper slackening")
        print(f"plot: {args.out / 'pfem_linear_vs_nonlinear.png'}")
        force = runs["dropper slackening"][1]
        print(f"catenary FMU do_step alone, replaying the converged force for {args.spans} spans: "
              f"median {do_step_median(case, force, args.spans, Path(tmp)):.1f} us (limit 50 us)")


def do_step_median(case, force: np.ndarray, spans: int, tmp: Path) -> float:
    """Time the catenary FMU's doStep alone (fmpy, ctypes), with the converged span's force as input
    after a warm-up long enough for the dropper corrections to settle."""
    from pantohil.builder.build_fmus import build_case_fmus, default_delay_steps
    from pantohil.orchestrator.fmu_runtime import FmuInstance

    fmu = build_case_fmus(case, tmp / "fmus", names=("catenary",))["catenary"]
    inst = FmuInstance("catenary", fmu)
    inst.setup(0.0, {"delay_steps": default_delay_steps(case), "ramp_steps": 0})
    port = inst.port(["contact_force"])
    n, dt = case.samples_per_span, case.dt_s
    times = []
    for s in range(60 + spans):
        for m in range(n):
            port.write([force[m]])
            t0 = time.perf_counter_ns()
            inst.do_step((s * n + m) * dt, dt)
            if s >= 60:
                times.append(time.perf_counter_ns() - t0)
    inst.close()
    return float(np.median(times)) / 1000.0


if __name__ == "__main__":
    main()
