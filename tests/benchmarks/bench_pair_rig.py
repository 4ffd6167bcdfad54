"""Two pantographs, the first on the rig emulator and the second virtual (issue 33, acceptance 4), with both
pacings of the link: for each position of the virtual one, `pantohil run --hardware` against `pantohil
rig-emulator` (model-paced lockstep, and rig-paced with the horizon), each run's steady force of both
pantographs against the all-virtual pair (the in-process pair loop) as the rms of the difference over the std,
and the run's link counters. The rig-paced emulator ticks every --slow-motion dt of wall time (the rig still
counts dt per tick) so that a loaded machine keeps its deadlines.

    python tests/benchmarks/bench_pair_rig.py [--spacing 90] [--slow-motion 3] [--out DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

import numpy as np


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cli(*args: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", *args], text=True, **kwargs)


def run_on_rig(overrides: list[str], pacing: str, slow_motion: float, out: Path) -> tuple[dict, np.ndarray, float]:
    """One hardware run against a fresh emulator: its summary, steady forces (2, N) and wall time."""
    sets = [a for o in overrides for a in ("--set", o)]
    port = _free_port()
    paced = ["--paced-by", "rig", "--slow-motion", str(slow_motion)] if pacing == "rig" else []
    emulator = _cli("rig-emulator", "--listen", f"127.0.0.1:{port}", *paced, *sets,
                    stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    try:
        assert "listening on" in emulator.stdout.readline()
        t0 = time.perf_counter()
        run = _cli("run", "--hardware", f"127.0.0.1:{port}", *paced[:2], *sets, "--out", str(out), "--quiet",
                   stdout=subprocess.DEVNULL)
        run.wait()
        wall = time.perf_counter() - t0
    finally:
        emulator.terminate()
        emulator.wait()
    table = np.genfromtxt(out / "steady_span.csv", delimiter=",", names=True)
    return json.loads((out / "summary.json").read_text()), np.array([table["f_N"], table["f2_N"]]), wall


def rel_rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(((a - a.mean()) - (b - b.mean())) ** 2)) / b.std())


def main() -> None:
    from pantohil.models.case import load_case
    from pantohil.models.hil.pair_loop import run_pair_loop

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spacing", type=float, default=90.0, help="spacing L [m]")
    ap.add_argument("--slow-motion", type=float, default=3.0, help="rig-paced: wall time per tick [dt]")
    ap.add_argument("--out", type=Path, default=None, help="keep the run folders here")
    args = ap.parse_args()
    print(f"{date.today()} {platform.node()}, load {os.getloadavg()[0]:.1f}; L = {args.spacing:g} m, 10 Hz")
    root = args.out or Path(tempfile.mkdtemp(prefix="pantohil_pair_rig_"))
    for position in ("leading", "trailing"):
        overrides = [f"second_pantograph.spacing_m={args.spacing}", f'second_pantograph.position="{position}"',
                     "hil.max_frequency_hz=10", "link.receive_timeout_s=1.0"]
        virtual = run_pair_loop(load_case(None, overrides))
        print(f"\nthe rig's pantograph {'trailing' if position == 'leading' else 'leading'} the virtual one; "
              f"all-virtual: {virtual.status} after {virtual.spans} spans")
        for pacing in ("model", "rig"):
            summary, forces, wall = run_on_rig(overrides, pacing, args.slow_motion, root / f"{position}_{pacing}")
            errors = [rel_rms(forces[p], virtual.force_N[p]) for p in (0, 1)]
            link = summary.get("link", {})
            print(f"  {pacing}-paced: {summary['status']} after {summary['spans']} spans in {wall:.0f} s; against "
                  f"the all-virtual pair: rig's {100 * errors[0]:.3f} %, virtual {100 * errors[1]:.3f} % of the "
                  f"std; sent {link.get('sent')}, lost {link.get('lost')}, late {link.get('late')}")


if __name__ == "__main__":
    main()
