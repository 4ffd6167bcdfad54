"""Run-folder outputs: summary.json, steady_span.csv and the plots."""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def _clean(obj):
    """JSON-safe: non-finite floats become null."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def save_figure(fig, path: Path) -> None:
    """Lay out, write atomically (PNG, 120 dpi) and free a figure."""
    fig.tight_layout()
    tmp = path.with_name(path.name + ".part")
    fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    os.replace(tmp, path)


def write_json_atomic(path: Path, data: dict) -> None:
    tmp = path.with_suffix(path.suffix + ".part")
    tmp.write_text(json.dumps(_clean(data), indent=2) + "\n")
    os.replace(tmp, path)


def write_steady_span(path: Path, t: np.ndarray, z0: np.ndarray, z: np.ndarray, f: np.ndarray) -> None:
    rows = "\n".join(f"{a:.6f},{b:.12e},{c:.12e},{d:.12e}" for a, b, c, d in zip(t, z0, z, f))
    tmp = path.with_suffix(".csv.part")
    tmp.write_text("t_s,z0_m,z_m,f_N\n" + rows + "\n")
    os.replace(tmp, path)


def plot_contact_force(path: Path, dt: float, spans: list[np.ndarray], reference: np.ndarray | None,
                       filtered: np.ndarray | None, title: str) -> None:
    """Last spans overlaid (Paper B Fig. 11 style), with the closed form where there is one."""
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for i, f in enumerate(spans):
        ax.plot(np.arange(len(f)) * dt, f, color="0.2", lw=0.8, alpha=0.35 + 0.65 * (i + 1) / len(spans),
                label=f"HIL, last {len(spans)} spans" if i == len(spans) - 1 else None)
    if filtered is not None:
        ax.plot(np.arange(len(filtered)) * dt, filtered, color="tab:blue", lw=1.2, label="last span, 20 Hz low-pass")
    if reference is not None:
        ax.plot(np.arange(len(reference)) * dt, reference, "--", color="tab:red", lw=1.2,
                label="closed form (same harmonics)")
    ax.set_xlabel("time in span [s]")
    ax.set_ylabel("contact force [N]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    save_figure(fig, path)


def plot_convergence(path: Path, history: list[dict], tol: float, title: str) -> None:
    spans = [h["span"] for h in history]
    change = [h["change"] if math.isfinite(h["change"]) else np.nan for h in history]
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax1.semilogy(spans, change, "o-", ms=3)
    ax1.axhline(tol, color="tab:red", ls="--", lw=1, label=f"tolerance {tol:g}")
    ax1.set_ylabel("rms span-to-span change / std")
    ax1.grid(alpha=0.3, which="both")
    ax1.legend(fontsize=8)
    ax1.set_title(title)
    ax2.plot(spans, [h["std_N"] for h in history], "o-", ms=3, label="std")
    ax2.plot(spans, [h["mean_N"] for h in history], "s-", ms=3, label="mean")
    ax2.set_xlabel("virtual span")
    ax2.set_ylabel("contact force [N]")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=8)
    save_figure(fig, path)


def plot_dropper_corrections(path: Path, dt: float, corrections: np.ndarray, title: str) -> None:
    """Dropper correction forces over the converged span, one curve per dropper (Paper C Fig. 8 style).
    Each column holds dropper d's correction at the instant of its window that every step visits."""
    fig, ax = plt.subplots(figsize=(9, 4.5))
    t = np.arange(corrections.shape[0]) * dt
    for d in range(corrections.shape[1]):
        if np.any(corrections[:, d] > 0):
            ax.plot(t, corrections[:, d], lw=1.0, label=f"dropper {d + 1}")
    ax.set_xlabel("time in span [s] (pantograph position / speed)")
    ax.set_ylabel("correction force [N]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=8)
    save_figure(fig, path)


def plot_force_comparison(path: Path, dt: float, forces: dict, title: str) -> None:
    """Contact force over one span of several runs, overlaid."""
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for label, f in forces.items():
        ax.plot(np.arange(len(f)) * dt, f, lw=1.1, label=label)
    ax.set_xlabel("time in span [s]")
    ax.set_ylabel("contact force [N]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    save_figure(fig, path)


def plot_force_history(path: Path, forces: list, per_block: int, title: str) -> None:
    """Contact force step by step, blocks marked (Paper C Fig. A.4 style)."""
    fig, ax = plt.subplots(figsize=(9, 4))
    k = np.arange(1, len(forces) + 1)
    ax.plot(k, forces, "o-", ms=2.5, lw=0.8)
    for b in range(per_block, len(forces), per_block):
        ax.axvline(b + 0.5, color="0.85", lw=0.6)
    ax.set_xlabel("step")
    ax.set_ylabel("contact force [N]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    save_figure(fig, path)


def plot_section_force(path: Path, x: np.ndarray, force: np.ndarray, filtered: np.ndarray, span_m: float,
                       central: list, title: str) -> None:
    """Contact force along a finite section, central spans shaded."""
    fig, ax = plt.subplots(figsize=(11, 4.5))
    ax.plot(x, force, color="0.6", lw=0.5, label="contact force")
    ax.plot(x, filtered, color="tab:blue", lw=1.0, label="20 Hz low-pass")
    ax.axvspan(central[0] * span_m, (central[-1] + 1) * span_m, color="tab:orange", alpha=0.12, label="central spans")
    ax.set_xlabel("pantograph position [m]")
    ax.set_ylabel("contact force [N]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    save_figure(fig, path)


def plot_dropper_comparison(path: Path, a: np.ndarray, b: np.ndarray, label_a: str, label_b: str) -> None:
    """Dropper correction forces of two runs (columns t_s, dropper 1..n), Paper C Fig. 10 style."""
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for d in range(1, a.shape[1]):
        if np.any(a[:, d] > 0) or np.any(b[:, d] > 0):
            line, = ax.plot(a[:, 0], a[:, d], lw=1.1, label=f"dropper {d}: {label_a}")
            ax.plot(b[:, 0], b[:, d], "--", lw=1.1, color=line.get_color(), label=f"dropper {d}: {label_b}")
    ax.set_xlabel("time in span [s]")
    ax.set_ylabel("correction force [N]")
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=6, ncol=2)
    save_figure(fig, path)
