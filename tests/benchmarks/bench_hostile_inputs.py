"""Time and memory of each hostile-input refusal (tests/system/test_hostile_inputs.py): every case runs as
`pantohil ...` in a child process limited to 1 GB of address space; prints the median and the largest
wall time, the CPU time (user + system, which a busy machine does not inflate) and the peak resident set
size of the children, and the slowest cases.

    .venv/bin/python tests/benchmarks/bench_hostile_inputs.py
"""
from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "system"))
from test_hostile_inputs import CASES, _limit_memory, prepare  # noqa: E402


def measure(hostile) -> tuple[float, float, int, float]:
    """(wall seconds, peak RSS in MiB, exit code, CPU seconds) of one refusal."""
    with tempfile.TemporaryDirectory() as tmp:
        argv = prepare(hostile, Path(tmp))
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", *argv], cwd=tmp,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, preexec_fn=_limit_memory)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        return wall, usage.ru_maxrss / 1024, proc.returncode, usage.ru_utime + usage.ru_stime


def main() -> int:
    rows = []
    for h in CASES:
        wall, rss, code, cpu = measure(h)
        rows.append((wall, rss, code, h.name, cpu))
    walls = [r[0] for r in rows]
    cpus = [r[4] for r in rows]
    print(f"{len(rows)} hostile inputs, load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    print(f"refusal time: median {statistics.median(walls):.2f} s, max {max(walls):.2f} s "
          f"(spread p10-p90 {statistics.quantiles(walls, n=10)[0]:.2f}-{statistics.quantiles(walls, n=10)[-1]:.2f} s)")
    print(f"CPU time: median {statistics.median(cpus):.2f} s, max {max(cpus):.2f} s")
    print(f"peak RSS: median {statistics.median(r[1] for r in rows):.0f} MiB, max {max(r[1] for r in rows):.0f} MiB")
    print("slowest: " + ", ".join(f"{n} {w:.2f} s" for w, _, _, n, _ in sorted(rows, reverse=True)[:5]))
    wrong = [n for _, _, c, n, _ in rows if c != 2]
    if wrong:
        print(f"not exit 2: {', '.join(wrong)}")
    return 1 if wrong else 0


if __name__ == "__main__":
    sys.exit(main())
