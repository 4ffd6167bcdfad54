"""The search of `pantohil optimise`: designs evaluated on Dask (the engine of sweeps: a LocalCluster, or a
scheduler's address), each evaluation kept in a journal (evaluations.jsonl, one whole line per design) so that an
interrupted optimisation resumes where it stopped, and a bounded Gauss-Newton search over the design variables.

The contact force's standard deviation is the norm of the force's deviation from its mean, so the objective is
a sum of squares: scipy's trust-region least squares (`least_squares`, method "trf", within the bounds) on the
residuals (f - mean f) sqrt(w_s / (N sum w)) of every speed, with the Jacobian from one-sided differences of
fixed steps, its columns evaluated in parallel. A design that cannot be built gives large residuals: the trust
region shrinks away from it. The objective has several minima over the dropper positions (a coarse grid over
Paper A's stitched catenary at 300 km/h finds minima 4 % apart), so the search first evaluates a scrambled Sobol
sample of the bounds in one parallel batch and then descends from the best few designs found, the nominal among
them. It is deterministic (a seeded sample), so a resumed one retraces its steps from the journal.
"""
from __future__ import annotations

import json
from contextlib import suppress
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import qmc

from pantohil.models.catenary.pfem.design_evaluation import SpeedPoint, evaluate_design

JOURNAL = "evaluations.jsonl"
INFEASIBLE_RESIDUAL_N = 1e3  # per sample: far above any feasible design's deviation


class BudgetSpent(Exception):
    """The number of designs allowed was evaluated."""


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
    cache: dict = field(default_factory=dict)
    evaluated: int = 0

    def __post_init__(self):
        self.cache.update(read_journal(self.journal))

    def results(self, xs: list[np.ndarray]) -> list[dict]:
        """The evaluation of each design (journal or Dask); BudgetSpent once max_designs are in the journal."""
        keys = [design_key(x) for x in xs]
        todo = [(k, x) for k, x in dict(zip(keys, xs, strict=True)).items() if k not in self.cache]
        if todo and len(self.cache) + len(todo) > self.max_designs:
            raise BudgetSpent
        if todo:
            futures = self.client.map(evaluate_design, [self.make_raw(x) for _, x in todo],
                                      [self.points] * len(todo), [self.min_dropper_length_m] * len(todo),
                                      [True] * len(todo), pure=False)
            for (k, x), result in zip(todo, self.client.gather(futures), strict=True):
                row = {"key": k, "x": [float(v) for v in x], "index": len(self.cache), "result": result}
                with open(self.journal, "a", encoding="utf-8") as fh:
                    fh.write(json.dumps(row) + "\n")
                self.cache[k] = row
                self.evaluated += 1
                if self.on_new is not None:
                    self.on_new(row)
        return [self.cache[k]["result"] for k in keys]


def residuals(result: dict, points: list[SpeedPoint]) -> np.ndarray:
    """(f - mean f) sqrt(w / (N sum w)) over the speeds: its norm squared is the weighted mean variance."""
    total = sum(p.weight for p in points)
    if not result["feasible"]:
        return np.full(sum(p.settings.samples_per_span for p in points), INFEASIBLE_RESIDUAL_N)
    parts = []
    for p, s in zip(points, result["speeds"], strict=True):
        f = np.asarray(s["force_N"])
        parts.append((f - f.mean()) * np.sqrt(p.weight / (len(f) * total)))
    return np.concatenate(parts)


def search(evaluator: Evaluator, x0: np.ndarray, bounds: list[tuple[float, float]], step: float,
           relative_tolerance: float = 1e-3) -> str:
    """Bounded least squares from x0 until the cost changes by less than `relative_tolerance` or the budget is
    spent; returns why it stopped."""
    lo, hi = (np.array(b, dtype=float) for b in zip(*bounds, strict=True))
    points = evaluator.points

    def fun(x):
        return residuals(evaluator.results([x])[0], points)

    def jac(x):
        steps = np.where(x + step <= hi, step, -step)
        trial = [x.copy() for _ in x]
        for i, t in enumerate(trial):
            t[i] += steps[i]
        r0, *rs = (residuals(r, points) for r in evaluator.results([x, *trial]))
        return np.column_stack([(r - r0) / h for r, h in zip(rs, steps, strict=True)])

    try:
        out = least_squares(fun, np.clip(x0, lo, hi), jac=jac, bounds=(lo, hi), method="trf", x_scale=10 * step,
                            ftol=relative_tolerance, xtol=1e-4, gtol=1e-8)
    except BudgetSpent:
        return "the design budget (--max-designs) was spent"
    return out.message


def explore(evaluator: Evaluator, bounds: list[tuple[float, float]], count: int, seed: int = 34) -> None:
    """Evaluate `count` designs of a scrambled Sobol sample of the bounds, in one batch."""
    if count <= 0:
        return
    lo, hi = np.array(bounds, dtype=float).T
    sample = qmc.Sobol(len(bounds), scramble=True, seed=seed).random_base2(int(np.ceil(np.log2(count))))[:count]
    with suppress(BudgetSpent):
        evaluator.results(list(qmc.scale(sample, lo, hi)))


def starts(evaluator: Evaluator, x0: np.ndarray, count: int) -> list[np.ndarray]:
    """The nominal design and the best feasible ones evaluated so far, at most `count` in all (fewer where the
    sample found no other design that can be built: heights far from the nominal ones compress droppers)."""
    rows = sorted((r for r in evaluator.cache.values() if r["result"]["feasible"]),
                  key=lambda r: r["result"]["objective_N"])
    out = [np.asarray(x0, dtype=float)]
    for r in rows:
        if len(out) >= count:
            break
        if not any(np.allclose(r["x"], x) for x in out):
            out.append(np.array(r["x"]))
    return out


def best(evaluator: Evaluator) -> dict | None:
    """The feasible design of the lowest objective among all evaluated (None: none was feasible)."""
    rows = [r for r in evaluator.cache.values() if r["result"]["feasible"]]
    return min(rows, key=lambda r: r["result"]["objective_N"]) if rows else None
