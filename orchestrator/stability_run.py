"""`pantohil stability`: maps of the spectral radius of the virtual HIL iteration over f_max, the contact
stiffness and the delay, with the best relaxation at every point (Paper D sec. 4, Figs. 5-7).

One Dask task per (f_max, delay) row computes every contact stiffness of the row (the operator is built
once per row). The delay D is the loop latency, compensated in full (Paper D sec. 3.4); without --delay
the case's own latency and advance are used (master connections + rig). A case with a rig file has the
rig's chain in the map (models/stability/rig_map.py: its decimation, drive ramp, position loop and filter,
with their compensation at the kept harmonics), and D is the advance alone.
"""
from __future__ import annotations

import csv
import math
import os
import time
from pathlib import Path

import numpy as np

from pantohil.models.case import Case, CaseError, load_case
from pantohil.models.catenary.interface import catenary_model
from pantohil.models.catenary.receptance import harmonic_count
from pantohil.models.stability.map_point import (best_relaxation, contact_frequency_hz, problem_for,
                                                 rig_problem_for, with_contact_stiffness)
from pantohil.models.storage import atomic_path

from .dask_engine import dask_client, run_tasks, tune_worker_allocator, worker_count
from .run_topology import delay_plan
from .output_paths import atomic_output_folder
from .report import write_json_atomic

COLUMNS = ("update", "f_max_hz", "contact_stiffness_N_m", "delay_steps", "relaxation", "spectral_radius")
MAX_AXIS_POINTS = 10_000
MAX_MAP_POINTS = 200_000


def parse_range(text: str | None, option: str, integer: bool = False, positive: bool = False) -> np.ndarray | None:
    """"A:B:N" (N values from A to B), "A:B:N:log" (geometric), "A,B,C" or "A"; with `positive`, every
    value must be above 0."""
    if text is None:
        return None
    parts = text.split(":")
    try:
        if len(parts) == 1:
            if text.count(",") >= MAX_AXIS_POINTS:
                raise CaseError(f"{option}: above the limit of {MAX_AXIS_POINTS} points per axis")
            values = np.array([float(v) for v in text.split(",") if v.strip()])
        elif len(parts) in (3, 4):
            a, b, n = float(parts[0]), float(parts[1]), int(parts[2])
            if n < 1:
                raise CaseError(f"{option}: empty range {text!r} (N must be >= 1)")
            if n > MAX_AXIS_POINTS:
                raise CaseError(f"{option}: {n} points, above the limit of {MAX_AXIS_POINTS} points per axis")
            if len(parts) == 4 and parts[3] != "log":
                raise CaseError(f"{option}: expected A:B:N or A:B:N:log (got {text!r})")
            if len(parts) == 4 and (a <= 0 or b <= 0):
                raise CaseError(f"{option}: a log range needs positive ends (got {text!r})")
            values = np.geomspace(a, b, n) if len(parts) == 4 else np.linspace(a, b, n)
        else:
            raise ValueError
    except CaseError:
        raise
    except ValueError:
        raise CaseError(f"{option}: expected A:B:N, A:B:N:log, A,B,C or A (got {text!r})") from None
    if len(values) == 0:
        raise CaseError(f"{option}: empty range {text!r}")
    if not np.all(np.isfinite(values)):
        raise CaseError(f"{option}: values must be finite numbers (got {text!r})")
    if positive and np.any(values <= 0):
        raise CaseError(f"{option}: must be > 0 (got {text!r})")
    if integer:
        if np.any(values != np.round(values)):
            raise CaseError(f"{option}: delays are whole steps (got {text!r})")
        values = np.unique(values.astype(int))
    return values


def _operator(case: Case, f_max: float):
    """The catenary model's operator reduced to f_max's harmonics: (kernel, None) or (None, I_cc)."""
    return catenary_model(case).stability_operator(case, harmonic_count(f_max, case.samples_per_span, case.dt_s))


def stability_row(task: dict) -> list[dict]:
    """One map row (one f_max and delay, every contact stiffness): runs on a Dask worker."""
    tune_worker_allocator()
    t0 = time.perf_counter()
    case = load_case(task["case"], task["overrides"])
    kernel, I_cc = _operator(case, task["f_max_hz"])
    nh = harmonic_count(task["f_max_hz"], case.samples_per_span, case.dt_s)
    rows = []
    for kc in task["contact_stiffness_N_m"]:
        pan = with_contact_stiffness(case.pantograph, kc)
        if case.rig_spec is not None:  # the rig file's chain in the loop (models/stability/rig_map.py)
            pb = rig_problem_for(case, task["update"], pan, nh, task["delay_steps"], kernel=kernel, I_cc=I_cc)
        else:
            pb = problem_for(task["update"], pan, case.dt_s, task["latency_steps"], task["delay_steps"],
                             kernel=kernel, I_cc=I_cc)
        if task["relaxation"] is None:
            mu, rho = best_relaxation(pb)
        else:
            mu, rho = task["relaxation"], pb.spectral_radius(task["relaxation"])
        rows.append({"update": task["update"], "f_max_hz": task["f_max_hz"], "contact_stiffness_N_m": float(kc),
                     "delay_steps": task["delay_steps"], "relaxation": mu, "spectral_radius": rho})
    rows[-1]["_row_s"] = time.perf_counter() - t0
    return rows


def _frequency_and_stiffness_axes(case: Case, f_max_hz: np.ndarray | None,
                                  contact_stiffness_N_m: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The f_max and contact-stiffness axes of the map (the case's values if not given), checked positive."""
    f_values = np.array([case.sections.hil.max_frequency_hz] if f_max_hz is None else f_max_hz, dtype=float)
    k_values = np.array([case.pantograph.contact_stiffness_N_m] if contact_stiffness_N_m is None
                        else contact_stiffness_N_m, dtype=float)
    if np.any(f_values <= 0):
        raise CaseError(f"f_max: frequencies must be > 0 Hz (got {f_values.min():g} Hz)")
    if np.any(k_values <= 0):
        raise CaseError(f"contact stiffness: must be > 0 N/m (got {k_values.min():g} N/m)")
    return f_values, k_values


def _delay_latency_pairs(case: Case, delay_steps: np.ndarray | None) -> list[tuple[int, int]]:
    """The (delay, latency) pairs of the map: the case's own without --delay, else each D compensating D.
    With a rig file the latency is the rig chain's own (in the map) and D the advance alone."""
    plan = delay_plan(case)
    if delay_steps is None:
        pairs = [(plan["delay_steps"], plan["loop_latency_steps"] + plan["rig_latency_steps"])]
    else:
        d_values = np.asarray(delay_steps)
        if np.any(d_values < 1) or np.any(d_values >= case.samples_per_span):
            raise CaseError(f"delay: must lie in 1..{case.samples_per_span - 1} steps (got {d_values.min()} to "
                            f"{d_values.max()})")
        pairs = [(int(d), int(d)) for d in d_values]
    return pairs


def _map_summary(case: Case, update: str, rows: list[dict], tasks: list[dict], n_workers: int,
                 scheduler: str | None, errors: list[str], relaxation: float | None, t_map: float, t0: float,
                 figures) -> dict:
    """The map's summary.json content: counts, stable points, lowest spectral radius and timing."""
    rho = np.array([r["spectral_radius"] for r in rows])
    return {
        "case": case.name, "update": update, "points": len(rows), "tasks": len(tasks), "workers": n_workers,
        "scheduler": scheduler or "LocalCluster", "failed_rows": errors,
        "stable_points": int(np.sum(rho < 1)), "min_spectral_radius": float(rho.min()) if len(rho) else None,
        "contact_frequency_hz_at_case_kc": float(contact_frequency_hz(case.pantograph,
                                                                      case.pantograph.contact_stiffness_N_m)),
        "relaxation": "best found" if relaxation is None else relaxation,
        "rig": None if case.rig_spec is None else {
            "file": case.rig_spec.name, "in_map": "its chain (models/stability/rig_map.py)",
            "compensation": "response" if case.compensates_rig_response else "delay"},
        "timing": {"map_s": t_map, "wall_s": time.perf_counter() - t0,
                   "per_point_s": t_map / max(len(rows), 1) * max(n_workers, 1)},
        "figures": figures,
    }


def run_stability(case_path: Path | None, overrides: list[str], out: Path, update: str | None = None,
                  f_max_hz: np.ndarray | None = None, contact_stiffness_N_m: np.ndarray | None = None,
                  delay_steps: np.ndarray | None = None, relaxation: float | None = None,
                  scheduler: str | None = None, workers: int | None = None, progress: bool = True,
                  overwrite: bool = False) -> dict:
    """The spectral-radius map over f_max, contact stiffness and delay (Paper D sec. 4); an axis not
    given takes the case's value (the delay: the case's latency and advance). The folder `out` is checked
    first and appears complete or not at all (`overwrite` replaces a used one)."""
    case = load_case(case_path, overrides)
    if update is not None and update not in ("step", "span"):
        raise CaseError(f"update: must be step or span (got {update!r})")
    if relaxation is not None and not 0 < relaxation < 2:
        raise CaseError(f"relaxation: must lie in (0, 2) (got {relaxation:g})")
    if case.sections.second_pantograph is not None:
        from .pair_stability import refuse_pair_axes, run_pair_stability

        refuse_pair_axes(f_max_hz, contact_stiffness_N_m, delay_steps)
        return run_pair_stability(case, case_path, overrides, out, update, relaxation, overwrite, write_csv)
    update = update or case.hil_update
    f_values, k_values = _frequency_and_stiffness_axes(case, f_max_hz, contact_stiffness_N_m)
    pairs = _delay_latency_pairs(case, delay_steps)
    points = len(pairs) * len(f_values) * len(k_values)
    if points > MAX_MAP_POINTS:
        raise CaseError(f"stability map: {points} points, above the limit of {MAX_MAP_POINTS} points")
    tasks = [{"case": str(case.source) if case_path is not None else None, "overrides": list(overrides),
              "update": update, "f_max_hz": float(f), "contact_stiffness_N_m": [float(k) for k in k_values],
              "delay_steps": d, "latency_steps": lat, "relaxation": relaxation}
             for d, lat in pairs for f in f_values]
    tasks.sort(key=lambda t: -t["f_max_hz"])  # the rows with most harmonics cost most: first, so none is left last
    rows: list[dict] = []
    errors: list[str] = []
    t0 = time.perf_counter()

    def keep(task, result, error):
        if error:
            errors.append(f"f_max {task['f_max_hz']:g} Hz, D {task['delay_steps']}: {error}")
        else:
            rows.extend(result)

    with atomic_output_folder(out, "--out", overwrite) as part:
        with dask_client(scheduler, workers) as client:
            n_workers = worker_count(client)
            t_start = time.perf_counter()
            keys = [f"stability-{os.getpid()}-{i}" for i in range(len(tasks))]
            run_tasks(client, stability_row, tasks, keys, keep, progress, desc="stability map",
                      weight=lambda task: len(task["contact_stiffness_N_m"]))
            t_map = time.perf_counter() - t_start
        rows.sort(key=lambda r: (r["delay_steps"], r["f_max_hz"], r["contact_stiffness_N_m"]))
        write_csv(part / "stability.csv", rows)
        from .report import plot_stability_maps

        figures = plot_stability_maps(part, rows, case.pantograph, update, case.title)
        summary = _map_summary(case, update, rows, tasks, n_workers, scheduler, errors, relaxation, t_map, t0,
                               figures)
        write_json_atomic(part / "summary.json", summary)
    if errors:  # the map of the rows that ran is in place
        raise RuntimeError(f"{len(errors)} map rows failed; first: {errors[0]}")
    return summary


def write_csv(path: Path, rows: list[dict]) -> None:
    """Write the map points to stability.csv, atomically."""
    with atomic_path(path) as part, open(part, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for r in rows:
            w.writerow([r["update"], f"{r['f_max_hz']:.6g}", f"{r['contact_stiffness_N_m']:.6g}", r["delay_steps"],
                        f"{r['relaxation']:.6g}",
                        f"{r['spectral_radius']:.9g}" if math.isfinite(r["spectral_radius"]) else "inf"])


def read_csv(path: Path) -> list[dict]:
    """Read the map points of a stability.csv."""
    with open(path) as fh:
        return [{"update": r["update"], "f_max_hz": float(r["f_max_hz"]),
                 "contact_stiffness_N_m": float(r["contact_stiffness_N_m"]), "delay_steps": int(r["delay_steps"]),
                 "relaxation": float(r["relaxation"]), "spectral_radius": float(r["spectral_radius"])}
                for r in csv.DictReader(fh)]
