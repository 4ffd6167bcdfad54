"""The pantograph as a linear discrete-time system in contact, for the stability analysis (Paper D eq. A.3).

One step of the time integrator is x' = Pp x + pz z + pf f and the force it then measures is
f' = c.x' + cz z, with z the height imposed in the step and f the force of the step before. For the
chain this is the HHT step of models/pantograph/lumped.py with the penalty contact active (f = k_c (y1 - z));
for the rigid mass it is its Newmark differentiator (f = -m z''). Offsets (uplift, gravity) drop out of
the map between consecutive spans, so only the homogeneous part is kept.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pantohil.models.pantograph.lumped import ChainPantograph, HhtConstants, PantographParameters


@dataclass(frozen=True)
class LinearPantograph:
    """The pantograph's HHT step as a linear map x+ = Pp x + pz z + pf f, f+ = c x+ + cz z (Paper D app.)."""
    Pp: np.ndarray  # state to state
    pz: np.ndarray  # imposed height to state
    pf: np.ndarray  # previous force to state
    c: np.ndarray  # state to measured force
    cz: float  # imposed height to measured force

    @property
    def size(self) -> int:
        """Number of states of the step map."""
        return len(self.pz)

    def transfer(self, lam: np.ndarray) -> np.ndarray:
        """H(lambda) = F / Z of the step, for z-transform variable lambda (Paper D eq. A.3 in z-domain)."""
        lam = np.asarray(lam, dtype=complex)
        vals, vecs = np.linalg.eig(self.Pp)
        left = np.linalg.solve(vecs, np.column_stack([self.pz, self.pf]))  # modal inputs
        cz_modal, cf_modal = (self.c @ vecs) * left[:, 0], (self.c @ vecs) * left[:, 1]
        inv = 1.0 / (lam[..., None] - vals)
        c_r_pz, c_r_pf = inv @ cz_modal, inv @ cf_modal
        return (c_r_pz + self.cz / lam) / (1.0 - c_r_pf)


def rigid_mass_linear(params: PantographParameters, dt: float) -> LinearPantograph:
    """The rigid mass's Newmark differentiator as a map of x = [z, v, a]: f = -m a (Paper B sec. 5.1)."""
    b, g = HhtConstants().beta, HhtConstants().gamma
    # a' = (z_new - z - dt v - dt^2 (1/2 - b) a) / (b dt^2)
    a_row = np.array([-1.0, -dt, -dt * dt * (0.5 - b)]) / (b * dt * dt)
    a_z = 1.0 / (b * dt * dt)
    Pp = np.vstack([np.zeros(3), np.array([0.0, 1.0, dt * (1 - g)]) + dt * g * a_row, a_row])
    pz = np.array([1.0, dt * g * a_z, a_z])
    m = params.masses_kg[0]
    return LinearPantograph(Pp, pz, np.zeros(3), np.array([0.0, 0.0, -m]), 0.0)


def chain_linear(params: PantographParameters, dt: float) -> LinearPantograph:
    """The chain's HHT step with the penalty contact active, f = k_c (y1 - z)."""
    pan = ChainPantograph(params, dt)
    P, n = pan.contact_step_matrix, params.n
    c = np.zeros(3 * n)
    c[0] = params.contact_stiffness_N_m
    return LinearPantograph(P[:, :3 * n], P[:, 3 * n], P[:, 3 * n + 1], c, -params.contact_stiffness_N_m)
