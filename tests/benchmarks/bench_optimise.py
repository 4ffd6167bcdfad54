"""Issue 34 acceptance 1-3 measured: `pantohil optimise` of Paper A's stitched catenary at 300 km/h (3-mass
pantograph, case pfem_stitched_250) over the heights and over the spacing, each from a fresh folder: its time,
the designs it evaluated, and the reduction of the PFEM steady state's std against Paper D Table 2's (11.24 %
for OC1, 21.87 % for OC2), with the max and min; then, with --spans, `pantohil fem-sim` of the nominal and of
each optimised design over that many spans, whose std (central spans, 20 Hz) is compared with the PFEM's and
whose reduction with the PFEM's reduction. Prints the figures; not a timed test.

    python tests/benchmarks/bench_optimise.py [--vary heights spacing] [--spans 60] [--out DIR]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from pantohil.models.case import load_case
from pantohil.models.catenary.design import DesignLimits
from pantohil.models.data import catalog
from pantohil.orchestrator.fem_sim import run_fem_sim
from pantohil.orchestrator.optimise import OptimiseRequest
from pantohil.orchestrator.optimise_run import run_optimise

PAPER_D_TABLE_2 = {"heights": 11.24, "spacing": 21.87}  # std reduction [%] of OC1 and OC2 on the rig
CASE = ("pfem_stitched_250", ["run.speed_kmh=300"])


def optimise(vary: str, out: Path, max_designs: int) -> dict:
    """One optimisation from scratch, timed."""
    request = OptimiseRequest(catalog.resolve("paper_a_stitched", "catenary"), catalog.resolve(CASE[0], "case"),
                              tuple(CASE[1]), vary, (), (), DesignLimits(), max_designs)
    t0 = time.perf_counter()
    s = run_optimise(request, out, progress=False, log=lambda line: None)
    s["measured_wall_s"] = time.perf_counter() - t0
    return s


def fem_std(case, spans: int, out: Path) -> float:
    """The 20 Hz std of the central spans of an n-span fem-sim."""
    return run_fem_sim(case, spans, out, progress=False)["contact_force"]["std_N"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vary", nargs="+", default=["heights", "spacing"], choices=sorted(PAPER_D_TABLE_2))
    ap.add_argument("--max-designs", type=int, default=200)
    ap.add_argument("--spans", type=int, default=0, help="fem-sim spans (0: no fem-sim)")
    ap.add_argument("--out", type=Path, default=None, help="keep the folders here")
    args = ap.parse_args()
    root = args.out or Path(tempfile.mkdtemp(prefix="bench_optimise_"))
    results = {v: optimise(v, root / v, args.max_designs) for v in args.vary}
    print("Paper A stitched catenary, 3-mass pantograph, 300 km/h, PFEM steady state 0-20 Hz")
    for v, s in results.items():
        sp = s["speeds"][0]
        print(f"{v:8s}: std {sp['nominal']['std_N']:.2f} -> {sp['optimised']['std_N']:.2f} N "
              f"({sp['std_reduction_percent']:.2f} % lower; Paper D {PAPER_D_TABLE_2[v]:.2f} %), max "
              f"{sp['nominal']['max_N']:.1f} -> {sp['optimised']['max_N']:.1f} N, min {sp['nominal']['min_N']:.1f} -> "
              f"{sp['optimised']['min_N']:.1f} N; {s['designs']['in_journal']} designs in "
              f"{s['measured_wall_s']:.0f} s on {s['workers']} workers ({s['stopped']})")
        c = s["nonlinear_confirmation"]
        print(f"{'':8s}  virtual HIL with dropper slackening: std {c['nominal']['std_N']:.2f} -> "
              f"{c['optimised']['std_N']:.2f} N ({c['std_reduction_percent']:.2f} % lower)")
    if args.spans:
        nominal = fem_std(load_case(catalog.resolve(CASE[0], "case"), CASE[1]), args.spans, root / "fem_nominal")
        print(f"fem-sim, {args.spans} spans, central spans at 20 Hz: nominal std {nominal:.2f} N")
        for v, s in results.items():
            sp = s["speeds"][0]
            fem = fem_std(load_case(root / v / "optimised_case.toml"), args.spans, root / f"fem_{v}")
            pfem, pfem_red = sp["optimised"]["std_N"], sp["std_reduction_percent"]
            fem_red = 100 * (1 - fem / nominal)
            print(f"{v:8s}: fem-sim std {fem:.2f} N against the PFEM's {pfem:.2f} N ({100 * (fem / pfem - 1):+.2f} %); "
                  f"reduction {fem_red:.2f} % against the PFEM's {pfem_red:.2f} % ({fem_red - pfem_red:+.2f} points)")
            c = s["nonlinear_confirmation"]
            hil, hil_red = c["optimised"]["std_N"], c["std_reduction_percent"]
            print(f"{'':8s}  against the PFEM HIL with dropper slackening: std {hil:.2f} N "
                  f"({100 * (fem / hil - 1):+.2f} %), reduction {hil_red:.2f} % ({fem_red - hil_red:+.2f} points)")
    print(f"folders in {root}")


if __name__ == "__main__":
    main()
