"""The moving-window FE simulation (models/catenary/fe/window.py): the dof map of a move is a symmetry of the
section away from its ends, and a move leaves the contact force continuous. Its accuracy against a 60-span
section is measured by tests/benchmarks/bench_fe_window.py (docs/benchmarks.md)."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import CATENARIES_DIR as CATENARIES
from pantohil.models.catenary.fe.definition import load_definition
from pantohil.models.catenary.fe.model import build_section
from pantohil.models.catenary.fe.window import WindowLayout, dof_one_span_ahead, simulate_window
from pantohil.models.parameters import PantographSection, pantograph_parameters

SPANS = 5


def _dof_abscissae(sec) -> np.ndarray:
    """The abscissa of every dof's node (heights and slopes alike)."""
    x = np.full(sec.ndof, np.nan)
    n = len(sec.x)
    for first in (0, 2 * n):
        for c in (0, 1):
            x[first + 2 * np.arange(n) + c] = sec.x
    for xs, dofs in zip(sec.stitch_x, sec.stitch_w, strict=True):
        for c in (0, 1):
            x[np.asarray(dofs) + c] = xs
    return x


@pytest.mark.parametrize("name", ["benchmark_simple.toml", "paper_a_stitched.toml"])
def test_a_move_maps_each_dof_to_the_same_dof_one_span_on(name):
    cat = load_definition(CATENARIES / name)
    sec = build_section(cat, SPANS)
    ahead = dof_one_span_ahead(sec)
    x = _dof_abscissae(sec)
    has = ahead >= 0
    assert np.allclose(x[ahead[has]], x[has] + cat.span_m, atol=1e-9)
    assert not np.any(has & (x >= (SPANS - 1) * cat.span_m + 1e-9))  # nothing ahead of the last span
    # away from the ends (spans 1..W-3 and their images) the wires' matrices do not change under the map
    inner = np.flatnonzero(has & (x > cat.span_m + 1e-9) & (x < (SPANS - 2) * cat.span_m - 1e-9))
    for A in (sec.K_wires.tocsr(), sec.M_wires.tocsr()):
        here = A[inner][:, inner].toarray()
        there = A[ahead[inner]][:, ahead[inner]].toarray()
        assert np.allclose(here, there, rtol=1e-12, atol=1e-12 * np.abs(here).max())


def test_a_moving_window_keeps_the_contact_force_continuous():
    """Two spans of travel in a 6-span window (one move): the force's change at the move is no larger than
    its largest change elsewhere in the span around it, and the force stays in contact."""
    cat = load_definition(CATENARIES / "benchmark_simple.toml")
    pan = pantograph_parameters(PantographSection(), 130.0)
    speed, dt = 250 / 3.6, 1e-3
    res = simulate_window(cat, pan, WindowLayout(6, 2), 2, speed, dt)
    per_span = int(round(cat.span_m / (speed * dt)))
    jumps = np.abs(np.diff(res.force_N))
    at_move = jumps[per_span - 2:per_span + 1].max()
    around = np.concatenate([jumps[per_span // 2:per_span - 2], jumps[per_span + 1:3 * per_span // 2]])
    assert res.contact.all()
    assert at_move <= around.max(), (at_move, around.max())
