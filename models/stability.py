"""Stability of the virtual HIL iteration (Paper D sec. 4 and appendix, eqs. A.1-A.16).

The virtual HIL test without contact loss is linear: from one virtual span to the next its state
X^b (the catenary's iteration state, the pantograph's HHT state, the force in hand and the heights in
flight through the loop delay) obeys X^(b+1) = A X^b + B (Paper D eq. 13). Instead of writing A out
term by term as the appendix does for one mass, A is obtained by running the same linearised loop on
every unit state at once (the columns of the identity), for any n-DOF pantograph and both update
strategies; the spectral radius of A decides convergence and predicts its rate per span.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from .hil import HilSettings
from .pantograph import ChainPantograph, PantographParameters


@dataclass
class SpanMap:
    A: np.ndarray
    blocks: dict  # name -> slice of the state vector

    @property
    def spectral_radius(self) -> float:
        return float(np.max(np.abs(np.linalg.eigvals(self.A))))


def span_map(kernel: np.ndarray, pantograph: PantographParameters, dt: float, settings: HilSettings,
             latency_steps: int) -> SpanMap:
    """A of X^(b+1) = A X^b for the loop of models/hil.py + the pantograph, with `latency_steps` between a
    force sample and the height it produces (1 = the thesis's unavoidable step), in contact throughout.

    `kernel` is the first column of the (frequency-reduced) circulant operator I_cc (ASM), so that
    column m of I_cc is np.roll(kernel, m).
    """
    n = len(kernel)
    I_dense = np.stack([np.roll(kernel, m) for m in range(n)], axis=1)
    pan = ChainPantograph(pantograph, dt)  # only its affine step matrix is used (contact active)
    P = pan._step_act
    ndof = pantograph.n
    kc = pantograph.contact_stiffness_N_m
    lag = latency_steps - 1  # heights in flight between the catenary and the pantograph
    span = settings.update == "span"
    sizes = {"z_older": n if span else 0, "z": n if span else 0, "rf": 0 if span else n, "pantograph": 3 * ndof,
             "force": 1, "in_flight": lag}
    blocks, start = {}, 0
    for name, size in sizes.items():
        blocks[name] = slice(start, start + size)
        start += size
    dim = start
    X = np.eye(dim)
    # unpack the unit states (the catenary's z is I rf in step-by-step updating: keep them consistent)
    if span:
        z_older, z = X[blocks["z_older"]].copy(), X[blocks["z"]].copy()
    else:
        rf = X[blocks["rf"]].copy()
        z = I_dense @ rf
    pan_state = X[blocks["pantograph"]].copy()
    force = X[blocks["force"]][0].copy()
    flight = deque(X[blocks["in_flight"]][i].copy() for i in range(lag))
    block_force = np.zeros((n, dim))
    mu, D = settings.relaxation, settings.delay_steps
    for n_bar in range(n):
        target = (n_bar + D) % n
        if span:  # Paper D eq. (3): blend of the last two block vectors
            block_force[n_bar] = force
            w_new = (n_bar + 1) / n
            command = (1 - w_new) * z_older[target] + w_new * z[target]
            if n_bar == n - 1:  # eq. (A.8)
                z_older, z = z, mu * (I_dense @ block_force) + (1 - mu) * z
        else:  # Paper D eq. (10)
            delta = mu * (force - rf[n_bar])
            rf[n_bar] += delta
            z += np.outer(I_dense[:, n_bar], delta)
            command = z[target].copy()
        flight.append(command)
        z_act = flight.popleft()
        ext = np.vstack([pan_state, z_act[None, :], force[None, :]])
        pan_state = P[:, :-1] @ ext  # homogeneous: no uplift, no reference height
        force = kc * (pan_state[0] - z_act)
    rows = [z_older] if span else []
    rows += [z] if span else [rf]
    rows += [pan_state, force[None, :]]
    rows += [np.vstack(list(flight))] if lag else []
    A = np.vstack([r if r.ndim == 2 else r[None, :] for r in rows])
    return SpanMap(A, blocks)
