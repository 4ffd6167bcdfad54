"""Lumped pantograph models: an n-mass chain with penalty contact, and a rigid mass on the actuator.

Chain (Paper A Fig. 2, Table A.3): mass 1 is the head; element i joins mass i to mass i+1 and the
last element joins the last mass to ground. The uplift force acts on the last mass. Heights are
absolute (z up); the chain is written in displacements u from the reference configuration in which
the head touches a wire at `reference_height_m` with a contact force equal to the uplift force:
    M u'' + C u' + K u = -(f - F_up) e1,   f = k_c max(0, y1 - z)
which is the absolute model with the ground-spring preload eliminated.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class PantographParameters:
    """A chain of 1 to 3 lumped masses (Paper A Table A.3), or a rigid mass (Paper B sec. 5.1); made from a
    case's [pantograph] section (its keys and defaults: models/parameters.PantographSection) by
    `pantograph_parameters`."""

    masses_kg: tuple
    stiffnesses_N_m: tuple
    dampings_Ns_m: tuple
    contact_stiffness_N_m: float
    uplift_force_N: float
    model: str  # a name in models/pantograph/interface.PANTOGRAPHS
    gravity_m_s2: float  # only the rigid mass feels it (its load cell is not tared)

    @property
    def n(self) -> int:
        """Number of masses of the chain."""
        return len(self.masses_kg)

    def matrices(self):
        """Mass, damping and stiffness matrices of the chain (Paper A eq. 18's M_p, C_p, K_p)."""
        n = self.n
        M = np.diag(np.asarray(self.masses_kg, dtype=float))
        K = np.zeros((n, n))
        C = np.zeros((n, n))
        for i in range(n):
            k, c = self.stiffnesses_N_m[i], self.dampings_Ns_m[i]
            K[i, i] += k
            C[i, i] += c
            if i + 1 < n:
                K[i + 1, i + 1] += k
                C[i + 1, i + 1] += c
                K[i, i + 1] -= k
                K[i + 1, i] -= k
                C[i, i + 1] -= c
                C[i + 1, i] -= c
        return M, C, K

    def contact_frequency_hz(self) -> float:
        """Natural frequency of the head on its contact spring, sqrt((k1 + k_c)/m1)/(2 pi) (Paper D sec. 4)."""
        return float(np.sqrt((self.stiffnesses_N_m[0] + self.contact_stiffness_N_m) / self.masses_kg[0]) / (2 * np.pi))


@dataclass(frozen=True)
class HhtConstants:
    """HHT-alpha constants of the thesis (Paper A Appendix A)."""

    alpha: float = -0.05
    beta: float = 0.2756
    gamma: float = 0.55


def _state_block(block: int, doc: str) -> tuple:
    """Getter, setter and docstring of block `block` (u, v or a) of a ChainPantograph's state vector, as a view."""
    def get(self) -> np.ndarray:
        n = self.params.n
        return self._x[block * n:(block + 1) * n]

    def put(self, value) -> None:
        n = self.params.n
        self._x[block * n:(block + 1) * n] = value
    return get, put, None, f"{doc} (a view of the state vector)"


@dataclass
class ChainPantograph:
    """HHT integration of the chain with unilateral penalty contact (Paper A sec. 2).

    `step(z_next)` advances one time step to t + dt with the wire (actuator) height z_next at the
    end of the step and returns the contact force there.
    """

    params: PantographParameters
    dt: float
    reference_height_m: float = 0.0
    hht: HhtConstants = field(default_factory=HhtConstants)

    def __post_init__(self):
        p = self.params
        self.M, self.C, self.K = p.matrices()
        n = p.n
        self.e1 = np.zeros(n)
        self.e1[0] = 1.0
        self.kc = p.contact_stiffness_N_m
        self.f_up = p.uplift_force_N
        # head height of the reference configuration: the penalty spring is compressed by F_up/k_c
        self.head_ref = self.reference_height_m + self.f_up / self.kc
        self.K_act = self.K + self.kc * np.outer(self.e1, self.e1)
        # One HHT step is affine in x = [u, v, a, z_next, f_old, 1]: precompute x -> x_new per contact state.
        self._step_free = self._affine_step(contact=False)
        self._step_act = self._affine_step(contact=True)
        self._x = np.zeros(3 * n + 3)  # the state [u, v, a] and the step's inputs [z_next, f_old, 1]
        self._x[-1] = 1.0
        self.force = self.f_up
        self.z = self.reference_height_m

    def settle(self, z: float) -> float:
        """Static equilibrium in contact with a wire at height z: K_act u = (F_up - k_c (y1* - z)) e1."""
        rhs = (self.f_up - self.kc * (self.head_ref - z)) * self.e1
        u = np.linalg.solve(self.K_act, rhs)
        if self.head_ref + u[0] - z < 0:  # cannot reach the wire: rest with no contact
            u = np.linalg.lstsq(self.K, self.f_up * self.e1, rcond=None)[0]  # K u = F_up e1 (f = 0)
        self.u, self.v, self.acc = u, np.zeros_like(u), np.zeros_like(u)
        self.z = z
        self.force = self.kc * max(0.0, self.head_ref + u[0] - z)
        return self.force

    u = property(*_state_block(0, "Displacements of the masses from the reference configuration [m]"))
    v = property(*_state_block(1, "Velocities of the masses [m/s]"))
    acc = property(*_state_block(2, "Accelerations of the masses [m/s2]"))

    @property
    def head_height(self) -> float:
        """Height of the head (mass 1) [m]."""
        return float(self.head_ref + self._x[0])

    @property
    def contact_step_matrix(self) -> np.ndarray:
        """The affine HHT step in contact, [u, v, a]_new = P [u, v, a, z_next, f_old, 1] (for the linear map)."""
        return self._step_act

    def _affine_step(self, contact: bool) -> np.ndarray:
        """Matrix P with [u, v, a]_new = P [u, v, a, z_next, f_old, 1] for one HHT step (Hilber-Hughes-Taylor
        1977; constants of Paper A App. A), with the penalty contact active or not."""
        a, b, g, dt = self.hht.alpha, self.hht.beta, self.hht.gamma, self.dt
        n, M, C, K, e1 = self.params.n, self.M, self.C, self.K, self.e1
        K1 = self.K_act if contact else K
        S = np.linalg.inv(M + (1 + a) * (g * dt * C + b * dt * dt * K1))
        I, Z = np.eye(n), np.zeros((n, n))  # noqa: E741 (identity and zero blocks)
        # predictors as maps of [u, v, a]
        u_pred = np.hstack([I, dt * I, dt * dt * (0.5 - b) * I])
        v_pred = np.hstack([Z, I, dt * (1 - g) * I])
        state = np.hstack([I, Z, Z]), np.hstack([Z, I, Z])
        acc = S @ (a * (C @ state[1] + K @ state[0]) - (1 + a) * (C @ v_pred + K1 @ u_pred))
        # columns for z_next, f_old and the constant: -alpha F_old + (1+alpha) F_new
        col_z = S @ ((1 + a) * self.kc * e1) if contact else np.zeros(n)
        col_f = S @ (a * e1)  # -alpha * (-(f_old - F_up) e1), force part
        const = S @ (-a * self.f_up * e1 + (1 + a) * (self.f_up - (self.kc * self.head_ref if contact else 0.0)) * e1)
        A_acc = np.hstack([acc, col_z[:, None], col_f[:, None], const[:, None]])
        def ext(m):
            return np.hstack([m, np.zeros((n, 3))])
        A_u = ext(u_pred) + b * dt * dt * A_acc
        A_v = ext(v_pred) + g * dt * A_acc
        return np.vstack([A_u, A_v, A_acc])

    def contact_force_at(self, z_next: float) -> float:
        """The contact force the next HHT step would give in contact for a wire height z_next, without
        advancing the pantograph: the step is affine in z_next."""
        x = self._x
        x[-3], x[-2] = z_next, self.force
        new = self._step_act @ x
        return self.kc * (self.head_ref + new[0] - z_next)

    def step(self, z_next: float) -> float:
        """One HHT step with unilateral contact: free unless the head would penetrate the wire."""
        x = self._x
        x[-3], x[-2] = z_next, self.force
        # numpy's pairwise row sums, not BLAS: the order the compiled block repeats (models/hil/span_kernel.py)
        new = (self._step_free * x).sum(axis=1)
        gap = self.head_ref + new.item(0) - z_next
        if gap > 0.0:
            new = (self._step_act * x).sum(axis=1)
            gap = self.head_ref + new.item(0) - z_next
        x[:-3] = new  # [u, v, a] of the new step
        self.z = z_next
        self.force = self.kc * gap if gap > 0.0 else 0.0
        return self.force


@dataclass
class RigidMass:
    """A mass fixed to the actuator (Paper B sec. 5.1): the load cell reads f = -m (g + z'').

    The acceleration follows the actuator position with the Newmark relations (HHT beta, gamma),
    a causal, second-order accurate and stable differentiator, so it adds no latency.
    """

    params: PantographParameters
    dt: float
    hht: HhtConstants = field(default_factory=HhtConstants)

    def __post_init__(self):
        self.m = self.params.masses_kg[0]
        self.g = self.params.gravity_m_s2
        self.z = 0.0
        self.v = 0.0
        self.acc = 0.0
        self.force = -self.m * self.g

    def settle(self, z: float) -> float:
        """Rest on the actuator at height z: zero velocity and acceleration; returns the static force -m g [N]."""
        self.z, self.v, self.acc = z, 0.0, 0.0
        self.force = -self.m * self.g
        return self.force

    @property
    def head_height(self) -> float:
        """Height of the mass, which follows the actuator [m]."""
        return self.z

    def step(self, z_next: float) -> float:
        """Move the mass to z_next with HHT's Newmark update; returns the force -m (g + a) [N]."""
        b, g, dt = self.hht.beta, self.hht.gamma, self.dt
        acc_new = (z_next - self.z - dt * self.v - dt * dt * (0.5 - b) * self.acc) / (b * dt * dt)
        self.v += dt * ((1 - g) * self.acc + g * acc_new)
        self.acc = acc_new
        self.z = z_next
        self.force = -self.m * (self.g + acc_new)
        return self.force


def chain_receptance(params: PantographParameters, omega) -> np.ndarray:
    """Contact-point receptance of the chain, H_p = 1/k_h + [K - w^2 M + i w C]^-1_(1,1), Paper A eq. (18)."""
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    M, C, K = params.matrices()
    out = np.empty(omega.shape, dtype=complex)
    for j, w in enumerate(omega):
        out[j] = np.linalg.inv(K - w**2 * M + 1j * w * C)[0, 0]
    return out + 1.0 / params.contact_stiffness_N_m
