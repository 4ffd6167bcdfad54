"""`pantohil catenary FILE --out DIR`: form-finding, stiffness map and ASM fit of a catenary file, as
catenary.json, profile.csv, stiffness.csv, droppers.csv, geometry.png and stiffness.png."""
from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from pantohil.models.catenary.fe.analysis import CatenaryAnalysis, analyse  # noqa: E402
from pantohil.models.catenary.fe.definition import load_definition  # noqa: E402
from pantohil.models.catenary.fe.model import form_find  # noqa: E402
from pantohil.models.storage import atomic_path, write_text_atomic

from .output_paths import atomic_output_folder  # noqa: E402
from .report import save_figure  # noqa: E402


def _write_csv(path: Path, header: list[str], rows) -> None:
    with atomic_path(path) as part, part.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)


def _geometry_plot(path: Path, cat, ff) -> None:
    """One span of wires and droppers, heights exaggerated (Paper D Fig. 8 style)."""
    sec, L, mid = ff.section, cat.span_m, ff.section.n_spans // 2
    sel = (sec.x >= mid * L - 1e-9) & (sec.x <= (mid + 1) * L + 1e-9)
    x = sec.x[sel] - mid * L
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(x, ff.heights[sec.cw_w[sel]], color="tab:red", lw=1.5, label="contact wire")
    ax.plot(x, ff.heights[sec.mw_w[sel]], color="tab:blue", lw=1.5, label="messenger wire")
    for xs, wd in zip(sec.stitch_x, sec.stitch_w, strict=False):
        xl = xs - mid * L
        keep = (xl >= -1e-9) & (xl <= L + 1e-9)
        if keep.any():
            ax.plot(xl[keep], ff.heights[wd[keep]], color="tab:green", lw=1.2, label="stitch wire")
    for xd, cw, up, _ in sec.droppers:
        if mid * L < xd < (mid + 1) * L:
            ax.plot([xd - mid * L] * 2, [ff.heights[cw], ff.heights[up]], color="0.4", lw=0.8)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("height above the contact wire at the supports [m]")
    ax.set_title(f"{cat.name}: one span (droppers grey)")
    handles, labels = ax.get_legend_handles_labels()
    ax.legend(
        dict(zip(labels, handles, strict=False)).values(), dict(zip(labels, handles, strict=False)).keys(), fontsize=8
    )
    ax.grid(alpha=0.3)
    save_figure(fig, path)


def _stiffness_plot(path: Path, a: CatenaryAnalysis) -> None:
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7))
    ax1.plot(a.stiffness_x_m, a.stiffness_N_m, color="tab:blue")
    ax1.axhline(a.mean_stiffness_N_m, ls="--", color="tab:red", lw=1, label=f"mean {a.mean_stiffness_N_m:.0f} N/m")
    for xd in a.dropper_positions_m:
        ax1.axvline(xd, color="0.8", lw=0.8)
    ax1.set_xlabel("x in the central span [m]")
    ax1.set_ylabel("vertical stiffness k_z [N/m]")
    ax1.set_title(f"{a.name}: contact-wire stiffness (Paper A Fig. 7 style; droppers grey)")
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    f = np.array(a.wave_frequencies_hz)
    lam = np.array(a.wavelengths_m)
    ok = np.array(a.propagating)
    ax2.plot(f[ok], lam[ok], "o", ms=4, label="FE, propagating")
    ax2.plot(f[~ok], lam[~ok], "x", ms=5, color="0.5", label="FE, stop band (not fitted)")
    from pantohil.models.catenary.asm.string import AsmParameters, wavelength_at_rest

    fine = np.linspace(f.min(), f.max(), 200)
    p = AsmParameters(a.contact_tension_N, a.fitted_density_kg_m, a.support_stiffness_N_m2, a.alpha_1_s, a.beta_s)
    ax2.plot(fine, [wavelength_at_rest(p, 2 * np.pi * x) for x in fine], color="tab:red",
             label=f"ASM2, mu = {a.fitted_density_kg_m:.4f} kg/m (10-40 Hz fit)")
    ax2.set_xlabel("frequency [Hz]")
    ax2.set_ylabel("wavelength [m]")
    ax2.set_title("wavelength under a fixed harmonic force (Paper A Fig. 10 style)")
    ax2.legend(fontsize=8)
    ax2.grid(alpha=0.3)
    save_figure(fig, path)


def catenary_report(path: Path, out_dir: Path, overwrite: bool = False) -> dict:
    """`pantohil catenary`: analyse a catenary file and write catenary.json, CSV files and plots to out_dir
    (checked first; it appears complete or not at all; `overwrite` replaces a used one)."""
    t0 = time.perf_counter()
    cat = load_definition(path)
    with atomic_output_folder(out_dir, "--out", overwrite) as part:
        a = analyse(cat)
        summary = {**a.summary(), "source": str(path), "elapsed_s": time.perf_counter() - t0}
        _write_report(part, cat, a, summary)
    return summary


def _write_report(out_dir: Path, cat, a, summary: dict) -> None:
    """The files of `pantohil catenary`, catenary.json last."""
    _write_csv(
        out_dir / "profile.csv",
        ["x_m", "z0_m"],
        ((f"{x:.4f}", f"{z:.9e}") for x, z in zip(a.profile_x_m, a.profile_z_m, strict=False)),
    )
    _write_csv(
        out_dir / "stiffness.csv",
        ["x_m", "kz_N_m"],
        ((f"{x:.4f}", f"{k:.3f}") for x, k in zip(a.stiffness_x_m, a.stiffness_N_m, strict=False)),
    )
    _write_csv(out_dir / "droppers.csv", ["dropper", "x_m", "length_m", "tension_N"],
               ((i + 1, f"{x:.4f}", f"{L:.6f}", f"{T:.3f}") for i, (x, L, T) in
                enumerate(zip(a.dropper_positions_m, a.dropper_lengths_m, a.dropper_tensions_N, strict=False))))
    _geometry_plot(out_dir / "geometry.png", cat, form_find(cat, 3))
    _stiffness_plot(out_dir / "stiffness.png", a)
    write_text_atomic(out_dir / "catenary.json", json.dumps(summary, indent=2) + "\n")
