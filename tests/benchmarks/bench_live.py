"""Cost of the live view: the default virtual run without --live, with
--live and one subscribed client that reads everything, and with --live and a client that subscribes
and then stops reading. Runs are interleaved (A B C A B C ...) on a shared machine; prints the median,
min and max of the real-time factor, the wall time per step, the sum of the FMUs' median set+doStep+get
times (measured inside the stepping loop), the CPU time per step of the run's
process while it steps (all its threads: stepping, publishing, the server; summary.json
timing.cpu_s) and its peak resident memory (VmHWM of /proc/PID/status). The client runs in a
session of its own (as a viewer program would), so that the kernel's per-session CPU sharing does
not lend the run its share. Not a timed test.

    python tests/benchmarks/bench_live.py [--repeats 5] [--spans 30]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

ARMS = ("no live", "live + reading client", "live + stalled client")


def client(url: str, stall: bool) -> None:
    """A Foxglove-protocol client: subscribe to every channel, then read until the server closes
    (or, stalled, never read again: the socket and the server's backlog fill up)."""
    import time

    from websockets.sync.client import connect

    with connect(url, subprotocols=["foxglove.sdk.v1"], max_size=None, max_queue=4, ping_interval=None) as ws:
        channels = []
        while not channels:
            msg = json.loads(ws.recv())
            channels = msg.get("channels", []) if msg["op"] == "advertise" else []
        ws.send(json.dumps({"op": "subscribe",
                            "subscriptions": [{"id": i, "channelId": c["id"]} for i, c in enumerate(channels, 1)]}))
        if stall:
            while True:
                time.sleep(3600)  # killed by the benchmark when the run ends
        count = 0
        try:
            for _ in ws:
                count += 1
        except Exception:
            pass
        print(f"client received {count} messages", file=sys.stderr)


def _follow_process(proc: subprocess.Popen, figures: dict) -> None:
    """Follow VmHWM (peak resident set) of the run until it exits."""
    status = Path(f"/proc/{proc.pid}/status")
    while proc.poll() is None:
        try:
            for line in status.read_text().splitlines():
                if line.startswith("VmHWM:"):
                    figures["peak_rss_mb"] = max(figures["peak_rss_mb"], int(line.split()[1]) / 1024)
        except (OSError, ValueError):
            break
        threading.Event().wait(0.05)


def _pinned(cpu: int | None) -> list[str]:
    """taskset prefix: the run (and its MCAP writer) on one CPU, so that no arm gains or loses by where the
    kernel happens to place it (unpinned, the same run steps at 20 or 33 us per catenary call on VM-2)."""
    return [] if cpu is None or shutil.which("taskset") is None else ["taskset", "-c", str(cpu)]


def one_run(arm: int, out: Path, spans: int, cpus: tuple[int | None, int | None] = (None, None)) -> dict | None:
    cmd = [*_pinned(cpus[0]), sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--out", str(out), "--quiet",
           "--set", f"run.max_spans={spans}", "--set", "run.convergence_tol=1e-12"]
    if arm:
        cmd += ["--live", "127.0.0.1:0", "--live-wait"]
    run = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    figures = {"peak_rss_mb": 0.0}
    watcher = threading.Thread(target=_follow_process, args=(run, figures), daemon=True)
    watcher.start()
    viewer = None
    if arm:
        for line in run.stdout:  # wait on the server's line
            if "listening on" in line:
                url = line.split("listening on ")[1].split()[0]
                stall = ["--stall"] if arm == 2 else []
                viewer = subprocess.Popen([*_pinned(cpus[1]), sys.executable, __file__, "--client", url, *stall],
                                          start_new_session=True)
                break
    _, err = run.communicate()
    watcher.join()
    if viewer is not None:
        if arm == 2:
            viewer.kill()
        viewer.wait()
    if run.returncode not in (0, 1):  # counted and left out of the figures
        print(f"{ARMS[arm]}: run failed ({run.returncode}): {err.strip().splitlines()[-1] if err.strip() else ''}",
              file=sys.stderr)
        return None
    s = json.loads((out / "summary.json").read_text())
    steps = s["timing"]["simulated_s"] / s["dt_s"]
    return {"rtf": s["timing"]["realtime_factor"], "us_per_step": s["timing"]["wall_s"] / steps * 1e6,
            "cpu_us_per_step": s["timing"]["cpu_s"] / steps * 1e6,
            "fmu_us_per_step": sum(s["timing"]["per_step_us"].values()), "peak_rss_mb": figures["peak_rss_mb"]}


def _line(name: str, values: list[float], unit: str, fmt: str = ".1f") -> str:
    return (f"  {name:<14s} median {statistics.median(values):{fmt}} {unit} "
            f"(min {min(values):{fmt}}, max {max(values):{fmt}})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--spans", type=int, default=30, help="spans per run (a fixed amount of work)")
    ap.add_argument("--pin", action=argparse.BooleanOptionalAction, default=True,
                    help="run on the last CPU, the client on the first (default: pinned)")
    ap.add_argument("--client", metavar="URL", help=argparse.SUPPRESS)
    ap.add_argument("--stall", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.client:
        client(args.client, args.stall)
        return
    results = {arm: [] for arm in range(len(ARMS))}
    n_cpus = os.cpu_count() or 1
    cpus = (n_cpus - 1, 0) if args.pin and n_cpus > 1 else (None, None)
    with tempfile.TemporaryDirectory() as tmp:
        one_run(0, Path(tmp) / "warmup", 2)  # builds (and caches) the FMUs
        for i in range(args.repeats):
            for arm in results:
                row = one_run(arm, Path(tmp) / f"r{i}-{arm}", args.spans, cpus)
                if row is not None:
                    results[arm].append(row)
    print(f"default case, {args.spans} spans per run, {args.repeats} interleaved repeats per arm; run on CPU "
          f"{cpus[0]}, client on CPU {cpus[1]}; uptime: {os.popen('uptime').read().strip()}")
    keys = {"rtf": ("real time", "x"), "us_per_step": ("wall per step", "us"),
            "cpu_us_per_step": ("CPU per step", "us"), "fmu_us_per_step": ("FMU calls/step", "us")}
    base = {k: statistics.median(r[k] for r in results[0]) for k in keys}
    for arm, name in enumerate(ARMS):
        print(f"{name} ({len(results[arm])} runs):")
        for key, (label, unit) in keys.items():
            values = [r[key] for r in results[arm]]
            print(_line(label, values, unit) + f"  {100 * (statistics.median(values) / base[key] - 1):+.1f} %")
        print(_line("peak RSS", [r["peak_rss_mb"] for r in results[arm]], "MB"))


if __name__ == "__main__":
    main()
