"""Stability map budget: a 20 x 20 map (f_max x contact stiffness, best relaxation at
every point) of the default case within 30 s on 2 Dask workers; how it scales from 1 to 2 Dask workers; and the cost of
one spectral radius by each construction. Prints medians; not a timed test.

    python tests/benchmarks/bench_stability.py [--repeats 1] [--update step] [--size 20]
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def per_radius_costs() -> None:
    from pantohil.models.case import load_case
    from pantohil.models.hil.loop import HilSettings
    from pantohil.models.pantograph.interface import linear_pantograph
    from pantohil.models.catenary.receptance import asm_operator
    from pantohil.models.stability.maps import (circulant_dense, circulant_range_basis, reduced_span_map,
        reduced_span_parts, span_map, step_matrix)
    from pantohil.models.stability.step_roots import step_loop, step_spectral_radius

    c = load_case(None, [])
    op = asm_operator(c.catenary, c.speed_m_s, c.samples_per_span, c.dt_s, c.n_harmonics)
    lin = linear_pantograph(c.pantograph, c.dt_s)
    dense = circulant_dense(op.kernel)
    basis = circulant_range_basis(op.kernel)
    loop = step_loop(op.kernel, lin, 8, 8)
    parts = reduced_span_parts(dense, lin, 8, 8, basis)
    cases = {
        "dense span map, step-by-step": lambda: span_map(dense, lin, HilSettings("step", 0.1, 8), 8).spectral_radius,
        "dense span map, span-by-span": lambda: span_map(dense, lin, HilSettings("span", 0.1, 8), 8).spectral_radius,
        "one-step matrix eigenvalues (step)": lambda: step_matrix(op.kernel, lin, HilSettings("step", 0.1, 8), 8)
        .spectral_radius,
        "characteristic roots (step)": lambda: step_spectral_radius(loop, 0.1),
        "reduced span map (span)": lambda: reduced_span_map(dense, lin, HilSettings("span", 0.1, 8), 8, basis)
        .spectral_radius,
        "reduced span map, one more mu (span)": lambda: parts.at(0.1).spectral_radius,
    }
    print(f"one spectral radius, default case (N = {c.samples_per_span}, 25 Hz, latency 8):")
    for name, fn in cases.items():
        times = []
        for _ in range(3):
            t = time.perf_counter()
            rho = fn()
            times.append(time.perf_counter() - t)
        print(f"  {name:38s} {statistics.median(times) * 1e3:8.1f} ms  (rho {rho:.6f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--size", type=int, default=20)
    ap.add_argument("--update", choices=("step", "span", "both"), default="both")
    args = ap.parse_args()
    per_radius_costs()
    updates = ("step", "span") if args.update == "both" else (args.update,)
    for update in updates:
        for workers in (1, 2):
            walls = []
            for _ in range(args.repeats):
                with tempfile.TemporaryDirectory() as tmp:
                    t = time.perf_counter()
                    subprocess.run([sys.executable, "-m", "pantohil.orchestrator.cli", "stability", "--update", update,
                                    "--fmax", f"2:40:{args.size}", "--contact-stiffness", f"1e4:1e6:{args.size}:log",
                                    "--workers", str(workers), "--out", str(Path(tmp) / "map"), "--quiet"], check=True,
                                   stdout=subprocess.DEVNULL)
                    walls.append(time.perf_counter() - t)
            print(f"{args.size}x{args.size} map, {update}-by-{update}, {workers} worker(s): median "
                  f"{statistics.median(walls):.1f} s (min {min(walls):.1f}, max {max(walls):.1f}; "
                  f"budget 30 s on 2 workers)", flush=True)


if __name__ == "__main__":
    main()
