"""The PFEM operator between two contact points a distance apart (the cross operators of a pantograph pair,
Paper A sec. 3.4 on the PFEM of Paper C): O[n, m], the height at x_n + offset at sample n per unit force at the
contact point x_m at sample m, x_n = n V dt, reduced to the N_h harmonics of the HIL (Paper D eq. 6).

The PFEM's response to the moving load is quasi-periodic over the blocks (Paper C eqs. 10-14, the boundary
relation u_L = E u_R with E = exp(i w T)): the field one span further on is the field here one period
later, U(y + k span, w) = conj(E)^k U(y, w). The point x_n + offset lies in block k_n = floor((x_n +
offset) / span) at y_n = (x_n + offset) mod span, so eq. (19) with the output functional at y_n and the
factor conj(E)^k_n gives the operator: the boundary part by that factor per frequency, the fixed-interface
modal part by the modal lag functions at the lag n - m - k_n N. The sums are those of the contact operator
(operators.py), with the output functional at y_n instead of x_n; with offset 0 they are that operator.

For two pantographs L apart with the second at x + delta (delta = -L trailing, +L leading): I_21 = O(delta),
and I_12 = O(-delta) re-indexed to the second point's samples (`pair_cross_operators`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.fft as sfft

from pantohil.models.catenary.pfem.blocks import ContactBlock
from pantohil.models.catenary.pfem.lag_transform import LagTransform
from pantohil.models.catenary.pfem.operator_data import PfemSettings
from pantohil.models.catenary.pfem.pair_operators import sample_shift
from pantohil.models.catenary.pfem.operators import (
    _build_context,
    _chunk_bounds,
    _combine,
    _functionals,
    _phases,
    _reduce,
)


def _output_side(ctx, cb: ContactBlock, y: np.ndarray):
    """The build context with the contact functional's output terms at the points y (psi, phi, w_c)."""
    psi_o, phi_o = ctx.fim.functionals(cb.contact_shapes(y))
    m_qb, low = ctx.fim.M_qB, ctx.low
    w_low = (phi_o[:, None, low] * m_qb[low].T[None]).reshape(ctx.n * ctx.nB, -1)
    w_virtual = (phi_o[:, None, ~low] * m_qb[~low].T[None]).reshape(ctx.n * ctx.nB, -1) @ ctx.basis
    return replace(ctx, psi_c=psi_o, phi_c=phi_o, w_c=np.hstack([w_low, w_virtual]).astype(np.float32)), phi_o


def offset_operator(cb: ContactBlock, s: PfemSettings, offset_m: float, chunk: int = 256,
                    span_cells: float = 32.0) -> np.ndarray:
    """O[n, m] (rows: the observed samples n, columns: the loaded samples m) between the contact point and the
    point `offset_m` ahead of it (behind for a negative offset), in the span's sample order."""
    n, dt = s.samples_per_span, s.dt_s
    period = n * dt
    span = cb.block.length_m
    if abs(period * s.speed_m_s - span) > 1e-6 * span:
        raise ValueError("samples_per_span x dt x speed must equal the block length")
    J = s.n_harmonics
    omega, w, x, ctx = _build_context(cb, s, period, J, {})
    ahead = x + offset_m
    k = np.floor(ahead / span + 1e-12).astype(int)
    y = np.clip(ahead - k * span, 0.0, span)
    max_lag = (int(np.abs(k).max()) + 2) * n
    lt = LagTransform(float(omega[-1]) * dt, max_lag)
    out_ctx, phi_o = _output_side(ctx, cb, y)
    nR, rows_c, low = ctx.nB // 2, ctx.rows_c, ctx.low
    r_lo, q = int(low.sum()), len(ctx.lam_v)
    grid = np.zeros((lt.n_rows, r_lo + q), dtype=complex)
    H2 = np.zeros((rows_c, n), dtype=complex)
    bounds = _chunk_bounds(omega * dt / lt.h, chunk, span_cells)
    for k0, k1 in zip(bounds[:-1], bounds[1:], strict=True):
        om, wk = omega[k0:k1], w[k0:k1]
        c, dp, S, _ = ctx.fim.coefficients(om)
        inv_d = 1.0 / dp
        inv_dv = 1.0 / ((1 + 1j * om * ctx.fim.beta)[:, None] * ctx.lam_v[None, :] + c[:, None])
        xi_in, _ = _functionals(ctx, c, inv_d, inv_dv)
        xi_out, _ = _functionals(out_ctx, c, inv_d, inv_dv)
        E = np.exp(1j * om * period)
        ph = _phases(om * dt, n)
        blocks = np.conj(E)[None, :] ** k[:, None]  # conj(E)^k_n: the block the observed point is in
        x_out = (E * xi_out[:, :nR] + xi_out[:, nR:]) * blocks[:, None, :]
        a_c = sfft.fft(ph[:, None, :] * x_out, axis=0)[ctx.harm]
        V = np.linalg.solve(np.transpose(S, (0, 2, 1)), a_c.transpose(2, 1, 0))
        U = V * wk[:, None, None]
        y_in = np.conj(ph)[:, None, :] * (np.conj(E) * xi_in[:, :nR] + xi_in[:, nR:])
        H2 += U.transpose(2, 1, 0).reshape(rows_c, nR * len(om)) @ y_in.reshape(n, nR * len(om)).T
        rows, kernel = lt.spreading(om * dt)
        grid[rows] += kernel @ (np.concatenate([inv_d[:, low], inv_dv], axis=1) * wk[:, None])
    lags = np.arange(-max_lag, max_lag + 1)
    G = lt.evaluate(grid, lags).real
    modal = np.empty((n, n))
    m = np.arange(n)
    phi_in_lo, phi_out_lo = ctx.phi_c[:, low], phi_o[:, low]
    for i in range(n):
        at = i - m - k[i] * n + max_lag
        modal[i] = np.einsum("p,mp,pm->m", phi_out_lo[i], phi_in_lo, G[:r_lo, at], optimize=True)
        if q:
            modal[i] += _virtual_row(phi_o[i, ~low], ctx.phi_hi, ctx.basis, G[r_lo:, at])
    op = _reduce(modal, _combine(H2, J), J, n)
    if cb.origin_m:
        shift = int(round(cb.origin_m / (s.speed_m_s * dt)))
        op = np.roll(op, (shift, shift), axis=(0, 1))
    return op


def _virtual_row(phi_out_hi: np.ndarray, phi_in_hi: np.ndarray, basis: np.ndarray, g: np.ndarray) -> np.ndarray:
    """sum_j (sum_p l_j(u_p) phi_p(y) phi_p(x_m)) g_j(lag_m) for one observed point y: the modes above the cut
    through the virtual modes (operators.py `_virtual_modes`)."""
    coupling = (phi_in_hi * phi_out_hi[None, :]) @ basis  # [m, j]
    return np.einsum("mj,jm->m", coupling, g)


def pair_cross_operators(cb: ContactBlock, s: PfemSettings, offset_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(I_12, I_21) of a pair with the second contact point at x + offset_m (rows observed, columns loaded):
    I_21 = O(offset); the second point's load at sample m is the first's at m + s, k spans on and k N + s
    samples earlier, so I_12[n, m] = O(-offset)[n + s, m + s] (indices mod N). I_11 is the contact operator
    and I_22[n, m] = I_11[n + s, m + s]."""
    shift = sample_shift(s, offset_m)
    return np.roll(offset_operator(cb, s, -offset_m), (-shift, -shift), axis=(0, 1)), offset_operator(cb, s, offset_m)
