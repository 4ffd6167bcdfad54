"""A long rig-paced test (default 30 min) against the free-running emulator: the master's resident
memory and the MCAP log, read while the test runs.

Every --every seconds it prints the run process's resident and peak memory (VmRSS, VmHWM from
/proc, the master; the MCAP writer is a child process of its own, reported apart) and what a
follower of the growing run.mcap has read so far (messages per topic, the newest simulated time).
At the end: the summary's link figures, the emulator's session record, and the peak memory.
The run ignores divergence (a soak measures memory and the log, not the iteration). Not a timed test.

    nohup python tests/benchmarks/soak_rig_paced.py [--duration 1800] [--dt 0.002] [--drift-ppm 100]
        [--set SECTION.KEY=VALUE ...] &
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from pantohil.models.case import load_case
from pantohil.orchestrator.mcap_follow import McapFollower


def memory_kb(pid: int) -> dict[str, int]:
    out = {}
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(("VmRSS:", "VmHWM:")):
                key, value = line.split(":")
                out[key] = int(value.split()[0])
    except OSError:
        pass
    return out


def children(pid: int) -> list[int]:
    try:
        return [int(p) for p in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=1800.0, help="test length [s]")
    ap.add_argument("--dt", type=float, default=0.002)
    ap.add_argument("--drift-ppm", type=float, default=100.0)
    ap.add_argument("--every", type=float, default=60.0, help="seconds between reports")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="case changes for the emulator and the run (e.g. rig.delay_steps=0)")
    ap.add_argument("--out", type=Path, help="keep the run folder here (default: a temporary folder)")
    args = ap.parse_args()
    print(f"uptime: {os.popen('uptime').read().strip()}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        out = args.out or tmp / "soak"
        stats = tmp / "emulator.json"
        dt_set = f"run.dt_s={args.dt}"
        sets = [a for kv in args.set for a in ("--set", kv)]
        emu = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "rig-emulator", "--listen",
                                "127.0.0.1:0", "--paced-by", "rig", "--drift-ppm", str(args.drift_ppm), "--stats",
                                str(stats), "--set", dt_set, *sets], stdout=subprocess.PIPE, text=True)
        address = emu.stdout.readline().split("listening on ")[1].split()[0]
        case = load_case(None, [dt_set, *args.set])
        spans = int(args.duration / (case.samples_per_span * case.dt_s)) + 2
        run = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--hardware", address,
                                "--paced-by", "rig", "--out", str(out), "--quiet", "--set", dt_set,
                                "--set", f"run.duration_s={args.duration}", "--set", f"run.max_spans={spans}",
                                "--set", "run.divergence_change=100", "--set", "run.force_limit_N=1e6", *sets,
                                "--set", "run.height_limit_m=100"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        follower, counts, newest_s, peak_kb, writer_peak_kb = None, Counter(), 0.0, 0, 0
        t0 = time.monotonic()
        while True:
            pid, status, usage = os.wait4(run.pid, os.WNOHANG)
            if pid:
                break
            time.sleep(args.every)
            mem = memory_kb(run.pid)
            peak_kb = max(peak_kb, mem.get("VmHWM", 0))
            writer = [memory_kb(c).get("VmHWM", 0) for c in children(run.pid)]
            writer_peak_kb = max([writer_peak_kb, *writer])
            if follower is None and (out / "run.mcap").exists():
                follower = McapFollower(out / "run.mcap")
            if follower is not None:
                for topic, log_ns, _ in follower.poll():
                    counts[topic] += 1
                    newest_s = max(newest_s, log_ns / 1e9)
            print(f"{time.monotonic() - t0:7.0f} s: master RSS {mem.get('VmRSS', 0) / 1024:.0f} MB (peak "
                  f"{mem.get('VmHWM', 0) / 1024:.0f} MB), children peak {writer_peak_kb / 1024:.0f} MB; run.mcap "
                  f"read so far: {dict(counts)}, newest t = {newest_s:.1f} s; load {os.getloadavg()[0]:.1f}",
                  flush=True)
        returncode = os.waitstatus_to_exitcode(status)
        stdout, stderr = run.stdout.read(), run.stderr.read()
        emu.terminate()
        emu.wait()
        if follower is not None:
            for topic, _log_ns, _ in follower.poll():
                counts[topic] += 1
        print(stdout.strip())
        print(stderr.strip()[-2000:])
        summary = json.loads((out / "summary.json").read_text())
        rig = json.loads(stats.read_text())["session_log"][-1]
        print(f"exit {returncode}; {summary['status']} after {summary['spans']} spans; link {summary['link']}")
        print(f"emulator: {rig}")
        print(f"master peak RSS {usage.ru_maxrss / 1024:.0f} MB (getrusage at exit; {peak_kb / 1024:.0f} MB at the "
              f"last sample); MCAP writer peak "
              f"{writer_peak_kb / 1024:.0f} MB; follower read {dict(counts)}, log finished: {follower.finished}")
    print(f"uptime: {os.popen('uptime').read().strip()}", flush=True)


if __name__ == "__main__":
    main()
