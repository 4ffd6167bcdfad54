"""The run of `pantohil optimise` (orchestrator/optimise.py checks its request): the search on Dask, the
confirmation of the nominal and the optimised design in the virtual HIL with dropper slackening (both on Dask),
and the files: optimised_catenary.toml, optimised_case.toml, history.csv, optimise.png and summary.json (written
last)."""
from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import asdict
from functools import partial
from pathlib import Path

import numpy as np

from pantohil.models.case import load_case
from pantohil.models.catenary.pfem.design_evaluation import QUALITY_BAND_HZ
from pantohil.models.catenary.fe.definition import build_definition
from pantohil.models.errors import InputError
from pantohil.models.hil.rig_loop import run_loop
from pantohil.models.metrics import lowpass_periodic
from pantohil.models.progress import progress as progress_bar
from pantohil.models.storage import write_text_atomic

from .dask_engine import dask_client, tune_worker_allocator, worker_count
from .design_search import (BUDGET_SPENT, JOURNAL, Evaluator, Extremes, best, design_key, explore, least_merit,
                            polish, search, starts)
from .optimise import STEP, OptimiseRequest, case_overrides, open_folder, prepare, written_case
from .optimise_report import FIGURE, plot_report, write_history
from .report import write_json_atomic

CATENARY_OUT = "optimised_catenary.toml"
CASE_OUT = "optimised_case.toml"
DESCENT_TIME_SPENT = "the descents' share of the time was spent"
COARSE_TIME_SPENT = "the coarse compass searches' share of the time was spent"
POLISH_STEPS = 10  # the compass search's first step, in finite-difference steps (0.5 m for positions, 10 mm heights)
# the descents' share of the time left after the first sample: the compass search after them has the rest, so that it
# runs within --max-minutes (a descent along a bound can take the whole time in steps of a few mm)
DESCENT_SHARE = 0.4
# then compass searches from several starts (COARSE_SHARE of the time left), each down to COARSE_STEPS
# finite-difference steps, each next start RESTART_STEPS from every design an earlier one passed through (1 m, 20 mm),
# and a last one from the best design down to half a step
COARSE_SHARE = 0.8
COARSE_STEPS = 2.5
RESTART_STEPS = 20


def _toml(data: dict) -> str:
    import tomli_w

    return tomli_w.dumps(data)


def nonlinear_check(request: OptimiseRequest, catenary_file: Path, speed_kmh: float) -> dict:
    """The design in the virtual HIL with dropper slackening at `speed_kmh` (the case's iteration settings and
    f_max): its status and the converged span's statistics in the objective's band, the force low-passed at
    20 Hz (EN 50367, `lowpass_periodic`, as `pantohil run` and `pantohil fem-sim` report it)."""
    case = load_case(request.case_path, [*case_overrides(request, speed_kmh, catenary_file), "pfem.droppers=true"])
    t0 = time.perf_counter()
    result = run_loop(case)
    f = lowpass_periodic(result.force_N, case.dt_s, QUALITY_BAND_HZ)
    return {"status": result.status, "spans": result.spans, "std_N": float(f.std()), "max_N": float(f.max()),
            "min_N": float(f.min()), "f_max_hz": float(case.sections.hil.max_frequency_hz),
            "seconds": time.perf_counter() - t0}


def confirm_on_worker(request: OptimiseRequest, catenary_file: Path, speed_kmh: float) -> dict:
    """`nonlinear_check` as a Dask task, in a worker tuned for the operator build (`tune_worker_allocator`)."""
    tune_worker_allocator()
    return nonlinear_check(request, catenary_file, speed_kmh)


def _search(request: OptimiseRequest, problem, out: Path, client, progress: bool, log, deadline: float) -> tuple:
    """The Dask search until `deadline` (time.monotonic()): (evaluator, the extremes' bounds, why it stopped)."""
    make_raw = partial(problem.space.apply, problem.raw, problem.cat)
    with progress_bar(request.max_designs, f"optimise {request.vary}", "design", progress, leave=True) as bar:
        lowest = [np.inf]

        def on_new(row):
            bar.update(1)
            if row["result"]["feasible"]:
                lowest[0] = min(lowest[0], row["result"]["objective_N"])
                bar.set_postfix(best=f"{lowest[0]:.3f} N")

        evaluator = Evaluator(client, make_raw, problem.points, request.limits.min_dropper_length_m,
                              out / JOURNAL, request.max_designs, on_new, deadline)
        if evaluator.cache:
            bar.update(len(evaluator.cache))
            log(f"continuing: {len(evaluator.cache)} designs already in {out / JOURNAL}")
        nominal = evaluator.results([problem.x0])[0]
        if not nominal["feasible"]:
            raise InputError(f"{request.catenary_file}: the nominal design cannot be evaluated ({nominal['reason']})",
                             key="catenary")
        extremes = Extremes.of(nominal, request.extremes == "nominal")
        explore(evaluator, problem.bounds, request.explore)
        why = _descend(evaluator, request, problem, extremes, deadline)
        if why[-1] != BUDGET_SPENT:
            why += _compass(evaluator, request, problem, extremes, deadline)
        return evaluator, extremes, "; ".join(dict.fromkeys(why))


@contextmanager
def _share_of_time(evaluator: Evaluator, share: float, deadline: float):
    """Within the block, the evaluator sends no new design after `share` of the time left until `deadline`."""
    evaluator.deadline = time.monotonic() + share * max(0.0, deadline - time.monotonic())
    try:
        yield
    finally:
        evaluator.deadline = deadline


def _stopped(evaluator: Evaluator, share_spent: str) -> str:
    """Why a phase with a share of the time stopped: its share was spent, or the budget of designs was."""
    return share_spent if len(evaluator.cache) < evaluator.max_designs else BUDGET_SPENT


def _descend(evaluator: Evaluator, request: OptimiseRequest, problem, extremes: Extremes, deadline: float) -> list[str]:
    """The Gauss-Newton descents from the best designs so far (`--starts`), within DESCENT_SHARE of the time left;
    why each stopped."""
    why = []
    with _share_of_time(evaluator, DESCENT_SHARE, deadline):
        for x in starts(evaluator, request.starts, extremes):
            why.append(search(evaluator, x, problem.bounds, STEP[request.vary], extremes).rstrip("."))
            if why[-1] == BUDGET_SPENT:
                why[-1] = _stopped(evaluator, DESCENT_TIME_SPENT)
                break
    return why


def _compass(evaluator: Evaluator, request: OptimiseRequest, problem, extremes: Extremes, deadline: float) -> list[str]:
    """Compass searches down to COARSE_STEPS finite-difference steps, each from the design of least merit away from
    every design an earlier one passed through, within COARSE_SHARE of the time left (the objective has several
    minima: a search from the next start can find a lower one); then one from the best down to half a step. Why
    each stopped."""
    step = STEP[request.vary]
    visited: list[np.ndarray] = []
    why = []
    with _share_of_time(evaluator, COARSE_SHARE, deadline):
        start = least_merit(evaluator, extremes)
        while start is not None:
            why.append(polish(evaluator, start, problem.bounds, POLISH_STEPS * step, COARSE_STEPS * step, extremes,
                              visited))
            if why[-1] == BUDGET_SPENT:
                why[-1] = _stopped(evaluator, COARSE_TIME_SPENT)
                break
            start = least_merit(evaluator, extremes, visited, RESTART_STEPS * step)
    if len(evaluator.cache) >= evaluator.max_designs or time.monotonic() >= deadline:
        return [*why, BUDGET_SPENT]
    return [*why, polish(evaluator, least_merit(evaluator, extremes), problem.bounds, COARSE_STEPS * step, step / 2,
                         extremes)]


def run_optimise(request: OptimiseRequest, out: Path, scheduler: str | None = None, workers: int | None = None,
                 overwrite: bool = False, progress: bool = True, confirm: bool = True, log=print) -> dict:
    """`pantohil optimise`: search, confirm, write; the summary (also summary.json)."""
    t0 = time.perf_counter()
    deadline = time.monotonic() + 60.0 * request.max_minutes
    problem = prepare(request)
    out = Path(out)
    open_folder(out, request, overwrite)
    with dask_client(scheduler, workers) as client:
        evaluator, extremes, why = _search(request, problem, out, client, progress, log, deadline)
        t_search = time.perf_counter() - t0
        top = best(evaluator, extremes)
        nominal = evaluator.cache[design_key(problem.x0)]["result"]
        x_best = np.array(top["x"])
        optimised_raw = problem.space.apply(problem.raw, problem.cat, x_best)
        write_text_atomic(out / CATENARY_OUT, _toml(optimised_raw))
        write_text_atomic(out / CASE_OUT, _toml(written_case(request, problem, CATENARY_OUT)))
        load_case(out / CASE_OUT)  # the case written loads as `pantohil run` will load it
        rows = list(evaluator.cache.values())
        names = problem.space.variables(problem.cat)
        write_history(out / "history.csv", rows, names)
        plot_report(out / FIGURE, problem.cat, build_definition(optimised_raw), rows, nominal, top["result"])
        checks = {}
        if confirm:
            speed = problem.points[0].speed_kmh
            log(f"confirmation at {speed:g} km/h (virtual HIL, droppers slacken)")
            files = {"nominal": Path(request.catenary_file), "optimised": out / CATENARY_OUT}
            futures = client.map(confirm_on_worker, [request] * 2, list(files.values()), [speed] * 2, pure=False)
            checks = dict(zip(files, client.gather(futures), strict=True))
        n_workers = worker_count(client)
    summary = _summary(request, problem, names, nominal, top, why, evaluator, n_workers, t_search, checks, t0)
    summary["extremes"] = {"bounded_by": request.extremes, "max_N": extremes.max_N, "min_N": extremes.min_N}
    write_json_atomic(out / "summary.json", summary)
    return summary


def _reduction(nominal: dict, optimised: dict) -> dict:
    """The optimised design against the nominal one: std reduction [%], and max and min changes [N]."""
    return {"std_reduction_percent": 100.0 * (1.0 - optimised["std_N"] / nominal["std_N"]),
            "max_change_N": optimised["max_N"] - nominal["max_N"],
            "min_change_N": optimised["min_N"] - nominal["min_N"]}


def _summary(request, problem, names, nominal, top, why, evaluator, n_workers, t_search, checks, t0) -> dict:
    stats = ("std_N", "max_N", "min_N")
    speeds = []
    for n, o in zip(nominal["speeds"], top["result"]["speeds"], strict=True):
        speeds.append({"speed_kmh": n["speed_kmh"], "nominal": {k: n[k] for k in (*stats, "slack_pairs")},
                       "optimised": {k: o[k] for k in (*stats, "slack_pairs")}, **_reduction(n, o)})
    nonlinear = {k: v for k, v in checks.items()}
    if checks:
        nonlinear.update(_reduction(checks["nominal"], checks["optimised"]))
        nonlinear["hil_against_steady_state_percent"] = {
            k: 100.0 * (checks[k]["std_N"] / r["speeds"][0]["std_N"] - 1.0)
            for k, r in (("nominal", nominal), ("optimised", top["result"]))}
    return {"catenary_file": str(request.catenary_file), "case": str(request.case_path), "vary": request.vary,
            "variables": names, "nominal_x": [float(v) for v in problem.x0], "optimised_x": top["x"],
            "bounds": problem.bounds, "limits": asdict(request.limits),
            "objective": "std of the contact force, 0-20 Hz, of the PFEM steady state with dropper slackening (over "
                         "several speeds: root of the weighted mean variance)",
            "nominal_objective_N": nominal["objective_N"], "optimised_objective_N": top["result"]["objective_N"],
            "speeds": speeds, "nonlinear_confirmation": nonlinear, "stopped": why,
            "designs": {"in_journal": len(evaluator.cache), "evaluated_now": evaluator.evaluated,
                        "max_designs": request.max_designs, "max_minutes": request.max_minutes},
            "workers": n_workers, "timing": {"search_s": t_search, "wall_s": time.perf_counter() - t0},
            "files": [CATENARY_OUT, CASE_OUT, "history.csv", FIGURE, JOURNAL]}
