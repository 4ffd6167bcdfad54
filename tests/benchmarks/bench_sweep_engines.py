"""Wall time of a sweep with each engine, in one script run: `pantohil sweep` of
models/data/sweeps/speed_200_300.toml (12 virtual HIL runs) with FMU runs on a cold FMU cache, again
on the warm cache (every point's FMUs built), and with in-process runs (the default). Prints the
times and the ratios; not a timed test.

    python tests/benchmarks/bench_sweep_engines.py [--workers 2] [--sweep FILE] [--no-warm]
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _sweep(path: Path, out: Path, workers: int, engine: str) -> tuple[float, dict]:
    from pantohil.orchestrator.sweep import run_sweep

    t0 = time.perf_counter()
    summary = run_sweep(path, out, workers=workers, progress=False, log=lambda line: None, engine=engine)
    return time.perf_counter() - t0, summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--sweep", type=Path, default=ROOT / "models" / "data" / "sweeps" / "speed_200_300.toml")
    ap.add_argument("--no-warm", action="store_true", help="skip the second FMU sweep (on the warm FMU cache)")
    args = ap.parse_args()
    runs = [("inprocess", "inprocess"), ("fmu, cold FMU cache", "fmu")]
    if not args.no_warm:
        runs.append(("fmu, warm FMU cache", "fmu"))
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["PANTOHIL_CACHE"] = str(Path(tmp) / "cache")  # a cold cache, the workers' too
        times = {}
        for label, engine in runs:
            wall, summary = _sweep(args.sweep, Path(tmp) / label.replace(" ", "_").replace(",", ""), args.workers,
                                   engine)
            times[label] = wall
            print(f"{label:<22s} {wall:7.1f} s whole sweep ({summary['wall_s']:.1f} s of points) on "
                  f"{summary['workers']} workers: {summary['statuses']}", flush=True)
    for label in [r[0] for r in runs if r[1] == "fmu"]:
        print(f"in-process is {times[label] / times['inprocess']:.1f}x faster than {label}")


if __name__ == "__main__":
    main()
