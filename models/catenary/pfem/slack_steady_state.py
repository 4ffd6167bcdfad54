"""The periodic steady state of a linear pantograph on the PFEM with dropper slackening, by an active-set solve,
without the HIL iteration: the fixed point the virtual HIL with `pfem.droppers` converges to.

At that fixed point (steady_state.py's harmonic balance, with the dropper corrections of Paper C sec. 5.3) the
contact-wire height is z = z0 + I_cc f + I_cd g (Paper C eq. 36, g the correction force of every dropper at the
instant of every phase), each dropper's elongation is dL = L_dc f + L_dd g (eqs. 35 and 37, the operators'
harmonics over the window index evaluated at the instant's window index) and the correction of a slack dropper
cancels its spring force, g = -(f_d0 + k_d dL) (eq. 40). So g and w = g + f_d0 + k_d dL are complementary:

    g >= 0,  w >= 0,  g w = 0    (w = f_d0 + k_d dL: the dropper's force where it holds, g = 0)

and the pantograph answers H_p f = x_s - z at every harmonic 1..N_h-1 (Paper A eq. 18). For a set A of slack
(dropper, phase) pairs the equations are linear in the force's harmonics and g_A; the set is updated (pairs of
g < 0 leave, pairs of w < 0 join) until it repeats: a primal-dual active-set iteration, which ends in a few
solves where slackening is local (a few droppers over part of the span). What a catenary designer evaluates a
design by when its droppers slacken (issue 34): the std, max and min of f in one build of the operators.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pantohil.models.errors import PantohilError

from .operator_data import PfemOperators
from .steady_state import LinearSteadyState, harmonic_balance, irfft_rows

MAX_ACTIVE_SET_ITERATIONS = 60


class SlackSteadyStateError(PantohilError, ValueError):
    """The active-set iteration did not settle (cycling between slack sets)."""


@dataclass(frozen=True)
class SlackSteadyState(LinearSteadyState):
    """The steady contact force with dropper slackening [N], the slack (dropper, phase) pairs and their
    correction forces, and the active-set iterations it took."""

    slack_pairs: int = 0
    iterations: int = 0
    correction_N: np.ndarray | None = None  # [phase, dropper]


def _window_basis(n: int, jd: int) -> np.ndarray:
    """Row i: the complex weights that give a real sequence's value at index i from its rfft harmonics 0..jd-1
    (`irfft_rows`, the HIL's own, as one complex row)."""
    rows = irfft_rows(n, jd)
    return rows[:, :jd] - 1j * rows[:, jd:]


def slack_steady_state(ops: PfemOperators, pantograph_receptance_m_N: np.ndarray, mean_force_N: float,
                       tolerance_N: float = 1e-9) -> SlackSteadyState:
    """The steady contact force over one span with droppers that slacken (module docstring); `ops` built with
    the droppers' windows, the receptance at the span's harmonics 1..N_h-1 as for `linear_steady_state`."""
    n, nd = ops.n, ops.n_droppers
    basis, project, system, rhs_force = harmonic_balance(ops.cc, ops.z0, pantograph_receptance_m_N, mean_force_N)
    f0, kd, win = ops.dropper_tension_N, ops.dropper_stiffness_N_m, np.asarray(ops.window_start)
    wb = _window_basis(n, ops.settings.n_harmonics_dropper)
    phase_rows = (np.arange(n)[None, :] - win[:, None]) % n  # [dropper, phase] -> window index
    # L_dc: elongation of dropper e at the instant of phase p per unit contact force at m  [e, p, m]
    l_dc = np.stack([(wb[phase_rows[e]] @ ops.dc[:, e, :].T).real for e in range(nd)])
    dl_mean = l_dc.sum(axis=2) * mean_force_N  # [e, p]
    dl_harm = l_dc @ basis  # [e, p, 2 (N_h - 1)]

    def dd_columns(pairs: np.ndarray) -> np.ndarray:
        """Elongation of every dropper at every phase per unit correction of each (dropper, phase) pair."""
        loads = ops.dd[pairs[:, 0], (pairs[:, 1] - win[pairs[:, 0]]) % n]  # [a, e, j]
        out = np.empty((len(pairs), nd, n))
        for e in range(nd):
            out[:, e, :] = (loads[:, e, :] @ wb[phase_rows[e]].T).real
        return out

    def solve(pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Harmonics c, corrections g_A and the elongations [e, p] with the pairs slack."""
        if not len(pairs):
            c = np.linalg.solve(system, rhs_force)
            return c, np.zeros(0), dl_mean + dl_harm @ c
        d, p = pairs[:, 0], pairs[:, 1]
        cols = dd_columns(pairs)  # [a, e, p]
        heights = ops.cd[p, d].T  # [n, a]
        k = kd[d]
        top = np.hstack([system, project @ heights])
        bottom = np.hstack([k[:, None] * dl_harm[d, p], np.eye(len(pairs)) + k[:, None] * cols[:, d, p].T])
        rhs = np.concatenate([rhs_force, -f0[d] - k * dl_mean[d, p]])
        sol = np.linalg.solve(np.vstack([top, bottom]), rhs)
        c, g = sol[:len(rhs_force)], sol[len(rhs_force):]
        return c, g, dl_mean + dl_harm @ c + np.einsum("a,aep->ep", g, cols)

    pairs = np.zeros((0, 2), dtype=int)
    seen: set[bytes] = set()
    for iteration in range(1, MAX_ACTIVE_SET_ITERATIONS + 1):
        c, g, dl = solve(pairs)
        w = f0[:, None] + kd[:, None] * dl  # [e, p]: the dropper's force where it holds
        keep = pairs[g > tolerance_N] if len(pairs) else pairs
        slack = np.zeros((nd, n), dtype=bool)
        slack[w < -tolerance_N] = True
        if len(keep):
            slack[keep[:, 0], keep[:, 1]] = True
        new = np.argwhere(slack)
        if len(pairs) == len(new) and (not len(new) or np.array_equal(pairs, new)) and np.all(g >= -tolerance_N):
            correction = np.zeros((n, nd))
            if len(pairs):
                correction[pairs[:, 1], pairs[:, 0]] = g
            return SlackSteadyState(mean_force_N + basis @ c, ops.settings.dt_s, len(pairs), iteration, correction)
        key = new.tobytes()
        if key in seen:
            raise SlackSteadyStateError(f"the slack droppers' active set cycles after {iteration} solves")
        seen.add(key)
        pairs = new
    raise SlackSteadyStateError(f"the slack droppers' active set did not settle in {MAX_ACTIVE_SET_ITERATIONS} solves")
