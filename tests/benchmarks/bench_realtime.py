"""Real-time factor of the default case through fmpy with the three FMUs and MCAP logging
(budget: at least 10x real time). Prints medians over repeats; not a timed test.

    python tests/benchmarks/bench_realtime.py [--repeats 5] [--spans 30]
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

from pantohil.models.case import load_case
from pantohil.orchestrator.hil_run import run_case


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--spans", type=int, default=30, help="spans per run (a fixed amount of work)")
    args = ap.parse_args()
    case = load_case(None, [f"run.max_spans={args.spans}", "run.convergence_tol=1e-12"])
    rtf, per_step, wall = [], {}, []
    with tempfile.TemporaryDirectory() as tmp:
        run_case(case, Path(tmp) / "warmup", progress=False)  # builds (and caches) the FMUs
        for i in range(args.repeats):
            s = run_case(case, Path(tmp) / f"r{i}", progress=False)
            rtf.append(s.timing.realtime_factor)
            wall.append(s.timing.wall_s)
            for fmu, us in s.timing.per_step_us.items():
                per_step.setdefault(fmu, []).append(us)
    steps = args.spans * case.samples_per_span
    print(
        f"default case, {args.spans} spans = {steps} steps of {case.dt_s * 1e3:.3f} ms, {args.repeats} repeats, MCAP on"
    )
    print(f"real-time factor: median {statistics.median(rtf):.1f}x (min {min(rtf):.1f}x, max {max(rtf):.1f}x)")
    print(f"wall per step:    median {statistics.median(wall) / steps * 1e6:.1f} us")
    for fmu, values in per_step.items():
        print(f"  {fmu:<11s} set+doStep+get median {statistics.median(values):.1f} us")


if __name__ == "__main__":
    main()
