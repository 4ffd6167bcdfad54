"""The compass searches of `pantohil optimise` (orchestrator/design_search.py `merit`, `polish`, `least_merit`) on
a closed-form objective with two basins and a bound on the min, evaluated in process: the search's logic, apart
from the catenary designs it is run on (tests/system/test_optimise_cli.py runs it on those)."""
from __future__ import annotations

import numpy as np
import pytest
from pantohil.orchestrator.design_search import (POLISH_PENALTY, Extremes, design_key, least_merit, merit, polish)

BOUNDS = [(0.0, 10.0), (0.0, 10.0)]
SHALLOW, DEEP = np.array([2.0, 2.0]), np.array([8.0, 6.0])
MIN_BOUND_N = 100.0


def _result(x: np.ndarray) -> dict:
    """Two quadratic basins, the deeper one (std 5 N at DEEP) cut by the min's bound: the min falls below 100 N
    beyond x_0 = 7.5, so that the best design within the bounds is at x_0 = 7.5 (std 5.25 N); the shallow basin's
    floor is 8 N."""
    std = min(8.0 + np.sum((x - SHALLOW) ** 2), 5.0 + np.sum((x - DEEP) ** 2))
    return {"feasible": True, "objective_N": float(std),
            "speeds": [{"max_N": 200.0, "min_N": float(MIN_BOUND_N + 7.5 - x[0])}]}


class _Designs:
    """What the searches ask of an Evaluator: results by design, kept in `cache` by design key."""

    def __init__(self):
        self.cache: dict[str, dict] = {}

    def results(self, xs):
        for x in xs:
            self.cache.setdefault(design_key(x), {"x": [float(v) for v in x], "result": _result(np.asarray(x))})
        return [self.cache[design_key(x)]["result"] for x in xs]


EXTREMES = Extremes(max_N=(200.0,), min_N=(MIN_BOUND_N,))


def test_the_merit_charges_the_excess_beyond_a_bound():
    within, beyond = _result(np.array([7.0, 6.0])), _result(np.array([8.0, 6.0]))
    assert merit(within, EXTREMES) == pytest.approx(6.0)
    assert merit(beyond, EXTREMES) == pytest.approx(5.0 + POLISH_PENALTY * 0.5)
    assert merit({"feasible": False}, EXTREMES) == np.inf


def test_a_compass_search_follows_the_bound_and_a_restart_finds_the_deeper_basin():
    """From the shallow basin the search ends at its floor (8 N); the design of least merit 2 units (twice the first
    step) from every design it passed is a start whose search ends on the min's bound in the deep basin, at
    x_0 = 7.5 (5.25 N), not beyond it (where the deep basin's own floor, 5 N, lies)."""
    designs = _Designs()
    visited: list[np.ndarray] = []
    why = polish(designs, np.array([1.0, 1.0]), BOUNDS, 1.0, 0.01, EXTREMES, visited)
    assert "fell below" in why
    assert np.allclose(visited[-1], SHALLOW, atol=0.01)
    for x in ([8.0, 6.0], [9.0, 9.0], [5.0, 8.0]):  # a first sample's designs
        designs.results([np.array(x, dtype=float)])
    start = least_merit(designs, EXTREMES, visited, 2.0)  # twice the first step, as optimise_run.py's restarts
    assert np.all([np.linalg.norm(start - v) >= 2.0 for v in visited])
    end: list[np.ndarray] = []
    polish(designs, start, BOUNDS, 1.0, 0.01, EXTREMES, end)
    assert end[-1][0] == pytest.approx(7.5, abs=0.01) and end[-1][1] == pytest.approx(6.0, abs=0.01)
    assert EXTREMES.hold(_result(end[-1]))
    assert least_merit(designs, EXTREMES) is not None and np.allclose(least_merit(designs, EXTREMES), end[-1])
