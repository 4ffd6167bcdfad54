"""Stability map budget: the step-by-step span maps' construction against its per-step reference; a 20 x 20
map (f_max x contact stiffness, best relaxation at
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


def step_map_builds() -> None:
    """The step-by-step span maps' construction, its updates queued a block of steps at a time (QueuedRankOne),
    against the same construction with a block of one step (the rank-one update of every unit state at every
    step, the reference), one point and the pair at L = 70 m (10 Hz), in this run; medians of 3."""
    from pantohil.models.case import load_case
    from pantohil.models.catenary.receptance import asm_operator
    from pantohil.models.hil.loop import HilSettings
    from pantohil.models.hil.pair_loop import pair_delay_steps, pair_iteration
    from pantohil.models.pantograph.interface import linear_pantograph
    from pantohil.models.stability import maps
    from pantohil.models.stability.pair_map import pair_loop_latency_steps, pair_span_map

    one = load_case(None, [])
    op = maps.circulant_dense(asm_operator(one.catenary, one.speed_m_s, one.samples_per_span, one.dt_s,
                                           one.n_harmonics).kernel)
    pair = load_case(None, ["hil.max_frequency_hz=10", "second_pantograph.spacing_m=70"])
    hil = pair_iteration(pair, pair_delay_steps(pair))
    builds = {
        "one point": lambda: maps.span_map(op, linear_pantograph(one.pantograph, one.dt_s),
                                           HilSettings("step", 0.1, 8), 8),
        "pair, L = 70 m": lambda: pair_span_map(hil, linear_pantograph(pair.pantograph, pair.dt_s),
                                                pair_loop_latency_steps(pair)),
    }
    block = maps.QueuedRankOne.BLOCK
    print("step-by-step span map, construction only (median of 3):")
    for name, build in builds.items():
        medians = {}
        for size in (1, block):
            maps.QueuedRankOne.BLOCK = size
            times = []
            for _ in range(3):
                t = time.perf_counter()
                build()
                times.append(time.perf_counter() - t)
            medians[size] = statistics.median(times)
        maps.QueuedRankOne.BLOCK = block
        print(f"  {name:16s} queued ({block} steps) {medians[block]:6.2f} s, per step (reference) {medians[1]:6.2f} s: "
              f"{medians[1] / medians[block]:.1f}x", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--size", type=int, default=20)
    ap.add_argument("--update", choices=("step", "span", "both"), default="both")
    args = ap.parse_args()
    step_map_builds()
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
