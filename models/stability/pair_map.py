"""Stability of the HIL iteration of two contact points (models/hil/pair.py; Paper D sec. 4 and its appendix,
eqs. A.1-A.16, for the pair).

In contact the pair's loop is linear: from one virtual span to the next its state X^b (the relaxed forces of
both points, for span-by-span updating also the older block vector, each pantograph's integrator state, the
force in hand at each point and the heights in flight through each point's latency) obeys X^(b+1) = A X^b + B
(Paper D eq. 13). A is built here as `maps.span_map` builds it for one point: by running the pair's loop on
every unit state at once (each state variable a row vector over the state's basis), with the heights of
both points z = z0 + I f_relaxed (models/hil/pair.py; on the PFEM, models/hil/pfem_pair.py, its droppers in
tension, I_ij the operators that pair applies), the coupling compensation Q where the iteration uses
it, and each point's own delay advance D_i and loop latency. The spectral radius of A decides whether the
pair converges and is its rate per span; the leading pantograph drives the trailing one through I_21 (or
I_12) and a little the other way round, which is what a map of one point cannot show.
"""
from __future__ import annotations

from collections import deque
from typing import Protocol

import numpy as np

from pantohil.models.case import Case, CaseError
from pantohil.models.hil.pair import PairedHil
from pantohil.models.hil.pair_loop import VIRTUAL_CONNECTIONS, pair_delay_steps, pair_iteration
from pantohil.models.hil.rig_loop import LOOP_CONNECTIONS
from pantohil.models.pantograph.interface import linear_pantograph
from pantohil.models.pantograph.linear import LinearPantograph

from .maps import QueuedRankOne, SpanMap, _layout

POINTS = PairedHil.POINTS


class PairIteration(Protocol):
    """What the map reads of a pair iteration: ASM2's (models/hil/pair.py) or the PFEM's (models/hil/pfem_pair.py)."""

    n: int
    s: object  # HilSettings: update and relaxation
    delays: tuple[int, int]

    def dense_operators(self) -> list[list[np.ndarray]]:
        """I_ij as N x N matrices, rows observed at point i, columns loaded at point j."""

    def dense_compensation(self) -> tuple[list, list] | None:
        """(Q, I Q) as N x N matrices per pair of points, or None without a coupling compensation."""


def pair_span_map(hil: PairIteration, pan: LinearPantograph, latency_steps: tuple[int, int]) -> SpanMap:
    """A of X^(b+1) = A X^b for the pair iteration `hil` (its operators, compensation, settings and delay
    advances) with the pantograph `pan` at both points and `latency_steps` per point between a force sample
    and the height it produces (1 = the unavoidable step): Paper D eqs. (A.1)-(A.16) for two points."""
    n, s = hil.n, hil.s
    span = s.update == "span"
    lags = [int(latency) - 1 for latency in latency_steps]
    if min(lags) < 0:
        raise ValueError(f"each point's loop latency must be at least one step, got {latency_steps}")
    blocks, dim = _layout({"rf": POINTS * n, "z_older": POINTS * n if span else 0, "pantograph": POINTS * pan.size,
                           "force": POINTS, "in_flight_1": lags[0], "in_flight_2": lags[1]})
    X = np.eye(dim)
    ops = hil.dense_operators()
    Q, IQ = hil.dense_compensation() or (None, None)
    rf = X[blocks["rf"]].reshape(POINTS, n, dim).copy()
    z = _heights(ops, rf)
    z_older = X[blocks["z_older"]].reshape(POINTS, n, dim).copy() if span else None
    pan_state = X[blocks["pantograph"]].reshape(POINTS, pan.size, dim).copy()
    force = X[blocks["force"]].copy()
    flights = [deque(X[blocks[f"in_flight_{i + 1}"]][m].copy() for m in range(lags[i])) for i in range(POINTS)]
    block_force = np.zeros((POINTS, n, dim))
    mu = s.relaxation
    rf_updates = None  # step-by-step: rf through its queue where the compensation Q spreads each residual
    if not span:
        z_updates = QueuedRankOne(z, ops if Q is None else IQ)
        rf_updates = None if Q is None else QueuedRankOne(rf, Q)
    for n_bar in range(n):
        targets = [(n_bar + d) % n for d in hil.delays]
        if span:  # Paper D eq. (3) at each point
            block_force[:, n_bar] = force
            w_new = (n_bar + 1) / n
            commands = [(1 - w_new) * z_older[i, targets[i]] + w_new * z[i, targets[i]] for i in range(POINTS)]
            if n_bar == n - 1:  # eq. (A.8) for the pair, through Q
                rf = rf + mu * _compensated(Q, block_force - rf)
                z_older, z = z, _heights(ops, rf)
        else:  # eq. (10) for both points' residuals
            z_updates.open(n_bar)
            if rf_updates is not None:
                rf_updates.open(n_bar)
            for j in range(POINTS):
                if Q is None:
                    delta = mu * (force[j] - rf[j, n_bar])
                    rf[j, n_bar] += delta
                else:  # f_relaxed += delta Q(:, n_bar), z += delta (I Q)(:, n_bar)
                    delta = mu * (force[j] - rf_updates.row(j, n_bar))
                    rf_updates.set(j, delta)
                z_updates.set(j, delta)
            commands = [z_updates.row(i, targets[i]) for i in range(POINTS)]
        for i in range(POINTS):
            flights[i].append(commands[i])
            z_act = flights[i].popleft()
            pan_state[i] = pan.Pp @ pan_state[i] + np.outer(pan.pz, z_act) + np.outer(pan.pf, force[i])
            force[i] = pan.c @ pan_state[i] + pan.cz * z_act
    if rf_updates is not None:
        rf_updates.flush()
    rows = [rf.reshape(POINTS * n, dim)] + ([z_older.reshape(POINTS * n, dim)] if span else [])
    rows += [pan_state.reshape(POINTS * pan.size, dim), force]
    rows += [np.vstack(list(f)) for f in flights if f]
    return SpanMap(np.vstack(rows), blocks)


def _heights(ops, rf: np.ndarray) -> np.ndarray:
    """z_i = sum_j I_ij f_relaxed_j (the homogeneous part of z = z0 + I f_relaxed), rows over the state basis."""
    return np.array([sum(ops[i][j] @ rf[j] for j in range(POINTS)) for i in range(POINTS)])


def _compensated(Q, residual: np.ndarray) -> np.ndarray:
    """The residuals through the coupling compensation Q (identity without it)."""
    if Q is None:
        return residual
    return np.array([sum(Q[i][j] @ residual[j] for j in range(POINTS)) for i in range(POINTS)])


def pair_loop_latency_steps(case: Case) -> tuple[int, int]:
    """Each point's loop latency in the virtual pair (models/hil/pair_loop.py, the FMUs of builder/system.py
    PAIR_CONNECTIONS): the first through the rig's connections and its pure delay, the second through two
    connections; both with the extra loop delay E. The map takes an ideal rig (a pure delay)."""
    rig = case.sections.rig
    if case.rig_spec is not None or rig.comm_decimation > 1 or rig.servo_bandwidth_hz > 0 or \
            rig.loadcell_cutoff_hz > 0:
        raise CaseError("second_pantograph: the pair's stability map takes a rig that is a pure delay (no rig file, "
                        "no decimation, servo or load-cell filter)", key="second_pantograph")
    return (LOOP_CONNECTIONS + case.hold_steps + rig.delay_steps, VIRTUAL_CONNECTIONS + case.hold_steps)


def pair_spectral_radius(case: Case, delay_steps: tuple[int, int] | None = None,
                         latency_steps: tuple[int, int] | None = None) -> float:
    """The rate per span of the case's pair iteration (its operators, coupling compensation, update, relaxation,
    f_max), below 1 where it converges (Paper D eq. 13 for two points): with the virtual pair's delay advances
    and loop latencies, or those given (a pair whose first pantograph is on a rig: the run's D and the link's
    latency)."""
    hil = pair_iteration(case, pair_delay_steps(case) if delay_steps is None else delay_steps)
    pan = linear_pantograph(case.pantograph, case.dt_s)
    latency = pair_loop_latency_steps(case) if latency_steps is None else latency_steps
    return pair_span_map(hil, pan, latency).spectral_radius
