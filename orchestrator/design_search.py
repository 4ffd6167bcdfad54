"""The search of `pantohil optimise`: designs evaluated on Dask (the engine of sweeps: a LocalCluster, or a scheduler's
address), each evaluation kept in a journal (evaluations.jsonl, one whole line per design) so that an interrupted
optimisation resumes where it stopped, and a bounded Gauss-Newton search over the design variables.

The contact force's standard deviation is the norm of the force's deviation from its mean, so the objective is a sum
of squares: scipy's trust-region least squares (`least_squares`, method "trf", within the bounds) on the residuals
(f - mean f) sqrt(w_s / (N sum w)) of every speed, with the Jacobian from one-sided differences of fixed steps, its
columns evaluated in parallel. Bounds on the max and min (the nominal design's, Paper D Table 2's pattern) enter as
a quadratic penalty on how far a design goes beyond them (a residual per bound and speed), and the design kept is
the best one evaluated that stays within them. A design that cannot be built gives large residuals: the trust region
shrinks away from it. The objective has several minima over the dropper positions (a coarse grid over Paper A's
stitched catenary at 300 km/h finds minima 4 % apart), so the search first evaluates a scrambled Sobol sample of the
bounds in one parallel batch, descends from the best designs found (the nominal one among them when it ranks), and
ends with a compass search from the best design within the bounds (`polish`). It is deterministic (a seeded sample),
so a resumed one retraces its steps from the journal.
"""
from __future__ import annotations

import json
import time
from contextlib import suppress
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import qmc

from pantohil.models.catenary.pfem.design_evaluation import SpeedPoint, evaluate_design

from .dask_engine import tune_worker_allocator

JOURNAL = "evaluations.jsonl"
BUDGET_SPENT = "the budget (--max-designs or --max-minutes) was spent"
INFEASIBLE_RESIDUAL_N = 1e3  # per sample: far above any feasible design's deviation
# 1 N beyond a bound costs as much as 100 N^2 of variance: where the std falls by less than 1 N per N of the bound
# given up, the descent settles within about 0.1 N of the penalty's bound, which sits EXTREME_MARGIN_N inside the
# bound itself, so that designs it ends among are within the bounds. (A stiffer penalty traps the descent: the
# max and min of a sampled force are not smooth in the design.)
EXTREME_PENALTY = 10.0
EXTREME_MARGIN_N = 0.1
# the compass search's merit: the objective plus this many N per N beyond a bound (an exact penalty: a design
# beyond a bound ranks after one within it unless it lowers the std by ten times its excess)
POLISH_PENALTY = 10.0


def evaluate_on_worker(raw: dict, points: list[SpeedPoint], min_dropper_length_m: float) -> dict:
    """`evaluate_design` as a Dask task, its force kept, in a worker whose allocator is tuned for the operator
    build's large arrays (`tune_worker_allocator`: 11 s a design instead of 17-22 s on the project's VM)."""
    tune_worker_allocator()
    return evaluate_design(raw, points, min_dropper_length_m, keep_force=True)


class BudgetSpent(Exception):
    """The number of designs allowed was evaluated, or the time allowed is up."""


def design_key(x: np.ndarray) -> str:
    """A design's identity in the journal: its variables to 1e-9 m."""
    return ",".join(f"{v:.9f}" for v in np.asarray(x, dtype=float))


def read_journal(path: Path) -> dict[str, dict]:
    """The evaluations of an earlier run by design key; a torn last line (an interrupted write) is skipped."""
    done: dict[str, dict] = {}
    if not path.exists():
        return done
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(row, dict) and isinstance(row.get("key"), str) and isinstance(row.get("result"), dict):
            done[row["key"]] = row
    return done


@dataclass
class Evaluator:
    """Designs to results, through the cache and the journal first, then Dask; counts what it evaluated now."""

    client: object
    make_raw: object  # x -> the design's catenary TOML (dict)
    points: list[SpeedPoint]
    min_dropper_length_m: float
    journal: Path
    max_designs: int
    on_new: object = None  # called with (row) after each new evaluation (progress, log)
    deadline: float = float("inf")  # time.monotonic() after which no new design is sent
    cache: dict = field(default_factory=dict)
    evaluated: int = 0

    def __post_init__(self):
        self.cache.update(read_journal(self.journal))

    def results(self, xs: list[np.ndarray]) -> list[dict]:
        """The evaluation of each design (journal or Dask); BudgetSpent once max_designs are in the journal or
        past the deadline."""
        keys = [design_key(x) for x in xs]
        todo = [(k, x) for k, x in dict(zip(keys, xs, strict=True)).items() if k not in self.cache]
        if todo and (len(self.cache) + len(todo) > self.max_designs or time.monotonic() > self.deadline):
            raise BudgetSpent
        if todo:
            futures = self.client.map(evaluate_on_worker, [self.make_raw(x) for _, x in todo],
                                      [self.points] * len(todo), [self.min_dropper_length_m] * len(todo), pure=False)
            for (k, x), result in zip(todo, self.client.gather(futures), strict=True):
                row = {"key": k, "x": [float(v) for v in x], "index": len(self.cache), "result": result}
                with open(self.journal, "a", encoding="utf-8") as fh:
                    fh.write(json.dumps(row) + "\n")
                self.cache[k] = row
                self.evaluated += 1
                if self.on_new is not None:
                    self.on_new(row)
        return [self.cache[k]["result"] for k in keys]


@dataclass(frozen=True)
class Extremes:
    """Bounds on each speed's max and min force [N] (the nominal design's); None: no bounds."""

    max_N: tuple[float, ...] | None = None
    min_N: tuple[float, ...] | None = None

    @classmethod
    def of(cls, nominal: dict, bounded: bool) -> Extremes:
        """The nominal result's max and min, or no bounds."""
        if not bounded:
            return cls()
        return cls(tuple(s["max_N"] for s in nominal["speeds"]), tuple(s["min_N"] for s in nominal["speeds"]))

    def excess_N(self, result: dict, margin_N: float = 0.0) -> np.ndarray:
        """How far each speed's max and min go beyond the bounds drawn `margin_N` inside [N] (0 within them);
        [] without bounds."""
        if self.max_N is None:
            return np.zeros(0)
        return np.array([[max(0.0, s["max_N"] - hi + margin_N), max(0.0, lo + margin_N - s["min_N"])]
                         for s, hi, lo in zip(result["speeds"], self.max_N, self.min_N, strict=True)]).ravel()

    def hold(self, result: dict) -> bool:
        """The design is feasible and its max and min are within the bounds."""
        return result["feasible"] and not np.any(self.excess_N(result) > 0.0)


def residuals(result: dict, points: list[SpeedPoint], extremes: Extremes = Extremes()) -> np.ndarray:
    """(f - mean f) sqrt(w / (N sum w)) over the speeds: its norm squared is the weighted mean variance; then
    the penalty of going beyond the extremes' bounds."""
    total = sum(p.weight for p in points)
    n_extra = 0 if extremes.max_N is None else 2 * len(points)
    if not result["feasible"]:
        return np.full(sum(p.settings.samples_per_span for p in points) + n_extra, INFEASIBLE_RESIDUAL_N)
    parts = []
    for p, s in zip(points, result["speeds"], strict=True):
        f = np.asarray(s["force_N"])
        parts.append((f - f.mean()) * np.sqrt(p.weight / (len(f) * total)))
    weights = np.repeat([np.sqrt(p.weight / total) for p in points], 2) if n_extra else np.zeros(0)
    parts.append(EXTREME_PENALTY * weights * extremes.excess_N(result, EXTREME_MARGIN_N))
    return np.concatenate(parts)


def cost(result: dict, points: list[SpeedPoint], extremes: Extremes) -> float:
    """What the descent minimises: the weighted mean variance and the extremes' penalty [N^2]."""
    return float(np.sum(residuals(result, points, extremes) ** 2))


def merit(result: dict, extremes: Extremes = Extremes()) -> float:
    """What the compass search minimises [N]: the objective plus POLISH_PENALTY times how far the max and min go
    beyond their bounds; inf for a design that cannot be built."""
    if not result["feasible"]:
        return np.inf
    return float(result["objective_N"] + POLISH_PENALTY * np.sum(extremes.excess_N(result)))


def search(evaluator: Evaluator, x0: np.ndarray, bounds: list[tuple[float, float]], step: float,
           extremes: Extremes = Extremes(), relative_tolerance: float = 1e-3) -> str:
    """Bounded least squares from x0 until the cost changes by less than `relative_tolerance` or the budget is
    spent; returns why it stopped."""
    lo, hi = (np.array(b, dtype=float) for b in zip(*bounds, strict=True))
    points = evaluator.points

    def fun(x):
        return residuals(evaluator.results([x])[0], points, extremes)

    def jac(x):
        steps = np.where(x + step <= hi, step, -step)
        trial = [x.copy() for _ in x]
        for i, t in enumerate(trial):
            t[i] += steps[i]
        r0, *rs = (residuals(r, points, extremes) for r in evaluator.results([x, *trial]))
        return np.column_stack([(r - r0) / h for r, h in zip(rs, steps, strict=True)])

    x0 = np.clip(x0, lo, hi)
    # a step shorter than the finite-difference step is below what the Jacobian resolves: the descent stops there
    # (along a bound's penalty it would otherwise creep on in steps of millimetres)
    xtol = max(1e-4, step / max(float(np.linalg.norm(x0)), step))
    try:
        out = least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale=10 * step,
                            ftol=relative_tolerance, xtol=xtol, gtol=1e-8)
    except BudgetSpent:
        return BUDGET_SPENT
    return out.message


def polish(evaluator: Evaluator, x0: np.ndarray, bounds: list[tuple[float, float]], step: float, smallest: float,
           extremes: Extremes = Extremes(), visited: list | None = None) -> str:
    """A compass search from x0 on the merit (`merit`: the objective, a design beyond the extremes' bounds charged
    POLISH_PENALTY N per N of excess): each poll evaluates x +- h along every variable in one parallel batch and
    moves to the design of least merit if that is lower, or halves h; it ends when h falls below `smallest` or the
    budget is spent. It follows a bound the descent's smooth penalty cannot (the max and min of a sampled force
    jump as the design moves), from a start just beyond it too, and its first steps are long enough to leave a
    local minimum the descent ended in. Appends the designs it moves through to `visited`."""
    visited = [] if visited is None else visited
    lo, hi = (np.array(b, dtype=float) for b in zip(*bounds, strict=True))
    x = np.asarray(x0, dtype=float)
    fx = merit(evaluator.results([x])[0], extremes)
    h = step
    visited.append(x)
    try:
        while h >= smallest:
            trial = []
            for i in range(len(x)):
                for sign in (1.0, -1.0):
                    t = x.copy()
                    t[i] = np.clip(t[i] + sign * h, lo[i], hi[i])
                    if not np.allclose(t, x) and not any(np.allclose(t, u) for u in trial):
                        trial.append(t)
            scored = [(merit(r, extremes), i) for i, r in enumerate(evaluator.results(trial))]
            if scored and min(scored)[0] < fx:
                fx, i = min(scored)
                x = trial[i]
                visited.append(x)
            else:
                h /= 2
    except BudgetSpent:
        return BUDGET_SPENT
    return f"the compass search's step fell below {smallest:g} m"


def explore(evaluator: Evaluator, bounds: list[tuple[float, float]], count: int, seed: int = 34) -> None:
    """Evaluate `count` designs of a scrambled Sobol sample of the bounds, in one batch."""
    if count <= 0:
        return
    lo, hi = np.array(bounds, dtype=float).T
    sample = qmc.Sobol(len(bounds), scramble=True, seed=seed).random_base2(int(np.ceil(np.log2(count))))[:count]
    with suppress(BudgetSpent):
        evaluator.results(list(qmc.scale(sample, lo, hi)))


def starts(evaluator: Evaluator, count: int, extremes: Extremes = Extremes()) -> list[np.ndarray]:
    """The `count` feasible designs of the lowest descent cost evaluated so far (the nominal one among them when
    it ranks), best first: the descents' starting points."""
    rows = sorted((r for r in evaluator.cache.values() if r["result"]["feasible"]),
                  key=lambda r: cost(r["result"], evaluator.points, extremes))
    out: list[np.ndarray] = []
    for r in rows:
        if len(out) >= count:
            break
        if not any(np.allclose(r["x"], x) for x in out):
            out.append(np.array(r["x"]))
    return out


def least_merit(evaluator: Evaluator, extremes: Extremes = Extremes(), away_from: list[np.ndarray] = (),
                distance: float = 0.0) -> np.ndarray | None:
    """The evaluated design of least `merit` at least `distance` (Euclidean, in the variables' units) from every
    design of `away_from` (a compass search's start); None if there is none that can be built."""
    rows = [r for r in evaluator.cache.values() if r["result"]["feasible"]
            and all(np.linalg.norm(np.asarray(r["x"]) - np.asarray(a)) >= distance for a in away_from)]
    return np.array(min(rows, key=lambda r: merit(r["result"], extremes))["x"]) if rows else None


def best(evaluator: Evaluator, extremes: Extremes = Extremes()) -> dict | None:
    """The design of the lowest objective among all evaluated that is feasible and within the extremes' bounds
    (None: none is)."""
    rows = [r for r in evaluator.cache.values() if extremes.hold(r["result"])]
    return min(rows, key=lambda r: r["result"]["objective_N"]) if rows else None
