"""Moving-window FE simulation of an endless catenary: the conventional simulation of
models/catenary/fe/simulation.py (Paper C sec. 6) on a window of W spans that travels with the pantograph,
as the real-time FE catenaries of the literature do.

The window holds W spans with the pantograph in span B (B spans behind it, W - B - 1 ahead). The contact
wire's two ends are absorbing (dashpots of the wire's impedance sqrt(T m)); the messenger is held at every
support. When the pantograph crosses into span B + 1 the window moves one span on: every dof takes the state
(displacement, velocity, acceleration and the last step's load) of the same dof one span ahead, every dropper
the slack state of the dropper one span ahead, and the new front span enters at rest in its static state.
The matrices are the same before and after the move, so the factorisation is computed once, and so are the
unit responses of span B's contact-wire dofs, the only ones the contact point ever loads. The static state
of the window is its own form-finding; the pantograph always runs in span B, whose static heights stand for
every span of the line.
"""
from __future__ import annotations

import resource
import time
from dataclasses import dataclass

import numpy as np

from pantohil.models.catenary.fe.definition import CatenaryDefinition
from pantohil.models.catenary.fe.model import Section, form_find
from pantohil.models.catenary.fe.simulation import FeSimResult, SectionStepper, form_found_model, record_steps
from pantohil.models.pantograph.lumped import HhtConstants, PantographParameters


@dataclass(frozen=True)
class WindowLayout:
    """The window's size and the pantograph's span in it."""

    spans: int  # W
    behind: int  # B: spans behind the pantograph's span

    def __post_init__(self):
        if not 0 <= self.behind <= self.spans - 1:
            raise ValueError(f"the pantograph's span {self.behind} must lie in the window of {self.spans} spans")


def dof_one_span_ahead(sec: Section) -> np.ndarray:
    """For every dof of the section, the same dof one span ahead (-1 in the last span): contact wire and
    messenger nodes move by the nodes of one span, the stitch wire's inner nodes to the next support's."""
    n = len(sec.x)
    per_span = (n - 1) // sec.n_spans
    ahead = -np.ones(sec.ndof, dtype=int)
    nodes = np.arange(n - per_span)
    for first in (0, 2 * n):  # contact wire, messenger: (height, slope) per node
        for c in (0, 1):
            ahead[first + 2 * nodes + c] = first + 2 * (nodes + per_span) + c
    for seg in range(len(sec.stitch_w) - 1):
        inner, inner_next = sec.stitch_w[seg][1:-1], sec.stitch_w[seg + 1][1:-1]
        for c in (0, 1):
            ahead[inner + c] = inner_next + c
    return ahead


def simulate_window(cat: CatenaryDefinition, pan: PantographParameters, layout: WindowLayout, n_spans: int,
                    speed_m_s: float, dt_s: float, droppers_slacken: bool = True, hht: HhtConstants | None = None,
                    progress=None, reference_height_m: float | None = None) -> FeSimResult:
    """Run the pantograph over `n_spans` spans of the endless line in a moving window. The result's positions
    are along the line; its dropper and support records are the window's, in window order, as they stand at
    each step (dropper_x_m relative to the start of the pantograph's span)."""
    t0 = time.perf_counter()
    hht = hht if hht is not None else HhtConstants()
    W, B = layout.spans, layout.behind
    ff = form_find(cat, W)
    sec = ff.section
    ahead = dof_one_span_ahead(sec)
    L = cat.span_m
    n_steps = int(round(n_spans * L / (speed_m_s * dt_s)))
    x_line = np.arange(n_steps + 1) * speed_m_s * dt_s
    span_of = np.floor(x_line / L + 1e-12).astype(int)
    x_local = B * L + np.minimum(x_line - span_of * L, L - 1e-9)
    model, free = form_found_model(cat, ff, x_local, x_line)
    pos = -np.ones(sec.ndof, dtype=int)
    pos[free] = np.arange(len(free))
    src = np.where(ahead[free] >= 0, pos[np.maximum(ahead[free], 0)], -1)  # free dof <- free dof one span ahead
    per_span_droppers = len(cat.dropper_positions_m)
    ref = float(model.z_static[0]) if reference_height_m is None else reference_height_m
    dofs_in_span = 4 * (int(np.sum((sec.x >= B * L - 1e-9) & (sec.x <= (B + 1) * L + 1e-9))) + 1)
    st = SectionStepper(model, pan, dt_s, droppers_slacken, hht, ref, float(model.z_static[0]),
                        keep_unit_responses=dofs_in_span)

    def move_on_crossing(k: int) -> None:
        if span_of[k + 1] > span_of[k]:
            _move_window(st, src, per_span_droppers)

    forces, dforce, dcorr, uplift = record_steps(st, n_steps, progress, move_on_crossing)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    res = FeSimResult(np.arange(1, n_steps + 1) * dt_s, x_line[1:], forces, forces > 0, dforce, dcorr, uplift,
                      np.array([d[0] for d in sec.droppers]) - B * L, n_spans, L, 0.0, peak)
    res.wall_s = time.perf_counter() - t0
    return res


def _move_window(st: SectionStepper, src: np.ndarray, per_span_droppers: int) -> None:
    """Move the window one span on: each dof takes the state of the same dof one span ahead (the front span at
    rest), each dropper the slack state of the dropper one span ahead (the front span's tense)."""
    keep = src >= 0
    for name in ("u", "v", "acc", "F_old"):
        old = getattr(st, name)
        new = np.zeros_like(old)
        new[keep] = old[src[keep]]
        setattr(st, name, new)
    slack = np.zeros_like(st.slack)
    slack[:len(slack) - per_span_droppers] = st.slack[per_span_droppers:]
    st.slack = slack
