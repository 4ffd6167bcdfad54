"""FE window budget: the moving-window FE simulation (models/catenary/fe/window.py) of pfem_benchmark_250 at
least 2x faster than real time over 30 spans, validated against a 60-span section within 1 % RMS of the
std (contact force low-passed at 25 Hz, the stationary span of each). Prints medians, the full 30-span
section's real-time factor measured in the same run, and the accuracy of each window size; not a timed test.

    python tests/benchmarks/bench_fe_window.py [--windows 6:2,8:3,10:4] [--repeats 3] [--spans 30]
"""
from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def stationary_span(force_N: np.ndarray, dt_s: float, steps_per_span: int, spans: range) -> np.ndarray:
    """The 25 Hz low-passed contact force over one span, averaged over `spans` (0-based span indices)."""
    from pantohil.models.metrics import lowpass

    f = lowpass(force_N, dt_s, 25.0)
    return np.mean([f[s * steps_per_span:(s + 1) * steps_per_span] for s in spans], axis=0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", default="6:2,8:3,10:4", help="W:B pairs: spans in the window, spans behind")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--spans", type=int, default=30, help="spans of travel of each window run")
    ap.add_argument("--reference-spans", type=int, default=60)
    ap.add_argument("--reference", type=Path, default=None, help="npz of a 60-span force record to reuse")
    args = ap.parse_args()
    from pantohil.models.case import load_case
    from pantohil.models.catenary.fe.definition import load_definition
    from pantohil.models.catenary.fe.simulation import simulate_section
    from pantohil.models.catenary.fe.window import WindowLayout, simulate_window

    case = load_case(ROOT / "models" / "data" / "cases" / "pfem_benchmark_250.toml")
    cat = load_definition(case.definition_path)
    dt, v, ref_h = case.dt_s, case.speed_m_s, case.reference_height_m()
    per_span = int(round(cat.span_m / (v * dt)))
    if args.reference is not None and args.reference.exists():
        ref_force = np.load(args.reference)["force_N"]
    else:
        r = simulate_section(cat, case.pantograph, args.reference_spans, v, dt, reference_height_m=ref_h)
        ref_force = r.force_N
        print(f"{args.reference_spans}-span section: {r.wall_s:.1f} s, {len(r.force_N) * dt / r.wall_s:.2f}x real time")
        if args.reference is not None:
            np.savez(args.reference, force_N=ref_force)
    centre = args.reference_spans // 2
    ref = stationary_span(ref_force, dt, per_span, range(centre - 3, centre))
    std_ref = ref.std()
    full = simulate_section(cat, case.pantograph, args.spans, v, dt, reference_height_m=ref_h)
    full_rt = len(full.force_N) * dt / full.wall_s
    print(f"full {args.spans}-span section: {full.wall_s:.1f} s, {full_rt:.2f}x real time "
          f"({full.wall_s / len(full.force_N) * 1e6:.0f} us/step)")
    print(f"reference: spans {centre - 2}-{centre} of {args.reference_spans}, std {std_ref:.3f} N at 25 Hz")
    for spec in args.windows.split(","):
        w, b = (int(t) for t in spec.split(":"))
        walls = []
        for _ in range(args.repeats):
            r = simulate_window(cat, case.pantograph, WindowLayout(w, b), args.spans, v, dt,
                                reference_height_m=ref_h)
            walls.append(r.wall_s)
        sim_s = len(r.force_N) * dt
        span = stationary_span(r.force_N, dt, per_span, range(args.spans - 3, args.spans))
        rms = np.sqrt(np.mean((span - ref) ** 2)) / std_ref * 100
        wall = statistics.median(walls)
        print(f"window W={w} B={b}: median {wall:.1f} s (min {min(walls):.1f}, max {max(walls):.1f}) for "
              f"{sim_s:.1f} s simulated: {sim_s / wall:.2f}x real time ({wall / full.wall_s * 100:.0f} % of the full "
              f"section's wall), {wall / len(r.force_N) * 1e6:.0f} us/step; std {span.std():.3f} N "
              f"({(span.std() / std_ref - 1) * 100:+.2f} %), RMS difference {rms:.2f} % of the std", flush=True)


if __name__ == "__main__":
    main()
