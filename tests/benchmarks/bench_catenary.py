"""Wall time of `pantohil catenary FILE --out DIR` for the shipped catenary files (budget:
at most 10 s each). Prints medians over repeats of the whole command (process start included)."""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    for name in ("paper_a_stitched", "benchmark_simple"):
        times = []
        for _ in range(args.repeats):
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                proc = subprocess.run([sys.executable, "-m", "pantohil.orchestrator.cli", "catenary",
                                       str(ROOT / "models" / "data" / "catenaries" / f"{name}.toml"), "--out", tmp],
                                      capture_output=True, text=True)
                times.append(time.perf_counter() - t0)
                assert proc.returncode == 0, proc.stderr
        print(
            f"{name:18s} median {statistics.median(times):.2f} s (min {min(times):.2f}, max {max(times):.2f}) "
            f"over {args.repeats}"
        )


if __name__ == "__main__":
    main()
