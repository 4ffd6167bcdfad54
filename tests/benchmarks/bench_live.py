"""Cost of the live view: the default virtual run without --live, with
--live and one subscribed client that reads everything, and with --live and a client that subscribes
and then stops reading. Runs are interleaved (A B C A B C ...) on a shared machine; prints the median,
min and max of the real-time factor, the wall time per step and the run process's peak resident
memory (VmHWM of /proc/PID/status, read while the run ends). Not a timed test.

    python tests/benchmarks/bench_live.py [--repeats 5] [--spans 30]
"""
from __future__ import annotations

import argparse
import json
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

    with connect(url, subprotocols=["foxglove.sdk.v1"], max_size=None, max_queue=4) as ws:
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


def _peak_rss_mb(proc: subprocess.Popen, peak: list) -> None:
    """Follow VmHWM (peak resident set) of the run until it exits."""
    path = Path(f"/proc/{proc.pid}/status")
    while proc.poll() is None:
        try:
            for line in path.read_text().splitlines():
                if line.startswith("VmHWM:"):
                    peak[0] = max(peak[0], int(line.split()[1]) / 1024)
        except OSError:
            break
        threading.Event().wait(0.05)


def one_run(arm: int, out: Path, spans: int) -> dict:
    cmd = [sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--out", str(out), "--quiet",
           "--set", f"run.max_spans={spans}", "--set", "run.convergence_tol=1e-12"]
    if arm:
        cmd += ["--live", "127.0.0.1:0", "--live-wait"]
    run = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    peak = [0.0]
    watcher = threading.Thread(target=_peak_rss_mb, args=(run, peak), daemon=True)
    watcher.start()
    viewer = None
    if arm:
        for line in run.stdout:  # wait on the server's line
            if "listening on" in line:
                url = line.split("listening on ")[1].split()[0]
                viewer = subprocess.Popen(
                    [sys.executable, __file__, "--client", url] + (["--stall"] if arm == 2 else [])
                )
                break
    _, err = run.communicate()
    watcher.join()
    if viewer is not None:
        if arm == 2:
            viewer.kill()
        viewer.wait()
    if run.returncode not in (0, 1):
        raise SystemExit(f"run failed ({run.returncode}): {err.strip().splitlines()[-1] if err.strip() else ''}")
    s = json.loads((out / "summary.json").read_text())
    steps = s["timing"]["simulated_s"] / s["dt_s"]
    return {"rtf": s["timing"]["realtime_factor"], "us_per_step": s["timing"]["wall_s"] / steps * 1e6,
            "peak_rss_mb": peak[0]}


def _line(name: str, values: list[float], unit: str, fmt: str = ".1f") -> str:
    return (f"  {name:<14s} median {statistics.median(values):{fmt}} {unit} "
            f"(min {min(values):{fmt}}, max {max(values):{fmt}})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--spans", type=int, default=30, help="spans per run (a fixed amount of work)")
    ap.add_argument("--client", metavar="URL", help=argparse.SUPPRESS)
    ap.add_argument("--stall", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.client:
        client(args.client, args.stall)
        return
    results = {arm: [] for arm in range(len(ARMS))}
    with tempfile.TemporaryDirectory() as tmp:
        one_run(0, Path(tmp) / "warmup", 2)  # builds (and caches) the FMUs
        for i in range(args.repeats):
            for arm in results:
                results[arm].append(one_run(arm, Path(tmp) / f"r{i}-{arm}", args.spans))
    print(f"default case, {args.spans} spans per run, {args.repeats} interleaved repeats per arm")
    base = {k: statistics.median(r[k] for r in results[0]) for k in ("rtf", "us_per_step")}
    for arm, name in enumerate(ARMS):
        rows = results[arm]
        rtf = [r["rtf"] for r in rows]
        step = [r["us_per_step"] for r in rows]
        print(f"{name}:")
        print(_line("real time", rtf, "x") + f"  {100 * (statistics.median(rtf) / base['rtf'] - 1):+.1f} %")
        print(
            _line("wall per step", step, "us") + f"  {100 * (statistics.median(step) / base['us_per_step'] - 1):+.1f} %"
        )
        print(_line("peak RSS", [r["peak_rss_mb"] for r in rows], "MB"))


if __name__ == "__main__":
    main()
