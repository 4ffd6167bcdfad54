"""Run-folder outputs: summary.json, steady_span.csv and the plots."""
from __future__ import annotations

import functools
import json
import math
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from pantohil.models.storage import atomic_path, write_text_atomic


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
    """Lay out, write atomically (PNG, 120 dpi) and free a figure. An axis over constant data (a run that
    ended after a step or two) is drawn as matplotlib widens it, without its warning on stderr, which
    carries the run's one line."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Attempting to set identical", category=UserWarning)
        fig.tight_layout()
        with atomic_path(path) as part:
            fig.savefig(part, dpi=120, format="png")
    plt.close(fig)


def write_json_atomic(path: Path, data: dict) -> None:
    """Write JSON to a temporary file and rename it into place, so a reader never sees half a file."""
    write_text_atomic(path, json.dumps(_clean(data), indent=2) + "\n")


def write_steady_span(path: Path, t: np.ndarray, z0: np.ndarray, z: np.ndarray, f: np.ndarray,
                      speed_m_s: float, second: tuple[np.ndarray, np.ndarray] | None = None) -> None:
    """Write steady_span.csv (`t_s,z0_m,z_m,f_N,x_m` over the converged span: x_m is the pantograph's
    position in the span, v t; with two pantographs also `z2_m,f2_N`, the second's wire height and force),
    atomically."""
    columns = [t, z0, z, f, t * speed_m_s] + (list(second) if second is not None else [])
    formats = ["{:.6f}", "{:.12e}", "{:.12e}", "{:.12e}", "{:.6f}", "{:.12e}", "{:.12e}"][:len(columns)]
    line = ",".join(formats)
    rows = "\n".join(line.format(*values) for values in zip(*columns, strict=True))
    header = "t_s,z0_m,z_m,f_N,x_m" + (",z2_m,f2_N" if second is not None else "")
    write_text_atomic(path, header + "\n" + rows + "\n")


def plot_contact_force(path: Path, dt: float, spans: list[np.ndarray], reference: np.ndarray | None,
                       filtered: np.ndarray | None, title: str, speed_m_s: float) -> None:
    """Last spans overlaid over the pantograph's position in the span (Paper B Fig. 11 style; time on the
    top axis), with the closed form where there is one, drawn about the run's mean: the summary's error
    is taken without the means, and a tared load cell (a rigid mass) measures no static force."""
    fig, ax = plt.subplots(figsize=(9, 4.5))
    x = np.arange(len(spans[-1])) * dt * speed_m_s
    for i, f in enumerate(spans):
        ax.plot(x, f, color="0.2", lw=0.8, alpha=0.35 + 0.65 * (i + 1) / len(spans),
                label=f"HIL, last {len(spans)} spans" if i == len(spans) - 1 else None)
    if filtered is not None:
        ax.plot(x, filtered, color="tab:blue", lw=1.2, label="last span, 20 Hz low-pass")
    if reference is not None:
        shift = float(np.mean(spans[-1]) - np.mean(reference))
        moved = f", moved {shift:+.1f} N to the run's mean" if abs(shift) > 0.01 * np.std(reference) else ""
        ax.plot(x, reference + shift, "--", color="tab:red", lw=1.2, label=f"closed form (same harmonics){moved}")
    ax.set_xlabel("pantograph position in the span [m]")
    ax.set_ylabel("contact force [N]")
    top = ax.secondary_xaxis("top", functions=(lambda p: p / speed_m_s, lambda t: t * speed_m_s))
    top.set_xlabel("time in span [s]")
    ax.set_title(title, pad=10)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    save_figure(fig, path)


def plot_convergence(path: Path, history: list[dict], tol: float, title: str) -> None:
    """Plot the span-to-span change and the force statistics per span."""
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
    """Contact force over one span of two runs, overlaid, and below it their difference (first - second)."""
    fig, (ax, below) = plt.subplots(2, 1, figsize=(9, 6), sharex=True, height_ratios=(3, 1.4))
    for label, f in forces.items():
        ax.plot(np.arange(len(f)) * dt, f, lw=1.1, label=label)
    (la, fa), (lb, fb) = list(forces.items())[:2]
    below.plot(np.arange(len(fa)) * dt, fa - fb, lw=1.0, color="tab:red")
    below.set_ylabel("difference [N]")
    below.set_title(f"{la} minus {lb}", fontsize=8)
    below.set_xlabel("time in span [s]")
    below.grid(alpha=0.3)
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
                       central: list, title: str, second: tuple | None = None) -> None:
    """Contact force along a finite section, central spans shaded; with `second` (its position, force and
    low-pass), a second pantograph's too, against its own position."""
    fig, ax = plt.subplots(figsize=(11, 4.5))
    ax.plot(x, force, color="0.6", lw=0.5, label="contact force")
    ax.plot(x, filtered, color="tab:blue", lw=1.0, label="20 Hz low-pass")
    if second is not None:
        ax.plot(second[0], second[1], color="tab:pink", lw=0.5, alpha=0.6, label="second pantograph")
        ax.plot(second[0], second[2], color="tab:red", lw=1.0, label="second pantograph, 20 Hz low-pass")
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


def _edges(values: np.ndarray, log: bool) -> np.ndarray:
    v = np.log(values) if log else values.astype(float)
    if len(v) == 1:
        e = np.array([v[0] - 0.5, v[0] + 0.5]) if not log else np.array([v[0] - 0.1, v[0] + 0.1])
    else:
        mid = (v[1:] + v[:-1]) / 2
        e = np.concatenate([[v[0] - (mid[0] - v[0])], mid, [v[-1] + (v[-1] - mid[-1])]])
    return np.exp(e) if log else e


def _is_geometric(values: np.ndarray) -> bool:
    if len(values) < 3 or np.any(values <= 0):
        return False
    r = values[1:] / values[:-1]
    return bool(np.allclose(r, r[0], rtol=1e-6) and not np.allclose(np.diff(values), values[1] - values[0], rtol=1e-6))


def _at_delay(index: dict, delay_steps, f_max_hz, contact_stiffness_N_m):
    """The map row of one delay, f_max and contact stiffness, or None."""
    return index.get((delay_steps, f_max_hz, contact_stiffness_N_m))


def plot_stability_maps(out: Path, rows: list[dict], pantograph, update: str, case_name: str) -> list[str]:
    """Paper D Figs. 5-7: spectral radius (unstable region blank) and the relaxation chosen, with the
    pantograph's contact natural frequency in red. Axes: contact stiffness (or delay) against f_max."""
    from pantohil.models.stability.map_point import contact_frequency_hz

    if not rows:
        return []
    f = np.unique([r["f_max_hz"] for r in rows])
    k = np.unique([r["contact_stiffness_N_m"] for r in rows])
    d = np.unique([r["delay_steps"] for r in rows])
    index = {(r["delay_steps"], r["f_max_hz"], r["contact_stiffness_N_m"]): r for r in rows}
    figures = []
    if len(k) == 1 and len(d) > 1:  # Paper D Fig. 7: delay against f_max at one contact stiffness
        panels = [("delay", d, lambda fi, xi: index.get((xi, fi, k[0])), f"D{d[0]}-{d[-1]}")]
    else:
        panels = [("kc", k, functools.partial(_at_delay, index, dd), f"D{dd}") for dd in d]
    for axis, xs, get, tag in panels:
        if len(xs) * len(f) < 2:
            continue
        rho = np.full((len(f), len(xs)), np.nan)
        mu = np.full_like(rho, np.nan)
        for i, fi in enumerate(f):
            for j, xj in enumerate(xs):
                r = get(fi, xj)
                if r is not None:
                    rho[i, j], mu[i, j] = r["spectral_radius"], r["relaxation"]
        log_x = axis == "kc" and _is_geometric(xs)
        xe, ye = _edges(xs, log_x), _edges(f, False)
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), sharey=True)
        stable = np.ma.masked_where(~(rho < 1.0), rho)
        m0 = axes[0].pcolormesh(xe, ye, stable, cmap="viridis", vmin=np.nanmin(stable) if stable.count() else 0,
                                vmax=1.0, shading="flat")
        fig.colorbar(m0, ax=axes[0], label="spectral radius (unstable: blank)")
        m1 = axes[1].pcolormesh(xe, ye, np.ma.masked_invalid(mu), cmap="magma", shading="flat")
        fig.colorbar(m1, ax=axes[1], label="relaxation mu_c")
        for ax in axes:
            if axis == "kc":
                kk = np.geomspace(xe[0], xe[-1], 200) if log_x else np.linspace(xe[0], xe[-1], 200)
                ax.plot(kk, contact_frequency_hz(pantograph, kk), "r-", lw=2, label="contact natural frequency")
                ax.set_xlabel("contact stiffness k_c [N/m]")
                if log_x:
                    ax.set_xscale("log")
            else:
                fc = float(contact_frequency_hz(pantograph, k[0]))
                ax.axhline(fc, color="r", lw=2, label=f"contact natural frequency ({fc:.1f} Hz)")
                ax.set_xlabel("delay D [steps]")
            ax.set_ylim(ye[0], ye[-1])
            ax.legend(loc="upper right", fontsize=8)
        axes[0].set_ylabel("f_max [Hz]")
        what = {"step": "step-by-step", "span": "span-by-span"}[update]
        extra = f"D = {tag[1:]}" if axis == "kc" else f"k_c = {k[0]:.3g} N/m"
        fig.suptitle(f"{case_name}: {what} updating, {extra} (Paper D Figs. 5-7)")
        fig.tight_layout()
        name = f"stability_{update}_{tag}.png"
        with atomic_path(out / name) as part:
            fig.savefig(part, dpi=110)
        plt.close(fig)
        figures.append(name)
    return figures


def plot_sweep_std(path: Path, curves: list, x_label: str, y_label: str, title: str) -> None:
    """One curve per combination of the other grid keys; points that failed or diverged are crossed."""
    fig, ax = plt.subplots(figsize=(8, 4.8))
    for label, xs, ys, ok in curves:
        line, = ax.plot(xs[ok], ys[ok], "o-", ms=4, label=label or None)
        if np.any(~ok):
            ax.plot(xs[~ok], np.where(np.isfinite(ys[~ok]), ys[~ok], np.nanmin(ys) if np.any(np.isfinite(ys)) else 0),
                    "x", color=line.get_color(), ms=8)
    ax.set_xlabel(x_label)
    ax.set_ylabel(y_label)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    if any(label for label, *_ in curves):
        ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as part:
        fig.savefig(part, dpi=110)
    plt.close(fig)
