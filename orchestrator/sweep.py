"""`pantohil sweep`: a grid over case keys run as independent points on Dask, resumable.

A sweep file (TOML) names a case, the keys to sweep and, optionally, keys fixed for every point:

    [sweep]
    name = "speed_200_300"
    case = "../cases/asm_250.toml"   # relative to the sweep file; omitted: the built-in case
    kind = "run"                     # "run": a virtual HIL run per point; "direct": the closed form (Paper A)
    engine = "inprocess"             # kind "run": "inprocess" (default, the models without FMUs) or "fmu"
    point_plots = false              # kind "run": each point's run folder with its figures too (default false)
    [set]
    "hil.relaxation" = 0.1
    [grid]
    "run.speed_kmh" = { start = 200.0, stop = 300.0, num = 12 }   # or a list of values

Every combination of the grid values is a point. A point of kind "run" is a virtual HIL run in its own
run folder under points/: with the in-process engine, in the Dask worker itself; with the FMU engine,
`pantohil run --engine fmu` in a child process of the worker (the engine changes the time a point takes,
not its result: the sweep's hash leaves it out); a point of kind "direct" is the ASM closed
form, with the extra key `direct.second_pantograph_m` for a trailing pantograph (Paper A Fig. 17). The
results table (results.csv and results.parquet) is rewritten at most every RESULTS_EVERY_S while points
finish and at the end (rewriting it after each of a thousand quick points cost more than the points); a
restart with the same sweep and folder skips the points already in it.
"""
from __future__ import annotations

import contextlib
import csv
import ctypes
import hashlib
import itertools
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from datetime import datetime, UTC
from pathlib import Path

import numpy as np

from pantohil.models.case import SCHEMA, CaseError, load_case
from pantohil.models.input_files import InputFileError, load_toml
from pantohil.models.schema import FileSchema, coerce, param
from pantohil.models.storage import atomic_path

from .dask_engine import dask_client, run_tasks, tune_worker_allocator, worker_count
from .inprocess import ENGINES
from .report import write_json_atomic
from .run_folder import SUMMARY, read_summary

KINDS = ("run", "direct")
DIRECT_KEYS = ("direct.second_pantograph_m",)
STATS = ("status", "converged", "diverged", "spans", "mean_N", "std_N", "std_20hz_N", "max_N", "min_N",
         "trailing_std_N", "trailing_std_20hz_N", "second_std_N", "second_std_20hz_N", "wall_s", "finished_utc",
         "message")  # second_*: kind "run" of a case with a [second_pantograph]
DONE = ("converged", "completed", "span_limit", "diverged", "ok")
RESULTS_EVERY_S = 2.0  # results.csv/.parquet rewritten at most this often while points finish, and at the end
MAX_POINTS = 10_000  # points of a sweep, all grid keys together


class SweepFileError(CaseError):
    """A sweep file that cannot run; one line naming the key."""


@dataclass(frozen=True)
class SweepSection:
    """[sweep]: what the sweep runs and how its results are drawn."""

    name: str = param("", "1", "sweep name (empty: the file's name)")
    description: str = param("", "1", "free text")
    case: str = param("", "1", "case file, relative to the sweep file (empty: the built-in case)")
    kind: str = param("run", "1", "a virtual HIL run per point, or the closed form of Paper A (with the extra "
                                  "key `direct.second_pantograph_m` for a trailing pantograph)", choices=KINDS)
    engine: str = param("inprocess", "1", "kind run: the FMU path (`pantohil run --engine fmu`), or "
                                          "the FMUs' models without the FMI boundary; the same results",
                        choices=ENGINES)
    plot_x: str = param("", "1", "grid key on the plots' x axis (empty: the first grid key)")
    point_plots: bool = param(False, "1", "kind run: each point's run folder with its figures too")


SWEEP_FILE = FileSchema(
    "sweep file", {"sweep": SweepSection}, SweepFileError,
    free_sections={"set": "case keys fixed for every point: `\"section.key\" = value`",
                   "grid": "case keys to sweep: `\"section.key\" = [values]` or `{ start, stop, num [, log = "
                           "true] }`; every combination of the values is a point (at most 10000)"},
    reference="sweep-reference")


def _fail(path: Path, what: str, key: str | None = None):
    raise SweepFileError(f"sweep file {path}: {what}", key=key)


def _number(path: Path, key: str, what: str, v) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        _fail(path, f"grid key {key!r}: {what} must be a finite number (got {v!r})")
    return float(v)


def _values(path: Path, key: str, spec) -> list:
    if isinstance(spec, dict):
        unknown = set(spec) - {"start", "stop", "num", "log"}
        if unknown or not {"start", "stop", "num"} <= set(spec):
            _fail(path, f"grid key {key!r}: a range is {{ start, stop, num [, log] }}")
        num = spec["num"]
        if isinstance(num, bool) or not isinstance(num, int) or num < 1:
            _fail(path, f"grid key {key!r} has an empty range (num = {num!r})")
        if num > MAX_POINTS:
            _fail(path, f"grid key {key!r}: num = {num} is above the limit of {MAX_POINTS} points")
        start, stop = _number(path, key, "start", spec["start"]), _number(path, key, "stop", spec["stop"])
        if spec.get("log", False):
            if start <= 0 or stop <= 0:
                _fail(path, f"grid key {key!r}: a log range needs positive ends")
            return [float(v) for v in np.geomspace(start, stop, num)]
        return [float(v) for v in np.linspace(start, stop, num)]
    if isinstance(spec, list):
        if not spec:
            _fail(path, f"grid key {key!r} has an empty range ([])")
        if len(spec) > MAX_POINTS:
            _fail(path, f"grid key {key!r}: {len(spec)} values, above the limit of {MAX_POINTS} points")
        return list(spec)
    return [spec]


def _check_key(path: Path, key: str, kind: str, where: str) -> None:
    if key in DIRECT_KEYS:
        if kind != "direct":
            _fail(path, f"{where} key {key!r} needs kind = \"direct\"")
        return
    section, _, name = key.partition(".")
    if section not in SCHEMA or name not in SCHEMA[section]:
        _fail(path, f"{where} key {key!r} is not a case key (section.key, see docs/case-reference.md)")


def _toml_value(v) -> str:
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(float(v)) if isinstance(v, float) else str(v)


def load_sweep(path: Path) -> dict:
    """Parse and check a sweep file; every point's case is validated before anything runs."""
    path = Path(path)
    try:
        raw = load_toml(path, "sweep file")
    except InputFileError as exc:
        raise CaseError(str(exc)) from None
    try:
        v = SWEEP_FILE.validate(raw)
    except SweepFileError as exc:
        _fail(path, str(exc), exc.key)
    head = v["sweep"]
    kind = head["kind"]
    case = (path.parent / head["case"]).resolve() if head.get("case") else None
    if case is not None and not case.exists():
        _fail(path, f"sweep.case {head['case']!r}: {case} does not exist")
    grid = v["grid"]
    if not grid:
        _fail(path, "[grid] names no key to sweep")
    fixed = v["set"]
    for key in grid:
        _check_key(path, key, kind, "grid")
    for key in fixed:
        _check_key(path, key, kind, "set")
    values = {key: _values(path, key, spec) for key, spec in grid.items()}
    total = math.prod(len(v) for v in values.values())
    if total > MAX_POINTS:
        _fail(path, f"the grid has {total} points, above the limit of {MAX_POINTS} points")
    plot_x = head["plot_x"] or next(iter(grid))
    if plot_x not in grid:
        _fail(path, f"sweep.plot_x {plot_x!r} is not a grid key")
    points = []
    for combo in itertools.product(*values.values()):
        assign = dict(zip(values, combo, strict=False))
        overrides = [f"{k}={_toml_value(v)}" for k, v in {**fixed, **assign}.items() if k not in DIRECT_KEYS]
        extra = {k: v for k, v in {**fixed, **assign}.items() if k in DIRECT_KEYS}
        try:
            load_case(case, overrides)
        except CaseError as exc:
            _fail(path, f"point {assign}: {exc}")
        digest = hashlib.sha1(json.dumps([overrides, extra], sort_keys=True).encode()).hexdigest()[:10]
        points.append({"id": f"p{len(points):03d}-{digest}", "assign": assign, "overrides": overrides, "extra": extra})
    definition = {"name": head["name"] or path.stem, "kind": kind, "case": str(case) if case else None,
                  "set": fixed, "grid": values, "plot_x": plot_x}
    definition["hash"] = hashlib.sha1(json.dumps(definition, sort_keys=True, default=str).encode()).hexdigest()[:16]
    definition["engine"] = head["engine"]  # not hashed: the same results
    definition["point_plots"] = head["point_plots"]  # not hashed either
    return {"definition": definition, "points": points}


def _engine(path: Path, engine: str) -> str:
    """An engine given beside the sweep file, checked against [sweep] engine's declaration."""
    try:
        return coerce(SWEEP_FILE.keys("sweep")["engine"], engine, SweepFileError)
    except SweepFileError as exc:
        _fail(path, str(exc), exc.key)


def sweep_point(task: dict) -> dict:
    """One point, on a Dask worker: a `pantohil run` in a child process, or the closed form."""
    tune_worker_allocator()
    t0 = time.perf_counter()
    if task["kind"] == "direct":
        from .direct import direct_solution

        case = load_case(task["case"], task["overrides"])
        spacing = task["extra"].get("direct.second_pantograph_m")
        res = direct_solution(case, spacing)
        out = {"status": "ok", "converged": True, "diverged": False, "mean_N": res["single"]["mean_N"],
               "std_N": res["single"]["std_N"], "std_20hz_N": res["single"]["std_20hz_N"], "message": ""}
        if spacing is not None:
            two = res["two_pantographs"]
            out.update(trailing_std_N=two["trailing_std_N"], trailing_std_20hz_N=two["trailing_std_20hz_N"])
    else:
        folder = Path(task["folder"])
        if folder.exists():  # a point interrupted earlier starts afresh
            shutil.rmtree(folder)
        if task.get("engine", "inprocess") == "inprocess":
            _run_in_worker(task, folder)
        else:
            _run_in_child(task, folder)
        s = read_summary(folder)
        cf = s.get("contact_force", {})
        out = {"status": s["status"], "converged": s["converged"], "diverged": s["diverged"], "spans": s["spans"],
               "mean_N": cf.get("mean_N"), "std_N": cf.get("std_N"),
               "std_20hz_N": cf.get("filtered_20hz", {}).get("std_N"), "max_N": cf.get("max_N"),
               "min_N": cf.get("min_N"), "message": s["message"]}
        second = s.get("second_pantograph", {}).get("contact_force", {})
        out.update(second_std_N=second.get("std_N"), second_std_20hz_N=second.get("filtered_20hz", {}).get("std_N"))
    out["wall_s"] = time.perf_counter() - t0
    out["finished_utc"] = datetime.now(UTC).isoformat(timespec="seconds")
    return out


def _run_in_worker(task: dict, folder: Path) -> None:
    """A point with the in-process engine, run in the worker itself: no interpreter to start and nothing
    to import per point; run.mcap is written inline (a Dask worker may not start processes)."""
    from .hil_run import run_case

    run_case(load_case(task["case"], task["overrides"]), folder, progress=False, engine="inprocess",
             log_writer="inline", plots=task.get("point_plots", False))


def _run_in_child(task: dict, folder: Path) -> None:
    """A point with the FMU engine, as `pantohil run` in a child process: the FMUs it loads (each with the
    Python of its own resources on sys.path) leave with the process."""
    cmd = [sys.executable, "-m", "pantohil.orchestrator.cli", "run"]
    cmd += [task["case"]] if task["case"] else []
    for o in task["overrides"]:
        cmd += ["--set", o]
    cmd += ["--out", str(folder), "--quiet", "--engine", task["engine"]]
    cmd += [] if task.get("point_plots", False) else ["--no-plots"]
    proc = subprocess.run(cmd, capture_output=True, text=True, preexec_fn=_end_with_parent)
    if proc.returncode not in (0, 1) or not (folder / SUMMARY).exists():
        lines = (proc.stderr or proc.stdout).strip().splitlines()
        raise RuntimeError(lines[-1] if lines else f"pantohil run exited with {proc.returncode}")


PR_SET_PDEATHSIG = 1


def _end_with_parent() -> None:
    """preexec of a point's `pantohil run`: the kernel sends it SIGTERM when the worker thread that waits
    for it ends (the worker dies with a killed sweep, SIGKILL included), so that it stops at a step
    boundary with its record instead of running on without anyone to read it."""
    with contextlib.suppress(OSError, AttributeError):  # not Linux: the point runs to its end
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)


def _read_results(path: Path) -> list[dict]:
    if not path.exists():
        return []
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _write_results(out: Path, rows: list[dict], columns: list[str]) -> None:
    import pandas as pd

    rows = sorted(rows, key=lambda r: r["point"])
    with atomic_path(out / "results.csv") as part, open(part, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=columns, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({c: ("" if r.get(c) is None else r.get(c)) for c in columns})
    frame = pd.read_csv(out / "results.csv")
    with atomic_path(out / "results.parquet") as part:
        frame.to_parquet(part, index=False)


def _check_same_sweep(marker: Path, out: Path, definition: dict) -> None:
    """Refuse a sweep folder whose sweep.json holds another sweep (a different hash)."""
    if marker.exists():
        previous = json.loads(marker.read_text())
        if previous.get("hash") != definition["hash"]:
            raise CaseError(f"sweep folder {out} holds the results of another sweep ({previous.get('name')}); "
                            "use a new folder")


def _status_counts(rows: list[dict]) -> dict:
    """How many result rows have each status, in the order the statuses first appear."""
    statuses = {}
    for r in rows:
        statuses[r["status"]] = statuses.get(r["status"], 0) + 1
    return statuses


def _sweep_as_run(sweep_path: Path, engine: str | None, point_plots: bool | None) -> tuple[dict, list]:
    """The sweep's definition and points, with the command line's engine and point_plots in place of the
    sweep file's."""
    sweep = load_sweep(sweep_path)
    definition = sweep["definition"]
    if engine is not None:
        definition["engine"] = _engine(Path(sweep_path), engine)
    if point_plots is not None:
        definition["point_plots"] = point_plots
    pair = any(o.startswith("second_pantograph.") for p in sweep["points"] for o in p["overrides"])
    if definition["kind"] == "run" and definition["engine"] == "inprocess" and pair:
        _fail(Path(sweep_path), 'two pantographs run as FMUs: set engine = "fmu" (or --engine fmu)', "sweep.engine")
    return definition, sweep["points"]


def run_sweep(sweep_path: Path, out: Path, scheduler: str | None = None, workers: int | None = None,
              progress: bool = True, log=print, engine: str | None = None, point_plots: bool | None = None) -> dict:
    """`pantohil sweep`: run the points of a sweep file on Dask, skip those done, write results. `engine`
    ("inprocess" or "fmu") and `point_plots` replace the sweep file's sweep.engine and sweep.point_plots."""
    definition, points = _sweep_as_run(sweep_path, engine, point_plots)
    out = Path(out)
    marker = out / "sweep.json"
    _check_same_sweep(marker, out, definition)
    grid_keys = list(definition["grid"])
    columns = ["point"] + grid_keys + list(STATS)
    existing = {r["point"]: r for r in _read_results(out / "results.csv")}
    done = {pid for pid, r in existing.items() if r.get("status") in DONE}
    todo = [p for p in points if p["id"] not in done]
    rows = [existing[p["id"]] for p in points if p["id"] in done]
    if todo:
        n_workers, wall, interrupted = _run_points(definition, todo, rows, out, columns,
                                                   (scheduler, workers, progress, log))
    else:  # a finished sweep run again: nothing to run, no cluster to start
        out.mkdir(parents=True, exist_ok=True)
        write_json_atomic(marker, definition)
        log(f"{definition['name']}: all {len(points)} points already done")
        n_workers, wall, interrupted = 0, 0.0, None
    if rows:
        _write_results(out, rows, columns)
    figures = plot_sweep(out, rows, definition) if rows else []
    statuses = _status_counts(rows)
    summary = {"name": definition["name"], "kind": definition["kind"], "engine": definition["engine"],
               "point_plots": definition["point_plots"],
               "points": len(points), "skipped_done": len(done), "ran": len(rows) - len(done), "statuses": statuses,
               "workers": n_workers, "scheduler": scheduler or "LocalCluster", "wall_s": wall,
               "interrupted": interrupted is not None, "figures": figures}
    write_json_atomic(out / "summary.json", summary)
    if interrupted is not None:
        raise interrupted
    return summary


def _run_points(definition: dict, todo: list, rows: list, out: Path, columns: list, how: tuple):
    """Run the points not done on Dask, appending their rows (results.csv rewritten as each finishes);
    (workers, wall time, the KeyboardInterrupt that stopped it or None)."""
    scheduler, workers, progress, log = how
    points_total = len(todo) + len(rows)
    marker = out / "sweep.json"
    with dask_client(scheduler, workers) as client:  # an unreachable scheduler fails before anything is written
        out.mkdir(parents=True, exist_ok=True)
        write_json_atomic(marker, definition)
        n_workers = worker_count(client)
        log(f"{definition['name']}: {points_total} points, {len(rows)} already done, {len(todo)} to run "
            f"on {n_workers} workers")
        tasks = [{"kind": definition["kind"], "engine": definition["engine"], "case": definition["case"],
                  "point_plots": definition["point_plots"], "overrides": p["overrides"],
                  "extra": p["extra"], "folder": str((out / "points" / p["id"]).resolve())} for p in todo]
        by_task = {id(t): p for t, p in zip(tasks, todo, strict=False)}
        t0 = time.perf_counter()
        written = [time.monotonic()]

        def keep(task, result, error):
            p = by_task[id(task)]
            row = {"point": p["id"], **p["assign"]}
            if error:
                row.update(status="error", message=error.splitlines()[0][:300],
                           finished_utc=datetime.now(UTC).isoformat(timespec="seconds"))
            else:
                row.update(result)
            rows.append(row)
            if time.monotonic() - written[0] >= RESULTS_EVERY_S:  # the whole table each time: not after every point
                _write_results(out, rows, columns)
                written[0] = time.monotonic()

        interrupted = None
        try:
            keys = [f"sweep-{definition['hash']}-{p['id']}-{os.getpid()}" for p in todo]
            run_tasks(client, sweep_point, tasks, keys, keep, progress, desc=definition["name"])
        except KeyboardInterrupt as exc:  # kept, with its signal, for after the results are written
            interrupted = exc
        wall = time.perf_counter() - t0
    return n_workers, wall, interrupted


def plot_sweep(out: Path, rows: list[dict], definition: dict) -> list[str]:
    """Standard deviation of the contact force against the swept key (Paper B Fig. 12, Paper A Fig. 17)."""
    from .report import plot_sweep_std

    x = definition["plot_x"]
    others = [k for k in definition["grid"] if k != x]

    def num(v):
        try:
            return float(v)
        except (TypeError, ValueError):
            return math.nan

    trailing = definition["kind"] == "direct" and "direct.second_pantograph_m" in definition["grid"]
    second = definition["kind"] == "run" and "second_pantograph.spacing_m" in definition["grid"]
    column = "trailing_std_N" if trailing else "second_std_20hz_N" if second else "std_20hz_N"
    series = {}
    for r in rows:
        label = ", ".join(f"{k} = {r.get(k)}" for k in others)
        series.setdefault(label, []).append(r)
    curves = []
    for label, rs in sorted(series.items(), key=lambda kv: [num(kv[1][0].get(k)) for k in others]):
        rs = sorted(rs, key=lambda r: num(r.get(x)))
        xs = np.array([num(r.get(x)) for r in rs])
        ys = np.array([num(r.get(column)) for r in rs])
        ok = np.array([r.get("status") in DONE for r in rs])
        curves.append((label, xs, ys, ok))
    ylabel = ("std of the trailing pantograph's contact force [N]" if trailing else
              "std of the second pantograph's contact force, 20 Hz [N]" if second else
              "std of the contact force, 20 Hz [N]")
    name = "std_vs_" + x.replace(".", "_") + ".png"
    plot_sweep_std(out / name, curves, x, ylabel, definition["name"])
    return [name]
