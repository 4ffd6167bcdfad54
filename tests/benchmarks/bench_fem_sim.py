"""fem-sim budget: a 30-span run of pfem_benchmark_250 in at most 60 s, memory
reported. Prints medians over repeats; not a timed test.

    python tests/benchmarks/bench_fem_sim.py [--repeats 3] [--spans 30]
"""
from __future__ import annotations

import argparse
import statistics
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--spans", type=int, default=30)
    args = ap.parse_args()
    from pantohil.models.case import load_case
    from pantohil.models.catenary.fe.definition import load_definition
    from pantohil.models.catenary.fe.simulation import simulate_section

    case = load_case(ROOT / "models" / "data" / "cases" / "pfem_benchmark_250.toml")
    cat = load_definition(case.definition_path)
    walls, mem = [], []
    for _ in range(args.repeats):
        r = simulate_section(cat, case.pantograph, args.spans, case.speed_m_s, case.dt_s,
                             reference_height_m=case.reference_height_m())
        walls.append(r.wall_s)
        mem.append(r.peak_memory_bytes / 1e6)
    steps = len(r.force_N)
    print(
        f"fem-sim {args.spans} spans ({steps} steps of {case.dt_s * 1e3:.0f} ms): "
        f"median {statistics.median(walls):.1f} s (min {min(walls):.1f}, max {max(walls):.1f}; limit 60 s), "
        f"{statistics.median(walls) / steps * 1e6:.0f} us/step, "
        f"peak memory {max(mem):.0f} MB"
    )


if __name__ == "__main__":
    main()
