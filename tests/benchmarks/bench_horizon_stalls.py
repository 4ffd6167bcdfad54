"""Rig-paced tests whose master is stopped now and then: the horizon keeps the result (issue: a rig test
whose result does not depend on how promptly the model computer answers; docs/udp-protocol.md).

Runs the in-process virtual HIL of the case (the reference), then rig-paced fixed-length tests against
the free-running emulator: one without stalls and, per repeat, one whose master process this script
stops (SIGSTOP/SIGCONT, seeded) for --stall-ms LO HI every --every-s LO HI, and optionally one with a
single long stall (--long-stall-s, e.g. 3 H dt). Prints per run the stalls made (count, longest), the
rig's tick counts up to the model's last sample (fresh, predicted, uncovered; the ticks after the
last answer, while the master closes, are counted apart), the answer time p50/p99/max, and the rms difference
of the converged span from the no-stall run's and from the virtual HIL's, in % of the std. Notes the
machine's load. Not a timed test.

    python tests/benchmarks/bench_horizon_stalls.py [--dt 0.002] [--drift-ppm 100] [--duration 120]
        [--stall-ms 10 40] [--every-s 0.5 2] [--long-stall-s 0.3] [--master fmpy|libcosim]
        [--repeats 1] [--seed 1] [--set SECTION.KEY=VALUE ...] [--keep DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_rig_paced import case_sets, cli, start_emulator  # noqa: E402

TICKS = ("fresh", "predicted", "uncovered")  # the rig's counts in its last SAMPLE the model took


def rms_pct(f: np.ndarray, ref: np.ndarray) -> float:
    """rms of the difference of two spans (their means removed), in % of the reference's std."""
    return float(100 * np.sqrt(np.mean(((f - f.mean()) - (ref - ref.mean())) ** 2)) / ref.std())


def span(folder: Path) -> np.ndarray:
    return np.loadtxt(folder / "steady_span.csv", delimiter=",", skiprows=1)[:, 3]


class Staller(threading.Thread):
    """Stops a process for a random time in [lo, hi] s every [every_lo, every_hi] s (seeded), or once for
    `long_s` after `long_at_s`; records every stall's measured length."""

    def __init__(self, pid: int, stall_s: tuple, every_s: tuple, seed: int, long_s: float = 0.0,
                 long_at_s: float = 20.0):
        super().__init__(daemon=True)
        self.pid, self.stall_s, self.every_s, self.long_s, self.long_at_s = pid, stall_s, every_s, long_s, long_at_s
        self.rng = random.Random(seed)
        self.done = threading.Event()
        self.stalls: list[float] = []

    def _stall(self, seconds: float) -> None:
        t0 = time.perf_counter()
        os.kill(self.pid, signal.SIGSTOP)
        try:
            time.sleep(seconds)
        finally:
            os.kill(self.pid, signal.SIGCONT)
        self.stalls.append(time.perf_counter() - t0)

    def run(self) -> None:
        try:
            if self.long_s:
                if not self.done.wait(self.long_at_s):
                    self._stall(self.long_s)
                return
            while not self.done.wait(self.rng.uniform(*self.every_s)):
                self._stall(self.rng.uniform(*self.stall_s))
        except ProcessLookupError:
            pass


def one_run(tmp: Path, args, tag: str, spans: int, stall: dict | None) -> dict:
    sets = case_sets(args)
    emu, address, stats_path = start_emulator(tmp, sets, args.drift_ppm, 0.0, tag)
    out = tmp / f"run-{tag}"
    load_before = os.getloadavg()[0]
    proc = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--hardware", address,
                             "--paced-by", "rig", "--master", args.master, "--out", str(out), "--quiet", *sets,
                             "--set", f"run.duration_s={args.duration}", "--set", f"run.max_spans={spans}"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    staller = Staller(proc.pid, **stall) if stall else None
    if staller:
        staller.start()
    stdout, stderr = proc.communicate()
    if staller:
        staller.done.set()
        staller.join()
    load_after = os.getloadavg()[0]
    emu.terminate()
    emu.wait()
    summary = json.loads((out / "summary.json").read_text())
    rig = json.loads(stats_path.read_text())["session_log"][-1]
    return {"tag": tag, "exit": proc.returncode, "status": summary["status"], "spans": summary["spans"],
            "message": summary.get("message", ""), "stderr": stderr.strip()[-300:],
            "stalls": staller.stalls if staller else [], **{c: summary["link"][c] for c in TICKS},
            "samples": summary["link"]["samples"], "after_last_answer": rig["after_last_answer"],
            "rig_uncovered": rig["uncovered"], "answer_us": summary["link"]["answer_us"],
            "span": span(out) if summary["spans"] else None, "load": (load_before, load_after),
            "horizon_steps": rig["horizon_steps"]}


def report(row: dict, reference: np.ndarray | None, virtual: np.ndarray) -> None:
    a, stalls = row["answer_us"], row["stalls"]
    vs_ref = rms_pct(row["span"], reference) if reference is not None and row["span"] is not None else float("nan")
    vs_virtual = rms_pct(row["span"], virtual) if row["span"] is not None else float("nan")
    print(f"{row['tag']}: exit {row['exit']}, {row['status']}, {row['spans']} spans; H = {row['horizon_steps']}; "
          f"{len(stalls)} stalls (longest {1e3 * max(stalls, default=0):.1f} ms); rig ticks up to the model's "
          f"last sample {row['samples']}: fresh {row['fresh']}, predicted {row['predicted']}, uncovered "
          f"{row['uncovered']} (the rig ticked {row['after_last_answer']} more after the last answer, "
          f"{row['rig_uncovered'] - row['uncovered']} of them uncovered); answer p50/p99/max "
          f"{a['p50']:.0f}/{a['p99']:.0f}/{a['max']:.0f} us; converged span vs no-stall run {vs_ref:.4f} %, vs "
          f"virtual HIL {vs_virtual:.4f} % of the std; load {row['load'][0]:.1f} -> {row['load'][1]:.1f}"
          + (f"; {row['message']}; stderr: {row['stderr']}" if row["exit"] not in (0,) else ""), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dt", type=float, default=0.002)
    ap.add_argument("--drift-ppm", type=float, default=100.0)
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--stall-ms", type=float, nargs=2, default=[10.0, 40.0])
    ap.add_argument("--every-s", type=float, nargs=2, default=[0.5, 2.0])
    ap.add_argument("--long-stall-s", type=float, default=0.0, help="also one run with one stall this long")
    ap.add_argument("--master", choices=("fmpy", "libcosim"), default="fmpy")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    ap.add_argument("--keep", metavar="DIR", help="keep the run folders and the emulator's records in DIR")
    args = ap.parse_args()
    args.jitter_us = 0.0
    print(f"uptime: {os.popen('uptime').read().strip()}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(args.keep) if args.keep else Path(tmp)
        proc = cli("run", "--engine", "inprocess", "--out", str(tmp / "virtual"), "--quiet", *case_sets(args),
                   "--set", f"run.duration_s={args.duration}")
        assert proc.returncode == 0, proc.stdout + proc.stderr
        vs = json.loads((tmp / "virtual" / "summary.json").read_text())
        virtual = span(tmp / "virtual")
        spans = int(np.ceil(round(args.duration / vs["dt_s"]) / vs["samples_per_span"]))
        print(f"virtual HIL (in-process) at dt {vs['dt_s']:.6g} s: {vs['status']} after {vs['spans']} spans, std "
              f"{virtual.std():.3f} N; rig-paced tests of {args.duration:g} s ({spans} spans), {args.master}, drift "
              f"{args.drift_ppm:+g} ppm", flush=True)
        calm = one_run(tmp, args, "no-stall", spans, None)
        report(calm, None, virtual)
        stall = {"stall_s": tuple(x / 1e3 for x in args.stall_ms), "every_s": tuple(args.every_s)}
        for i in range(args.repeats):
            row = one_run(tmp, args, f"stalls-{i}", spans, {**stall, "seed": args.seed + i})
            report(row, calm["span"], virtual)
        if args.long_stall_s:
            row = one_run(tmp, args, "long-stall", spans, {"stall_s": (0, 0), "every_s": (1, 1), "seed": 0,
                                                           "long_s": args.long_stall_s})
            report(row, calm["span"], virtual)
    print(f"uptime: {os.popen('uptime').read().strip()}", flush=True)


if __name__ == "__main__":
    main()
