"""The report of `pantohil optimise`: history.csv (every design in the order evaluated), and optimise.png: the
geometry before and after, the force of the nominal and the optimised design over the span, the optimiser's
history and the statistics of EN 50367 (std, max, min) side by side."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from pantohil.models.storage import atomic_path

FIGURE = "optimise.png"


def write_history(path: Path, rows: list[dict], names: list[str]) -> None:
    """One line per design: its index, variables, feasibility, objective and each speed's std, max and min."""
    speeds = next((r["result"]["speeds"] for r in rows if r["result"]["feasible"]), [])
    stats = [f"{k}_{s['speed_kmh']:g}kmh_N" for s in speeds for k in ("std", "max", "min")]
    with atomic_path(path) as part, open(part, "w", newline="", encoding="utf-8") as fh:
        out = csv.writer(fh)
        out.writerow(["design", *names, "feasible", "objective_N", *stats, "reason"])
        for r in sorted(rows, key=lambda r: r["index"]):
            res = r["result"]
            values = [v for s in res.get("speeds", []) for v in (s["std_N"], s["max_N"], s["min_N"])]
            out.writerow([r["index"], *r["x"], res["feasible"], res.get("objective_N", ""),
                          *(values or [""] * len(stats)), res.get("reason", "")])


def _geometry(ax, nominal_cat, optimised_cat) -> None:
    for cat, label, colour, ls in ((nominal_cat, "nominal", "k", "--"), (optimised_cat, "optimised", "C0", "-")):
        x = np.array(cat.dropper_positions_m)
        line = np.linspace(0.0, cat.span_m, 400)
        ax.plot(line, 1e3 * cat.design_height(line), color=colour, ls=ls, lw=1, label=label)
        ax.plot(x, 1e3 * cat.design_height(x), "o", color=colour, ms=4)
        for xd in x:  # the dropper positions, which a spacing design moves
            ax.axvline(xd, color=colour, ls=ls, lw=0.6, alpha=0.5)
    ax.set_xlabel("position in the span [m]")
    ax.set_ylabel("contact-wire design height [mm]")
    ax.set_title("geometry (markers and vertical lines: droppers)")
    ax.legend(fontsize=8)


def _forces(ax, speed_kmh: float, span_m: float, nominal: np.ndarray, optimised: np.ndarray) -> None:
    x = np.arange(len(nominal)) * span_m / len(nominal)
    ax.plot(x, nominal, "k--", lw=1, label=f"nominal, std {nominal.std():.2f} N")
    ax.plot(x, optimised, "C0-", lw=1, label=f"optimised, std {optimised.std():.2f} N")
    ax.set_xlabel("position in the span [m]")
    ax.set_ylabel("contact force [N]")
    ax.set_title(f"steady force, {speed_kmh:g} km/h, 0-20 Hz (linear pantograph)")
    ax.legend(fontsize=8)


def _history(ax, rows: list[dict]) -> None:
    rows = sorted(rows, key=lambda r: r["index"])
    k = np.array([r["index"] for r in rows if r["result"]["feasible"]])
    y = np.array([r["result"]["objective_N"] for r in rows if r["result"]["feasible"]])
    ax.plot(k, y, ".", color="0.6", label="design")
    if len(y):
        ax.plot(k, np.minimum.accumulate(y), "C0-", label="best so far")
    bad = [r["index"] for r in rows if not r["result"]["feasible"]]
    if bad and len(y):
        ax.plot(bad, np.full(len(bad), y.max()), "rx", label="cannot be built")
    ax.set_xlabel("design evaluated")
    ax.set_ylabel("objective: std [N]")
    ax.set_title("optimiser history")
    ax.legend(fontsize=8)


def _statistics(ax, nominal: dict, optimised: dict) -> None:
    keys = ("std_N", "max_N", "min_N")
    pos = np.arange(len(keys))
    for shift, stats, colour, label in ((-0.2, nominal, "0.6", "nominal"), (0.2, optimised, "C0", "optimised")):
        bars = ax.bar(pos + shift, [stats[k] for k in keys], 0.4, color=colour, label=label)
        ax.bar_label(bars, fmt="%.1f", fontsize=8)
    ax.set_xticks(pos, ["std", "max", "min"])
    ax.set_ylabel("force [N]")
    ax.set_title("EN 50367 statistics (first speed)")
    ax.legend(fontsize=8)


def plot_report(path: Path, nominal_cat, optimised_cat, rows: list[dict], nominal: dict, optimised: dict) -> None:
    """optimise.png: geometry, force over the span, history, statistics (first speed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    first_n, first_o = nominal["speeds"][0], optimised["speeds"][0]
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5))
    _geometry(axes[0, 0], nominal_cat, optimised_cat)
    _forces(axes[0, 1], first_n["speed_kmh"], nominal_cat.span_m, np.array(first_n["force_N"]),
            np.array(first_o["force_N"]))
    _history(axes[1, 0], rows)
    _statistics(axes[1, 1], first_n, first_o)
    fig.tight_layout()
    with atomic_path(path) as part:
        fig.savefig(part, dpi=110)
    plt.close(fig)
