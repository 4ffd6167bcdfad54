"""Periodic finite element model (PFEM): the steady response of an infinite periodic structure to a
load that visits every block once per period T = L / V, from the FE matrices of one block
(Paper C sec. 3).

Conventions (Paper C eqs. 3-5): U_L = exp(i w T) U_R. A nodal force on the node two blocks share is
counted once, and the inverse transform carries 1/(2 pi): the two corrections of NOTES.md that make
the printed appendix numbers come out.

Two evaluations of the same sums:
- `direct_frf` / `direct_receptance` / `direct_operator`: Paper C eqs. (10)-(22) written out, one
  dense solve per frequency. The reference, for small blocks (the appendix example).
- `FixedInterfaceModel`: a fixed-interface (Craig-Bampton) reduction of the block. The inner dofs
  become undamped-normal modes with a diagonal dynamic stiffness, so the frequency-dependent periodic
  coupling is confined to the few boundary dofs (a 3 x 3 solve per frequency for a catenary). Exact:
  every mode is kept, so it gives the direct path's receptance to round-off.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy import sparse


def _dense(a) -> np.ndarray:
    return a.toarray() if sparse.issparse(a) else np.asarray(a, dtype=float)


@dataclass
class PeriodicBlock:
    """FE matrices of the repeated block and its boundary partition (Paper C eq. 7).

    `left[i]` and `right[i]` are the same dof of consecutive blocks. For the fast path the damping
    must be C = alpha M + beta K plus any damping acting on boundary dofs only.
    """

    M: np.ndarray
    K: np.ndarray
    C: np.ndarray
    left: np.ndarray
    right: np.ndarray
    length_m: float
    alpha: float = 0.0
    beta: float = 0.0

    def __post_init__(self):
        self.M, self.K, self.C = _dense(self.M), _dense(self.K), _dense(self.C)
        self.left = np.asarray(self.left, dtype=int)
        self.right = np.asarray(self.right, dtype=int)
        if len(self.left) != len(self.right):
            raise ValueError("a periodic block needs as many left as right boundary dofs")

    @property
    def ndof(self) -> int:
        """Number of dofs of the block."""
        return self.K.shape[0]

    @property
    def inner(self) -> np.ndarray:
        """Indices of the inner dofs I (neither left nor right boundary; Paper C eq. 7)."""
        mask = np.ones(self.ndof, dtype=bool)
        mask[self.left] = False
        mask[self.right] = False
        return np.flatnonzero(mask)


def frequency_grid(dt_s: float, d_omega: float, omega_max: float) -> tuple[np.ndarray, int]:
    """w_k = k dw for k = 0..N_f-1 (Paper C eq. 17) with dw = 2 pi / (n_fft dt), n_fft an integer so
    that one FFT gives the inverse transform (eq. 19) at every lag. Returns (w_k, n_fft)."""
    n_fft = max(2, int(round(2 * np.pi / (d_omega * dt_s))))
    dw = 2 * np.pi / (n_fft * dt_s)
    n_f = min(int(np.floor(omega_max / dw + 1e-9)) + 1, n_fft // 2)
    return np.arange(n_f) * dw, n_fft


def transform_weights(omega: np.ndarray, dt_s: float) -> np.ndarray:
    """a_k dw dt / (2 pi): eq. (19) with the 1/(2 pi) of NOTES.md, times the dt of eq. (22)."""
    dw = omega[1] - omega[0] if len(omega) > 1 else 1.0
    a = np.full(len(omega), 2.0)
    a[0] = 1.0
    return a * dw * dt_s / (2 * np.pi)


def graded_grid(alpha: float, beta: float, omega_max: float, resolution: float = 0.094,
                max_step: float = 0.5, dt_s: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """A frequency grid fine where the response is lightly damped: dw(w) = resolution (alpha + beta w^2),
    at most max_step. A uniform dw aliases the impulse response with period 2 pi / dw, and with
    alpha = 0.0125 1/s the waves that reach a block from far ones decay over minutes: dw = 0.025
    leaves errors of tens of percent (measured against ASM2); this grid keeps about ten decay times
    inside the local period 2 pi / dw(w). Returns (w_k, weights of eq. 19-22 by the trapezoidal rule)."""
    if alpha <= 0 and beta <= 0:
        raise ValueError("the PFEM needs damping (alpha or beta > 0) for its impulse response to decay")
    pts = [0.0]
    while pts[-1] < omega_max:
        w = pts[-1]
        pts.append(w + min(max_step, max(resolution * (alpha + beta * w * w), 1e-5)))
    omega = np.array(pts)
    omega[-1] = omega_max
    trap = np.zeros(len(omega))
    dw = np.diff(omega)
    trap[:-1] += dw / 2
    trap[1:] += dw / 2
    return omega, trap * dt_s / np.pi


# ---------------------------------------------------------------------------------------------
# Direct evaluation (reference)

def direct_frf(block: PeriodicBlock, omega: float, period_s: float) -> np.ndarray:
    """H(w) of Paper C eqs. (10)-(14): displacements of every dof (rows in dof order) per unit nodal
    force on the inner and right dofs (columns: inner dofs, then right dofs), the F_R column halved."""
    L, I, R = block.left, block.inner, block.right  # noqa: E741 (Paper C's left, inner, right dofs)
    nI, nR = len(I), len(R)
    D = block.K + 1j * omega * block.C - omega**2 * block.M
    e = np.exp(1j * omega * period_s)
    A = np.zeros((nR + nI + nR, nI + nR + nR), dtype=complex)
    for r, rows in enumerate((L, I, R)):
        r0 = [0, nR, nR + nI][r]
        A[r0:r0 + len(rows), :nI] = D[np.ix_(rows, I)]
        A[r0:r0 + len(rows), nI:nI + nR] = D[np.ix_(rows, R)] + e * D[np.ix_(rows, L)]
    A[:nR, nI + nR:] = e * np.eye(nR)
    A[nR + nI:, nI + nR:] = -np.eye(nR)
    B = np.zeros((nR + nI + nR, nI + nR), dtype=complex)
    B[:nR, nI:] = 0.5 * e * np.eye(nR)  # F_L = e F_R, the shared node's force split half and half
    B[nR:nR + nI, :nI] = np.eye(nI)
    B[nR + nI:, nI:] = 0.5 * np.eye(nR)
    Hhat = np.linalg.solve(A, B)
    H = np.zeros((block.ndof, nI + nR), dtype=complex)
    H[I] = Hhat[:nI]
    H[R] = Hhat[nI:nI + nR]
    H[L] = e * Hhat[nI:nI + nR]
    return H


def direct_receptance(block: PeriodicBlock, omega: float, period_s: float, Nx: np.ndarray,
                      Ny: np.ndarray) -> np.ndarray:
    """I(w, x, y) of Paper C eq. (16) for every row of Nx (points x) and of Ny (points y)."""
    H = direct_frf(block, omega, period_s)
    e = np.exp(-1j * omega * period_s)
    F = np.concatenate([Ny[:, block.inner].T, Ny[:, block.right].T + e * Ny[:, block.left].T])
    return Nx @ H @ F


def direct_operator(block: PeriodicBlock, Nc: np.ndarray, dt_s: float, omega: np.ndarray) -> np.ndarray:
    """The contact operator II(n, n_hat) = h(t_n - t_n_hat, x_n, y_n_hat) dt (Paper C eqs. 19, 22),
    for contact points n = 0..N-1 whose shape rows are Nc, summed over the frequencies `omega`."""
    n = Nc.shape[0]
    T = n * dt_s
    lag = (np.arange(n)[:, None] - np.arange(n)[None, :]) * dt_s
    w = transform_weights(omega, dt_s)
    out = np.zeros((n, n))
    for wk, ok in zip(w, omega, strict=False):
        out += wk * np.real(direct_receptance(block, ok, T, Nc, Nc) * np.exp(1j * ok * lag))
    return out


# ---------------------------------------------------------------------------------------------
# Fixed-interface (Craig-Bampton) evaluation

@dataclass
class FixedInterfaceModel:
    """The block in fixed-interface coordinates u = Psi u_B + Phi q (Craig-Bampton).

    Boundary dofs B are the left dofs then the right dofs. Rayleigh damping maps to the same
    combination of the reduced matrices; `C_BB` is the damping acting on boundary dofs only.
    """

    boundary: np.ndarray
    Psi: np.ndarray  # ndof x n_B constraint modes
    Phi: np.ndarray  # ndof x r fixed-interface modes, mass-normalised
    lam: np.ndarray  # r eigenvalues w_p^2
    K_BB: np.ndarray
    M_BB: np.ndarray
    M_qB: np.ndarray
    C_BB: np.ndarray
    alpha: float
    beta: float
    period_s: float
    n_right: int

    @classmethod
    def build(cls, block: PeriodicBlock, period_s: float) -> FixedInterfaceModel:
        """Craig-Bampton form of a block: the inner dofs' fixed-interface modes and the boundary coupling.

        Exact (every mode kept); needs C = alpha M + beta K plus damping on the boundary dofs only.
        """
        B = np.concatenate([block.left, block.right])
        I = block.inner  # noqa: E741 (Paper C's inner dofs)
        K, M = block.K, block.M
        extra = block.C - block.alpha * M - block.beta * K
        inner_extra = np.abs(extra[np.ix_(I, np.arange(block.ndof))]).max(initial=0.0)
        if inner_extra > 1e-9 * max(1.0, np.abs(block.C).max(initial=0.0)):
            raise ValueError("the fast PFEM path needs C = alpha M + beta K plus boundary-only damping")
        K_II, M_II = K[np.ix_(I, I)], M[np.ix_(I, I)]
        Psi_I = -np.linalg.solve(K_II, K[np.ix_(I, B)]) if len(I) else np.zeros((0, len(B)))
        lam, Phi_I = sla.eigh(K_II, M_II) if len(I) else (np.zeros(0), np.zeros((0, 0)))
        n = block.ndof
        Psi = np.zeros((n, len(B)))
        Psi[I] = Psi_I
        Psi[B] = np.eye(len(B))
        Phi = np.zeros((n, len(I)))
        Phi[I] = Phi_I
        K_BB = Psi.T @ K @ Psi
        M_BB = Psi.T @ M @ Psi
        M_qB = Phi.T @ M @ Psi
        C_BB = extra[np.ix_(B, B)]
        return cls(B, Psi, Phi, lam, K_BB, M_BB, M_qB, C_BB, block.alpha, block.beta, period_s,
                   len(block.right))

    def functionals(self, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rows of shape functions (points x dofs) in reduced coordinates: (psi: x n_B, phi: x r)."""
        S = _dense(S)
        return S @ self.Psi, S @ self.Phi

    def coefficients(self, omega: np.ndarray):
        """Per frequency: c = i w alpha - w^2, d_p = (1 + i w beta) lam_p + c, and the periodic
        boundary Schur complement S = P^H S_B P with P = [exp(i w T) I; I] (n_w x n_R x n_R)."""
        w = np.asarray(omega, dtype=float)
        c = 1j * w * self.alpha - w**2
        d = (1 + 1j * w * self.beta)[:, None] * self.lam[None, :] + c[:, None]
        nB = self.M_qB.shape[1]
        mm = (self.M_qB[:, :, None] * self.M_qB[:, None, :]).reshape(len(self.lam), nB * nB)
        modal = ((1.0 / d) @ mm).reshape(-1, nB, nB)
        SB = ((1 + 1j * w * self.beta)[:, None, None] * self.K_BB + c[:, None, None] * self.M_BB
              + 1j * w[:, None, None] * self.C_BB - (c**2)[:, None, None] * modal)
        P = self.bloch(w)
        S = np.conj(np.transpose(P, (0, 2, 1))) @ SB @ P
        return c, d, S, P

    def bloch(self, omega: np.ndarray) -> np.ndarray:
        """The periodicity map U_L = exp(i w T) U_R (Paper C eq. 4) per frequency, boundary dofs from the right ones."""
        nR = self.n_right
        P = np.zeros((len(omega), 2 * nR, nR), dtype=complex)
        P[:, :nR, :] = np.exp(1j * np.asarray(omega) * self.period_s)[:, None, None] * np.eye(nR)
        P[:, nR:, :] = np.eye(nR)
        return P

    def dynamic_constraint(self, c: np.ndarray, d: np.ndarray, psi: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """Xi(w, x) = psi(x) - c sum_p phi_p(x) M_pB / d_p: the boundary part of the response
        functional at x (n_w x points x n_B)."""
        Q = (c[:, None] / d)[:, :, None] * self.M_qB[None, :, :]  # n_w x r x n_B
        return psi[None] - np.einsum("xp,kpb->kxb", phi, Q)

    def receptance(self, omega: np.ndarray, Sx, Sy) -> np.ndarray:
        """I(w, x, y) for rows of Sx and Sy (n_w x n_x x n_y): the fixed-interface modal part plus
        the boundary part Xi(x)^T P S^-1 P^H Xi(y)."""
        c, d, S, P = self.coefficients(omega)
        px, fx = self.functionals(Sx)
        py, fy = self.functionals(Sy)
        modal = np.einsum("xp,kp,yp->kxy", fx, 1.0 / d, fy)
        Xx = self.dynamic_constraint(c, d, px, fx) @ P  # n_w x n_x x n_R
        Xy = np.conj(np.transpose(P, (0, 2, 1))) @ np.transpose(self.dynamic_constraint(c, d, py, fy), (0, 2, 1))
        return modal + Xx @ np.linalg.solve(S, Xy)

    def point_response(self, omega: float, Sx, Sy, blocks: np.ndarray, n_phases: int = 2048) -> np.ndarray:
        """Response (blocks x points x sources) of the infinite periodic structure to a unit harmonic force
        at frequency `omega` applied in block 0 only (a fixed load, not a moving one), by Floquet-Bloch
        synthesis: u_j = (1/2 pi) int H(theta; x, y) exp(-i j theta) d theta over the propagation phase
        theta per block (the w T of Paper C eq. 13), midpoint rule with `n_phases` points. The modal part of
        H does not depend on theta, so it appears in block 0 only."""
        w = np.array([float(omega)])
        c, d, _, _ = self.coefficients(w)
        px, fx = self.functionals(Sx)
        py, fy = self.functionals(Sy)
        modal = np.einsum("xp,p,yp->xy", fx, 1.0 / d[0], fy)
        SB = ((1 + 1j * w[0] * self.beta) * self.K_BB + c[0] * self.M_BB + 1j * w[0] * self.C_BB
              - c[0] ** 2 * np.einsum("pa,p,pb->ab", self.M_qB, 1.0 / d[0], self.M_qB))
        Xx = self.dynamic_constraint(c, d, px, fx)[0]  # points x n_B
        Xy = self.dynamic_constraint(c, d, py, fy)[0]
        theta = (np.arange(n_phases) + 0.5) * 2 * np.pi / n_phases
        nR = self.n_right
        P = np.zeros((n_phases, 2 * nR, nR), dtype=complex)
        P[:, :nR, :] = np.exp(1j * theta)[:, None, None] * np.eye(nR)
        P[:, nR:, :] = np.eye(nR)
        PH = np.conj(np.transpose(P, (0, 2, 1)))
        boundary = (Xx @ P) @ np.linalg.solve(PH @ SB @ P, PH @ Xy.T)  # phases x points x sources
        phase = np.exp(-1j * np.outer(np.asarray(blocks), theta)) / n_phases  # blocks x phases
        out = np.einsum("jt,txy->jxy", phase, boundary)
        out[np.asarray(blocks) == 0] += modal
        return out

