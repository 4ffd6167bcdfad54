"""Real-time factor of the default case with the FMU engine (three FMUs in the fmpy master) and the
in-process engine (the same models without the FMI boundary), in the same run, interleaved, MCAP on;
their ratio; the share of the in-process step that logging takes. Prints medians; not a timed test.

    python tests/benchmarks/bench_inprocess.py [--repeats 5] [--spans 30]

The real-time factor is the summary's: simulated time over the wall time of stepping (observers,
logging hand-over and the convergence monitor included; building the FMUs and finishing the MCAP file
after the last step not). The whole call of `run_case` is printed beside it.
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from pantohil.models.case import load_case
from pantohil.orchestrator.hil_run import RunObserver, run_case


class _DropLogging(RunObserver):
    """Switches the run's MCAP logging off: nothing is handed to the writer (the file keeps its channels)."""

    def on_start(self, run) -> None:
        from pantohil.orchestrator.run_observers import McapObserver

        for observer in run.observers:
            if isinstance(observer, McapObserver):
                observer.on_span = lambda run, span, record: None
                observer._log_to = lambda master, stop: None


def _run(case, folder: Path, engine: str, log: bool = True) -> tuple[float, float, float]:
    t0 = time.perf_counter()
    s = run_case(case, folder, progress=False, engine=engine, observers=() if log else (_DropLogging(),))
    return s.timing.realtime_factor, s.timing.wall_s, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--spans", type=int, default=30, help="spans per run (a fixed amount of work)")
    args = ap.parse_args()
    case = load_case(None, [f"run.max_spans={args.spans}", "run.convergence_tol=1e-12"])
    steps = args.spans * case.samples_per_span
    results = {"fmu": [], "inprocess": [], "inprocess, no MCAP": []}
    with tempfile.TemporaryDirectory() as tmp:
        run_case(case, Path(tmp) / "warmup", progress=False)  # builds (and caches) the FMUs
        for i in range(args.repeats):
            results["fmu"].append(_run(case, Path(tmp) / f"fmu{i}", "fmu"))
            results["inprocess"].append(_run(case, Path(tmp) / f"in{i}", "inprocess"))
            results["inprocess, no MCAP"].append(_run(case, Path(tmp) / f"nolog{i}", "inprocess", log=False))
    print(f"default case, {args.spans} spans = {steps} steps of {case.dt_s * 1e3:.3f} ms, {args.repeats} repeats "
          "each, interleaved")
    median = {}
    for name, rows in results.items():
        rtf = [r[0] for r in rows]
        median[name] = statistics.median(rtf)
        print(f"{name:<20s} real-time factor median {median[name]:7.1f}x (min {min(rtf):.1f}x, max {max(rtf):.1f}x); "
              f"wall per step {statistics.median(r[1] for r in rows) / steps * 1e6:6.1f} us; whole run_case "
              f"{statistics.median(r[2] for r in rows):.2f} s")
    print(f"ratio in-process / fmu: {median['inprocess'] / median['fmu']:.1f}x")
    print(f"logging's share of the in-process stepping: "
          f"{1 - median['inprocess'] / median['inprocess, no MCAP']:.0%}")


if __name__ == "__main__":
    main()
