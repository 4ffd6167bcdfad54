"""Rig-paced runs of the default case against the free-running rig emulator on loopback.

For each drift (and repeat): a fixed-length test (run.duration_s) at dt, driven by the fmpy master or
libcosim, paced by the emulator's clock. Prints per run and as medians (with the spread): samples
sent by the rig, consumed and answered by the model, never answered or answered twice, the rig's
reused-answer count, the answer time p50/p99/max (model side and rig side), the emulator's own tick
lateness, and the rms difference of the converged span from the in-process virtual HIL's, in % of
its std. Notes the machine's load. Not a timed test.

    python tests/benchmarks/bench_rig_paced.py [--dt 0.002] [--drift-ppm 100 -100] [--duration 120]
        [--master fmpy|libcosim] [--repeats 1] [--jitter-us 0] [--set SECTION.KEY=VALUE ...]

`--set` changes the case for the virtual reference, the emulator and the rig-paced run alike (the
default case's virtual HIL diverges at dt = 2 ms with its 4-step rig delay; it converges with
`--set rig.delay_steps=0`).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def cli(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pantohil.orchestrator.cli", *args], capture_output=True, text=True,
                          **kw)


def span_difference(folder: Path, virtual: np.ndarray) -> float:
    f = np.loadtxt(folder / "steady_span.csv", delimiter=",", skiprows=1)[:, 3]
    return float(np.sqrt(np.mean(((f - f.mean()) - (virtual - virtual.mean())) ** 2)) / virtual.std())


def start_emulator(tmp: Path, sets: list[str], drift_ppm: float, jitter_us: float, tag: str):
    stats = tmp / f"emulator-{tag}.json"
    emu = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "rig-emulator", "--listen",
                            "127.0.0.1:0", "--paced-by", "rig", "--drift-ppm", str(drift_ppm), "--jitter-us",
                            str(jitter_us), "--stats", str(stats), *sets],
                           stdout=subprocess.PIPE, text=True)
    address = emu.stdout.readline().split("listening on ")[1].split()[0]
    return emu, address, stats


def one_run(tmp: Path, args, drift_ppm: float, i: int, virtual: np.ndarray, spans: int) -> dict:
    sets = case_sets(args)
    tag = f"{drift_ppm:+g}-{i}"
    emu, address, stats_path = start_emulator(tmp, sets, drift_ppm, args.jitter_us, tag)
    out = tmp / f"run{tag}"
    load_before = os.getloadavg()[0]
    proc = cli("run", "--hardware", address, "--paced-by", "rig", "--master", args.master, "--out", str(out),
               "--quiet", *sets, "--set", f"run.duration_s={args.duration}",
               "--set", f"run.max_spans={spans}")
    load_after = os.getloadavg()[0]
    emu.terminate()
    emu.wait()
    s = json.loads((out / "summary.json").read_text())
    rig = json.loads(stats_path.read_text())["session_log"][-1]
    ln = s["link"]
    row = {
        "exit": proc.returncode,
        "status": s["status"],
        "spans": s["spans"],
        "steps": int(round(s["timing"]["simulated_s"] / s["dt_s"])),
        "rig_samples": rig["samples"],
        "consumed": ln["samples"],
        "answered": ln["answered"],
        "rig_answered": rig["answered"],
        "unanswered": rig["unanswered"],
        "doubled": rig["doubled"],
        "lost": ln["lost"],
        "reused": rig["reused"],
        "reused_pct": 100.0 * rig["reused"] / max(rig["samples"], 1),
        "answer_us": ln["answer_us"],
        "rig_answer_us": rig["answer_us"],
        "tick_late_us": rig["tick_lateness_us"],
        "difference_pct": 100.0 * span_difference(out, virtual) if s["spans"] else float("nan"),
        "load": (load_before, load_after),
        "scheduling": ln.get("scheduling"),
    }
    print(f"drift {drift_ppm:+g} ppm, run {i}: exit {row['exit']}, {row['status']}, {row['spans']} spans "
          f"({row['steps']} steps); rig sent {row['rig_samples']} samples, the model consumed {row['consumed']} and "
          f"answered {row['answered']} (rig received {row['rig_answered']}), never answered {row['unanswered']}, "
          f"doubled {row['doubled']}, lost {row['lost']}; reused {row['reused']} ({row['reused_pct']:.3f} %); answer "
          f"p50/p99/max {ln['answer_us']['p50']:.0f}/{ln['answer_us']['p99']:.0f}/{ln['answer_us']['max']:.0f} us "
          f"(rig side {rig['answer_us']['p50']:.0f}/{rig['answer_us']['p99']:.0f}/{rig['answer_us']['max']:.0f} us), "
          f"rig tick lateness p50/p99/max {rig['tick_lateness_us']['p50']:.0f}/{rig['tick_lateness_us']['p99']:.0f}/"
          f"{rig['tick_lateness_us']['max']:.0f} us; span difference {row['difference_pct']:.3f} % of the virtual "
          f"std; {row['scheduling']}; load {load_before:.1f} -> {load_after:.1f}", flush=True)
    return row


def case_sets(args) -> list[str]:
    return [a for kv in [f"run.dt_s={args.dt}", *args.set] for a in ("--set", kv)]


def spread(values: list[float]) -> str:
    return f"median {statistics.median(values):.3f} (min {min(values):.3f}, max {max(values):.3f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dt", type=float, default=0.002)
    ap.add_argument("--drift-ppm", type=float, nargs="+", default=[100.0, -100.0])
    ap.add_argument("--duration", type=float, default=120.0, help="test length [s] (Paper D: 120 s)")
    ap.add_argument("--master", choices=("fmpy", "libcosim"), default="fmpy")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--jitter-us", type=float, default=0.0)
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = ap.parse_args()
    print(f"uptime: {os.popen('uptime').read().strip()}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        proc = cli("run", "--out", str(tmp / "virtual"), "--quiet", *case_sets(args))
        assert proc.returncode == 0, proc.stdout + proc.stderr
        virtual_summary = json.loads((tmp / "virtual" / "summary.json").read_text())
        virtual = np.loadtxt(tmp / "virtual" / "steady_span.csv", delimiter=",", skiprows=1)[:, 3]
        n = virtual_summary["samples_per_span"]
        spans = int(np.ceil(round(args.duration / virtual_summary["dt_s"]) / n))
        print(f"virtual HIL at dt {virtual_summary['dt_s']:.6g} s: {virtual_summary['status']} after "
              f"{virtual_summary['spans']} spans, std {virtual.std():.3f} N; rig-paced tests of {args.duration:g} s "
              f"({spans} spans) with {args.master}", flush=True)
        rows = [one_run(tmp, args, d, i, virtual, spans) for d in args.drift_ppm for i in range(args.repeats)]
    print(f"over {len(rows)} runs: reused % {spread([r['reused_pct'] for r in rows])}; answer p50 us "
          f"{spread([r['answer_us']['p50'] for r in rows])}; p99 us {spread([r['answer_us']['p99'] for r in rows])}; "
          f"max us {spread([r['answer_us']['max'] for r in rows])}; span difference % "
          f"{spread([r['difference_pct'] for r in rows])}; never answered {sum(r['unanswered'] for r in rows)}, "
          f"doubled {sum(r['doubled'] for r in rows)}, lost {sum(r['lost'] for r in rows)}")
    print(f"uptime: {os.popen('uptime').read().strip()}", flush=True)


if __name__ == "__main__":
    main()
