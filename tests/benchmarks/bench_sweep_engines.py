"""Wall time of `pantohil sweep` of models/data/sweeps/speed_200_300.toml (12 virtual HIL runs) in its
ways of running, in one script run, each on 2 workers: the default (in-process points run inside the
Dask workers, no figures per point), the same with each point's figures, and every point as a full
FMU run with its figures in a child process (the sweep before the in-process engine), on a cold and on
a warm FMU cache. Prints the times and their ratios to the FMU runs; not a timed test.

    python tests/benchmarks/bench_sweep_engines.py [--workers 2] [--sweep FILE] [--no-warm] [--repeats 1]
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _sweep(path: Path, out: Path, workers: int, engine: str, point_plots: bool) -> tuple[float, dict]:
    from pantohil.orchestrator.sweep import run_sweep

    t0 = time.perf_counter()
    summary = run_sweep(path, out, workers=workers, progress=False, log=lambda line: None, engine=engine,
                        point_plots=point_plots)
    return time.perf_counter() - t0, summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--sweep", type=Path, default=ROOT / "models" / "data" / "sweeps" / "speed_200_300.toml")
    ap.add_argument("--no-warm", action="store_true", help="skip the FMU sweep on the warm FMU cache")
    ap.add_argument("--repeats", type=int, default=1, help="runs of the in-process arms (medians printed)")
    args = ap.parse_args()
    runs = [("fmu, cold FMU cache, point figures", "fmu", True)]
    if not args.no_warm:
        runs.append(("fmu, warm FMU cache, point figures", "fmu", True))
    runs += [("inprocess, point figures", "inprocess", True), ("inprocess (default)", "inprocess", False)]
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["PANTOHIL_CACHE"] = str(Path(tmp) / "cache")  # a cold cache, the workers' too
        times = {}
        for label, engine, plots in runs:
            for _ in range(1 if engine == "fmu" else args.repeats):
                out = Path(tmp) / "sweep"
                shutil.rmtree(out, ignore_errors=True)
                wall, summary = _sweep(args.sweep, out, args.workers, engine, plots)
                times.setdefault(label, []).append(wall)
                print(f"{label:<36s} {wall:7.1f} s whole sweep ({summary['wall_s']:.1f} s of points) on "
                      f"{summary['workers']} workers: {summary['statuses']}", flush=True)
    median = {label: statistics.median(t) for label, t in times.items()}
    for reference in [r[0] for r in runs if r[1] == "fmu"]:
        for label in [r[0] for r in runs if r[1] == "inprocess"]:
            print(f"{label} is {median[reference] / median[label]:.1f}x faster than {reference}")


if __name__ == "__main__":
    main()
