"""The in-process engine against a reference revision of pantohil, in the same run, interleaved: the default
case's real-time factor with its complete run.mcap and without logging, here and at REV (158d128 by default, the
engine before the compiled block), and their ratios. Prints medians; not a timed test.

    python tests/benchmarks/bench_kernels.py [--reference 158d128] [--repeats 3] [--spans 30]

REV is exported with `git archive` and installed without its dependencies into a virtual environment that sees
this one's packages; each run is a child process of either installation running the same measuring code. The
real-time factor is the summary's (simulated time over the wall time of stepping); the child's whole `run_case`,
which includes building the models and closing run.mcap, is printed beside it.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

CHILD = '''
import json, sys, time
from pathlib import Path
from pantohil.models.case import load_case
from pantohil.orchestrator.hil_run import RunObserver, run_case


class DropLogging(RunObserver):
    def on_start(self, run):
        from pantohil.orchestrator.run_observers import McapObserver
        for observer in run.observers:
            if isinstance(observer, McapObserver):
                observer.on_span = lambda run, span, record: None
                observer._log_to = lambda master, stop: None


spans, folder, log = int(sys.argv[1]), Path(sys.argv[2]), sys.argv[3] == "log"
case = load_case(None, [f"run.max_spans={spans}", "run.convergence_tol=1e-12"])
run_case(case, folder / "warm", progress=False, engine="inprocess")  # compiles or loads what the engine caches
t0 = time.perf_counter()
s = run_case(case, folder / "run", progress=False, engine="inprocess", observers=() if log else (DropLogging(),))
whole = time.perf_counter() - t0
assert (folder / "run" / "run.mcap").stat().st_size > 0
print(json.dumps({"rtf": s.timing.realtime_factor, "wall_s": s.timing.wall_s, "whole_s": whole,
                  "steps": s.spans * case.samples_per_span}))
'''


def install_reference(rev: str, where: Path) -> Path:
    """A virtual environment (seeing this one's packages) with pantohil at `rev` installed; its python."""
    src = where / "src"
    src.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(src)], input=archive, check=True)
    venv = where / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True)
    python = venv / "bin" / "python"
    subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", str(src)],
                   check=True)
    return python


def measure(python: Path, spans: int, folder: Path, log: bool, cwd: Path) -> dict:
    """One child run (its own process and run folder)."""
    out = subprocess.run([str(python), "-c", CHILD, str(spans), str(folder), "log" if log else "nolog"],
                         check=True, capture_output=True, text=True, cwd=cwd)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", default="158d128", help="the revision to compare with")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--spans", type=int, default=30, help="spans per run (a fixed amount of work)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="pantohil_bench_kernels_") as tmp:
        tmp = Path(tmp)
        ref_python = install_reference(args.reference, tmp / "reference")
        here = [(f"this tree, {'MCAP' if log else 'no log'}", Path(sys.executable), log) for log in (True, False)]
        there = [(f"{args.reference}, {'MCAP' if log else 'no log'}", ref_python, log) for log in (True, False)]
        results: dict[str, list[dict]] = {name: [] for name, _, _ in here + there}
        for i in range(args.repeats):
            for name, python, log in here + there:
                folder = tmp / f"{i}_{len(results[name])}_{name.replace(' ', '_').replace(',', '')}"
                results[name].append(measure(python, args.spans, folder, log, tmp))
    steps = results[here[0][0]][0]["steps"]
    print(f"default case, {args.spans} spans = {steps} steps, {args.repeats} repeats each, interleaved")
    median = {}
    for name, rows in results.items():
        rtf = [r["rtf"] for r in rows]
        median[name] = statistics.median(rtf)
        print(f"{name:<24s} real-time factor median {median[name]:8.1f}x (min {min(rtf):.1f}x, max {max(rtf):.1f}x); "
              f"{statistics.median(r['wall_s'] for r in rows) / steps * 1e6:6.2f} us per step; whole run_case "
              f"{statistics.median(r['whole_s'] for r in rows):.2f} s")
    for log in ("MCAP", "no log"):
        ratio = median[f"this tree, {log}"] / median[f"{args.reference}, {log}"]
        print(f"ratio this tree / {args.reference}, {log}: {ratio:.1f}x")


if __name__ == "__main__":
    main()
