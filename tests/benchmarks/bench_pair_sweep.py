"""Two pantographs, a sweep of their spacing L (Paper A Fig. 17): at each L the in-process virtual HIL of the
pair (models/hil/pair_loop.py, the second trailing, harmonics up to 10 Hz) against the closed form of Paper A
eqs. (24)-(25); the local minima of the trailing pantograph's std against the optimal spacings of eq. (45) of
the dominant harmonics of z0. Prints, per speed, the largest difference of the trailing std from the closed
form and each minimum's distance to the nearest eq. (45) spacing; draws the figure into --out.

    python tests/benchmarks/bench_pair_sweep.py [--speeds 250 300] [--from 20 --to 250 --step 5] [--out DIR]
"""
from __future__ import annotations

import argparse
import platform
import time
from datetime import date
from pathlib import Path

import numpy as np

DOMINANT = 3  # harmonics of z0 whose eq. (45) spacings the minima are compared with


def local_minima(x: np.ndarray, y: np.ndarray) -> list[float]:
    """The x of every interior sample below both neighbours."""
    return [float(x[i]) for i in range(1, len(y) - 1) if y[i] < y[i - 1] and y[i] < y[i + 1]]


def sweep(speed_kmh: float, spacings_m: np.ndarray, overrides: list[str]) -> dict:
    """The HIL's and the closed form's std of both pantographs at each spacing, and eq. (45)'s spacings."""
    from pantohil.models.case import load_case
    from pantohil.models.catenary.asm.closed_form import one_sided_harmonics, optimal_spacings, two_pantographs
    from pantohil.models.hil.pair_loop import run_pair_loop
    from pantohil.models.progress import progress

    rows = []
    bar = progress(len(spacings_m), f"{speed_kmh:g} km/h", "spacing")
    for L in spacings_m:
        case = load_case(None, ["hil.max_frequency_hz=10", f"run.speed_kmh={speed_kmh}", "run.max_spans=600",
                                f"second_pantograph.spacing_m={L}", *overrides])
        t0 = time.perf_counter()
        result = run_pair_loop(case)
        lead, trail = two_pantographs(case.catenary, case.pantograph, case.speed_m_s, case.span_m,
                                      one_sided_harmonics(case.z0_samples()), case.pantograph.uplift_force_N,
                                      case.n_harmonics, float(L))
        rows.append({"L": float(L), "status": result.status, "spans": result.spans,
                     "hil_first": float(result.force_N[0].std()), "hil_trailing": float(result.force_N[1].std()),
                     "cf_first": lead.std_N(), "cf_trailing": trail.std_N(), "s": time.perf_counter() - t0})
        bar.update(1)
    bar.close()
    amplitudes = np.abs(one_sided_harmonics(case.z0_samples())[1:case.n_harmonics])
    dominant = [int(h) + 1 for h in np.argsort(amplitudes)[::-1][:DOMINANT]]
    eq45 = {h: optimal_spacings(case.catenary, case.pantograph, case.speed_m_s,
                                2 * np.pi * h * case.speed_m_s / case.span_m, float(spacings_m[-1]) + 1.0)
            for h in dominant}
    return {"rows": rows, "eq45": eq45}


def report(speed_kmh: float, result: dict, step_m: float) -> None:
    rows = result["rows"]
    L = np.array([r["L"] for r in rows])
    hil = np.array([r["hil_trailing"] for r in rows])
    cf = np.array([r["cf_trailing"] for r in rows])
    err = np.abs(hil - cf) / cf
    unconverged = [r["L"] for r in rows if r["status"] != "converged"]
    print(f"\n{speed_kmh:g} km/h: {len(rows)} spacings {L[0]:g}-{L[-1]:g} m, step {step_m:g} m; "
          f"median {np.median([r['s'] for r in rows]):.1f} s a point")
    print(f"  not converged: {unconverged or 'none'}")
    print(f"  trailing std, HIL against the closed form: largest difference {100 * err.max():.3f} % "
          f"(at L = {L[np.argmax(err)]:g} m), median {100 * np.median(err):.3f} %")
    spacings = sorted((s, h) for h, ss in result["eq45"].items() for s in ss)
    far = 0
    for m in local_minima(L, hil):
        s, h = min(spacings, key=lambda sh: abs(sh[0] - m))
        within = abs(s - m) <= step_m
        far += not within
        print(f"  minimum at L = {m:6.1f} m: eq. (45) harmonic {h} at {s:6.1f} m "
              f"({'within one step' if within else 'NOT within one step'})")
    print(f"  minima not within one step of an eq. (45) spacing of harmonics "
          f"{', '.join(map(str, result['eq45']))}: {far}")


def plot(out: Path, results: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    for speed, result in results.items():
        rows = result["rows"]
        L = [r["L"] for r in rows]
        line, = ax.plot(L, [r["cf_trailing"] for r in rows], label=f"{speed:g} km/h, closed form")
        ax.plot(L, [r["hil_trailing"] for r in rows], "o", ms=3, color=line.get_color(), label=f"{speed:g} km/h, HIL")
    ax.set_xlabel("spacing L [m]")
    ax.set_ylabel("trailing pantograph's std [N]")
    ax.set_title(f"Trailing pantograph against spacing (Paper A Fig. 17), harmonics <= 10 Hz; "
                 f"{date.today()} {platform.node()}", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "pair_sweep.png", dpi=120, bbox_inches="tight")
    print(f"\nfigure: {out / 'pair_sweep.png'}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speeds", type=float, nargs="+", default=[250.0, 300.0], help="speeds [km/h]")
    ap.add_argument("--from", dest="first", type=float, default=20.0, help="first spacing [m]")
    ap.add_argument("--to", dest="last", type=float, default=250.0, help="last spacing [m]")
    ap.add_argument("--step", type=float, default=5.0, help="spacing step [m]")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="a case override for every point (repeatable), e.g. hil.update=span")
    ap.add_argument("--out", type=Path, default=None, help="folder for pair_sweep.png")
    args = ap.parse_args()
    spacings = np.arange(args.first, args.last + args.step / 2, args.step)
    results = {speed: sweep(speed, spacings, args.overrides) for speed in args.speeds}
    for speed, result in results.items():
        report(speed, result, args.step)
    if args.out is not None:
        plot(args.out, results)


if __name__ == "__main__":
    main()
