"""`pantohil stability` of a two-pantograph case: the spectral radius of the pair's iteration
(models/stability/pair_map.py, Paper D eq. 13 for two contact points) at the case's settings, for one updating
strategy or both, so that a spacing is checked before a run or a rig session.

Step-by-step updating applies the coupling compensation Q sample by sample, where it is not exact: at some
spacings the pair diverges at any relaxation while span-by-span updating (Q exact, Paper D eq. A.8 through Q)
converges at every spacing of Paper A Fig. 17 (tests/benchmarks/bench_pair_sweep.py). The verdict names the
strategy that converges fastest.
"""
from __future__ import annotations

import time
from pathlib import Path

from pantohil.models.case import Case, CaseError, load_case
from pantohil.models.catenary.interface import catenary_model
from pantohil.models.hil.pair_loop import pair_delay_steps
from pantohil.models.stability.pair_map import pair_spectral_radius

from .output_paths import atomic_output_folder
from .report import write_json_atomic

UPDATES = ("step", "span")


def refuse_pair_axes(f_max_hz, contact_stiffness_N_m, delay_steps) -> None:
    """The pair's radius is at the case's f_max, contact stiffness and delays: a map axis is one line, exit 2."""
    for value, option in ((f_max_hz, "--fmax"), (contact_stiffness_N_m, "--contact-stiffness"),
                          (delay_steps, "--delay")):
        if value is not None:
            raise CaseError(f"{option}: a two-pantograph case's stability is at its own settings (set them with "
                            "--set); only --update and --relaxation apply", key="second_pantograph")


def pair_rows(case_path: Path | None, overrides: list[str], update: str | None,
              relaxation: float | None) -> list[dict]:
    """One row per updating strategy (the given one, or both) at the case's settings with that strategy (and
    `relaxation` if given): its relaxation and the pair's spectral radius."""
    rows = []
    for strategy in (update,) if update else UPDATES:
        mu = [] if relaxation is None else [f"hil.relaxation={relaxation!r}"]
        case = load_case(case_path, [*overrides, f"hil.update={strategy}", *mu])
        rows.append({"update": strategy, "f_max_hz": float(case.sections.hil.max_frequency_hz),
                     "contact_stiffness_N_m": float(case.pantograph.contact_stiffness_N_m),
                     "delay_steps": pair_delay_steps(case)[0], "relaxation": float(case.relaxation),
                     "spectral_radius": pair_spectral_radius(case)})
    return rows


def verdict(rows: list[dict]) -> str:
    """Which strategy converges fastest, or that none does."""
    best = min(rows, key=lambda r: r["spectral_radius"])
    if best["spectral_radius"] >= 1:
        return "diverges with every strategy mapped: change the relaxation, f_max or the spacing"
    return (f"converges with {best['update']}-by-{best['update']} updating at {best['spectral_radius']:.4f} per "
            f"span (hil.update = \"{best['update']}\", hil.relaxation = {best['relaxation']:g})")


def run_pair_stability(case: Case, case_path: Path | None, overrides: list[str], out: Path, update: str | None,
                       relaxation: float | None, overwrite: bool, write_csv) -> dict:
    """The pair's radius per strategy into `out` (stability.csv, summary.json), written whole or not at all;
    `case` loaded from `case_path` (None: the default case) with `overrides`."""
    if not getattr(catenary_model(case), "pair_stability_map", False):
        raise CaseError(f"catenary.model: {case.model!r} has no stability map of a pair (its operators are not "
                        "the pair's)", key="catenary.model")
    t0 = time.perf_counter()
    second = case.sections.second_pantograph
    with atomic_output_folder(out, "--out", overwrite) as part:
        rows = pair_rows(case_path, overrides, update, relaxation)
        t_map = time.perf_counter() - t0
        write_csv(part / "stability.csv", rows)
        stable = [r for r in rows if r["spectral_radius"] < 1]
        summary = {"case": case.name, "update": update or "step and span", "points": len(rows), "tasks": len(rows),
                   "workers": 1, "stable_points": len(stable),
                   "min_spectral_radius": min(r["spectral_radius"] for r in rows),
                   "second_pantograph": {"spacing_m": second.spacing_m, "position": second.position,
                                         "coupling_compensation": second.coupling_compensation},
                   "pair": {r["update"]: {"relaxation": r["relaxation"], "spectral_radius": r["spectral_radius"]}
                            for r in rows},
                   "verdict": verdict(rows), "timing": {"map_s": t_map, "wall_s": time.perf_counter() - t0}}
        write_json_atomic(part / "summary.json", summary)
    return summary
