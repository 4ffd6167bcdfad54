"""PFEM run against a fem-sim section, span by span: how much the FE's own spans differ (its
stationarity), which harmonics carry the difference, and the dropper corrections' largest values and
impulses per FE span. The measurements behind docs/validation.md "Stitched catenaries and Paper D's
HIL tests". Heavy: the section takes minutes (60 spans at 1 ms: about 12 min on a loaded 2-vCPU VM).

    python tests/benchmarks/pfem_fe_spread.py PFEM_RUN_FOLDER FE_CASE.toml --spans 60 --keep fe.npz

FE_CASE is the PFEM run's case, or for a rigid-mass HIL case a copy with a one-mass chain in its
place (fem-sim needs a pantograph in contact): tests/benchmarks/fe_mass_stitched_300_plus160.toml.
`--keep` stores the section's histories and reuses them.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

CUTOFF_HZ = 25.0  # Paper D's digital low-pass


def section(case_file: Path, n_spans: int, keep: Path | None) -> dict:
    """The fem-sim section's force and correction histories (computed, or loaded from `keep`)."""
    if keep is not None and keep.exists():
        return dict(np.load(keep))
    from pantohil.models.case import load_case
    from pantohil.models.catenary.fe.definition import load_definition
    from pantohil.models.catenary.fe.simulation import simulate_section

    case = load_case(case_file)
    cat = load_definition(case.definition_path)
    res = simulate_section(cat, case.pantograph, n_spans, case.speed_m_s, case.dt_s, case.values["pfem"]["droppers"],
                           reference_height_m=case.reference_height_m())
    out = {"force": res.force_N, "corr": res.dropper_correction_N, "n": case.samples_per_span, "dt": case.dt_s,
           "per_span": len(cat.dropper_positions_m)}
    if keep is not None:
        np.savez(keep, **out)
    return out


def force_spread(run: Path, fe: dict, spans: range) -> None:
    """RMS difference of the PFEM span from FE spans and means of spans, and the harmonics' spread."""
    from pantohil.models.metrics import lowpass, lowpass_periodic

    n, dt = int(fe["n"]), float(fe["dt"])
    fp = lowpass_periodic(np.loadtxt(run / "steady_span.csv", delimiter=",", skiprows=1)[:, 3], dt, CUTOFF_HZ)
    ff = lowpass(fe["force"], dt, CUTOFF_HZ)
    blocks = np.stack([ff[j * n - 1:(j + 1) * n - 1] for j in spans])
    first = (len(fe["force"]) // n - 3) // 2  # fem-sim's 3 central spans
    central = np.mean([ff[j * n - 1:(j + 1) * n - 1] for j in range(first, first + 3)], axis=0)
    s = np.std(central)
    pct = lambda x: 100 * float(np.sqrt(np.mean(x ** 2))) / s  # noqa: E731
    print(f"{CUTOFF_HZ:g} Hz: std PFEM {np.std(fp):.2f} N, FE central 3 {s:.2f} N; RMS PFEM - FE central 3 "
          f"{pct(fp - central):.2f} %, PFEM - FE mean of spans {spans.start}-{spans.stop - 1} "
          f"{pct(fp - blocks.mean(0)):.2f} %")
    print("  single FE spans from their central mean: " + " ".join(f"{pct(b - central):.1f}" for b in blocks) + " %")
    P, B = np.fft.rfft(fp) / n, np.fft.rfft(blocks, axis=1) / n
    print("  harmonic, Hz, PFEM amplitude, FE amplitude mean +- std over the spans, phase PFEM - FE [deg]")
    for k in np.argsort(np.abs(P[1:] - B[:, 1:].mean(0)))[::-1][:8] + 1:
        ph = np.degrees(np.angle(P[k] / B[:, k]))
        print(f"  {k:3d} {k / (n * dt):6.2f} {2 * abs(P[k]):7.3f} {2 * abs(B[:, k]).mean():7.3f} +- "
              f"{2 * abs(B[:, k]).std():.3f} {ph.mean():6.2f} +- {ph.std():.2f}")


def correction_spread(run: Path, fe: dict, spans: range) -> None:
    """Each slackening dropper's largest correction and impulse: the PFEM's against every FE span's."""
    n, dt, per = int(fe["n"]), float(fe["dt"]), int(fe["per_span"])
    cp = np.loadtxt(run / "dropper_corrections.csv", delimiter=",", skiprows=1)[:, 1:]
    C = np.stack([fe["corr"][j * n - 1:(j + 1) * n - 1, j * per:(j + 1) * per].astype(float) for j in spans])
    for d in range(per):
        if not cp[:, d].any() and not C[:, :, d].any():
            continue
        peak, imp = C[:, :, d].max(axis=1), C[:, :, d].sum(axis=1) * dt
        steps = np.count_nonzero(C[:, :, d] > 0, axis=1)
        print(f"dropper {d + 1}: PFEM {cp[:, d].max():.0f} N, {cp[:, d].sum() * dt:.2f} N s, "
              f"{np.count_nonzero(cp[:, d] > 0)} steps | FE spans {spans.start}-{spans.stop - 1}: "
              f"{peak.mean():.0f} N [{peak.min():.0f}-{peak.max():.0f}], {imp.mean():.2f} N s "
              f"[{imp.min():.2f}-{imp.max():.2f}], {steps.min()}-{steps.max()} steps")
        print("   largest per FE span: " + " ".join(f"{p:.0f}" for p in peak))


def main() -> None:
    """Command line: see the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("case", type=Path)
    ap.add_argument("--spans", type=int, default=60)
    ap.add_argument("--first", type=int, default=20, help="first FE span of the spread (default 20)")
    ap.add_argument("--count", type=int, default=21, help="FE spans in the spread (default 21)")
    ap.add_argument("--keep", type=Path)
    args = ap.parse_args()
    fe = section(args.case, args.spans, args.keep)
    spans = range(args.first, args.first + args.count)
    force_spread(args.run, fe, spans)
    if (args.run / "dropper_corrections.csv").exists():
        correction_spread(args.run, fe, spans)


if __name__ == "__main__":
    main()
