"""Real-time runs of the default case through the adapter FMU and the rig emulator on loopback.
Prints, per run and as medians: deadline misses, lateness percentiles, link
counters and the difference from the in-process virtual HIL. Not a timed test.

    python tests/benchmarks/bench_hardware_realtime.py [--repeats 3] [--spans N]
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def cli(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pantohil.orchestrator.cli", *args], capture_output=True, text=True, **kw
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--spans", type=int, default=None, help="fixed spans per run (default: run to convergence)")
    args = ap.parse_args()
    extra = ["--set", f"run.max_spans={args.spans}", "--set", "run.convergence_tol=1e-12"] if args.spans else []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        assert cli("run", "--out", str(tmp / "virtual"), "--quiet").returncode == 0
        virtual = np.loadtxt(tmp / "virtual" / "steady_span.csv", delimiter=",", skiprows=1)[:, 3]
        rows = []
        for i in range(args.repeats):
            emu = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "rig-emulator", "--listen",
                                    "127.0.0.1:0"], stdout=subprocess.PIPE, text=True)
            address = emu.stdout.readline().split("listening on ")[1].split()[0]
            out = tmp / f"rt{i}"
            proc = cli("run", "--hardware", address, "--realtime", "--out", str(out), "--quiet", *extra)
            emu.terminate()
            emu.wait()
            s = json.loads((out / "summary.json").read_text())
            f = np.loadtxt(out / "steady_span.csv", delimiter=",", skiprows=1)[:, 3]
            diff = float(np.sqrt(np.mean(((f - f.mean()) - (virtual - virtual.mean())) ** 2)) / virtual.std())
            rt, ln = s["realtime"], s["link"]
            rows.append((rt["deadline_miss_pct"], rt["lateness_us"]["p50"], rt["lateness_us"]["p99"],
                         rt["lateness_us"]["max"], diff))
            print(f"run {i}: exit {proc.returncode}, {s['status']} after {s['spans']} spans, {rt['steps']} steps, "
                  f"{rt['deadline_misses']} misses ({rt['deadline_miss_pct']:.3f} %), lateness p50 "
                  f"{rt['lateness_us']['p50']:.0f} us p99 {rt['lateness_us']['p99']:.0f} us max "
                  f"{rt['lateness_us']['max']:.0f} us, {rt['scheduling']}; lost {ln['lost']}, late {ln['late']}; "
                  f"rms difference from the virtual HIL {100 * diff:.3f} % of its std", flush=True)
        med = [statistics.median(c) for c in zip(*rows, strict=False)]
        print(f"median over {args.repeats}: misses {med[0]:.3f} %, lateness p50 {med[1]:.0f} us, p99 {med[2]:.0f} us, "
              f"max {med[3]:.0f} us, difference {100 * med[4]:.3f} %")


if __name__ == "__main__":
    main()
