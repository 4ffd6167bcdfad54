"""The PFEM impulse-response operators of one block in the periodic form of Paper D eqs. (11)-(12):
contact-to-contact I_cc, contact-to-dropper I_dc, dropper-to-contact I_cd and dropper-to-dropper I_dd
(Paper C sec. 3.2 and 5.2), the contact height and the dropper elongations frequency-reduced to N_h
and N_hd harmonics (Paper D sec. 3.5, 3.7).

Each operator entry is the sum of eq. (19) (with the 1/(2 pi) of NOTES.md) over the frequency grid.
Built without the naive N_c^2 x N_f complex terms (issue 21: 216 s -> 35 s on a loaded 2-core VM, 85 -> 14 s CPU):
- every sum wanted at whole-sample lags (the fixed-interface modal lag functions g_p(m), contact-to-dropper,
  the dropper-to-contact boundary part, dropper-to-dropper) is a type-1 non-uniform FFT
  (`pfem/lag_transform.py`): per frequency, `width` multiply-adds per function instead of one per lag;
- contact-to-dropper is a sum of lag functions of the contact functional's terms psi_b, phi_p, so no
  (window x contact sample) product is formed per frequency;
- the modes above 4/3 w_max enter the contact functional (and the modal lag functions) through a few
  virtual modes (Chebyshev interpolation of 1 / d_p in 1 / lam_p, `_virtual_modes`);
- the boundary part, Xi(w, x)^T P S^-1 P^H Xi(w, y), has rank n_R (3 for a catenary); its sum over
  the contact points is contracted with the output harmonics first (one FFT over the contact samples),
  so only the 2 N_h - 1 harmonics the HIL uses are ever formed; the contact side and the spreading run
  in single precision (the operators stay within 5e-7 of the double-precision evaluation; the operator
  file stores float32). The frequency grid is graded (`pfem.graded_grid`) and the transform tapered near
  w_max (`spectral_taper`); both are measured departures from Paper C.

Dropper correction forces act in a window of N samples per dropper, centred on the instant the
pantograph passes it (dropper d of the next block while the pantograph approaches, of the previous
one after it): at every step each dropper has exactly one instant to correct (Paper C sec. 5.3 with
N_nd = 1, Paper D eq. 11). Both terms of the elongation (eq. 12) are reduced to N_hd harmonics over
the window, as Paper D sec. 3.7 prescribes, and kept as those harmonics: the elongation of a dropper
lives in a space of N_hd complex coefficients, which makes the online update a few hundred
multiply-adds. The dropper-to-dropper operator depends only on the lag (its ends do not move): it is
computed as one Toeplitz kernel per dropper pair and then reduced column by column.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from pantohil.models.catenary.pfem.frf import FixedInterfaceModel, frequency_grid, graded_grid, transform_weights
from pantohil.models.catenary.pfem.blocks import ContactBlock
from pantohil.models.catenary.pfem.lag_transform import LagTransform
from pantohil.models.catenary.pfem.operator_data import PfemOperators, PfemSettings

NUMERICS_VERSION = 2  # part of the operator cache key: bump when the operators' numbers change


def dropper_windows(x_m: np.ndarray, speed_m_s: float, dt_s: float, n: int) -> np.ndarray:
    """First instant of each dropper's correction window: N samples centred on its passage."""
    return np.round(np.asarray(x_m) / (speed_m_s * dt_s)).astype(int) - n // 2


def _combine(H: np.ndarray, n_keep: int) -> np.ndarray:
    """Harmonics j = 0..n_keep-1 of Re(h) from the complex harmonics H[j] of h for j = -(n_keep-1)..n_keep-1
    (axis 0, index j + n_keep - 1)."""
    c = n_keep - 1
    return 0.5 * (H[c:] + np.conj(H[c::-1]))


def _reduce(term1_rows: np.ndarray, term2_harmonics: np.ndarray, n_keep: int, n: int) -> np.ndarray:
    """irfft of (rfft(term1) + term2) over axis 0, keeping harmonics 0..n_keep-1 (Paper D eq. 6)."""
    spec = sfft.rfft(term1_rows, axis=0)
    spec[:n_keep] += term2_harmonics
    spec[n_keep:] = 0.0
    return sfft.irfft(spec, n=n, axis=0)


def spectral_taper(omega: np.ndarray, omega_max: float, fraction: float) -> np.ndarray:
    """A cosine taper over the top `fraction` of [0, w_max]. Cutting eq. (19) off sharply at w_max turns a
    flat spectrum (a dropper's own bar makes the flexibility between its ends flat far beyond w_max) into
    sinc ringing that decays only as 1/lag, before and after the impulse; with it the per-instant
    dropper correction of eq. (40) diverges (measured). Tapered, each impulse response is compact."""
    if fraction <= 0:
        return np.ones_like(omega)
    start = omega_max * (1 - fraction)
    x = np.clip((omega - start) / (omega_max - start), 0.0, 1.0)
    return 0.5 * (1 + np.cos(np.pi * x))


def operator_grid(s: PfemSettings, alpha: float, beta: float) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies and transform weights of the operators: uniform (Paper C eq. 17) or graded by damping."""
    if s.grid == "uniform":
        omega, _ = frequency_grid(s.dt_s, s.d_omega, s.omega_max)
        return omega, transform_weights(omega, s.dt_s)
    return graded_grid(alpha, beta, s.omega_max, s.resolution, s.max_step_rad_s, s.dt_s)


def _virtual_modes(lam: np.ndarray, omega_max: float, alpha: float, beta: float, ratio: float = 4 / 3,
                   tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The modes above ratio x w_max replaced, in the contact functional, by q virtual modes: 1 / d_p(w) =
    u_p / (e + c u_p) with u_p = 1 / lam_p, e = 1 + i w beta, c = i w alpha - w^2, is smooth in u on (0, u_0]
    for w <= w_max, so Chebyshev interpolation in u gives sum_p a_p / d_p = sum_j (sum_p l_j(u_p) a_p) / d_j
    with lam_j = 1 / u_j. q is the smallest that keeps the interpolation within `tol` of the largest term on
    [0, w_max]. Returns (mask of the modes kept one by one, lam_j, l_j(u_p) as high modes x q)."""
    cut = (ratio * omega_max) ** 2
    low = lam < cut
    u = 1.0 / lam[~low]
    if u.size == 0:
        return low, np.zeros(0), np.zeros((0, 0))
    w = np.linspace(0.0, omega_max, 257)[:, None]
    e, c = 1 + 1j * w * beta, 1j * w * alpha - w**2
    exact = u[None, :] / (e + c * u[None, :])
    scale = np.abs(exact).max()
    for q in range(2, 65):
        j = np.arange(q)
        nodes = 0.5 / cut * (1 + np.cos(np.pi * (2 * j + 1) / (2 * q)))
        diff = u[:, None] - nodes[None, :]
        diff[diff == 0] = 1e-300
        t = (-1.0) ** j * np.sin(np.pi * (2 * j + 1) / (2 * q)) / diff
        basis = t / t.sum(axis=1, keepdims=True)
        approx = (nodes[None, :] / (e + c * nodes[None, :])) @ basis.T
        if np.abs(approx - exact).max() <= tol * scale:
            return low, 1.0 / nodes, basis
    raise ValueError("PFEM: the modes above the cut could not be interpolated (raise the cut ratio)")


@dataclass(frozen=True)
class _BuildContext:
    """The fixed quantities of one operator build: model, functionals, windows, lags and the lag transform."""

    fim: FixedInterfaceModel
    psi_c: np.ndarray
    phi_c: np.ndarray
    psi_e: np.ndarray
    phi_e: np.ndarray
    win: np.ndarray
    n: int
    nd: int
    nB: int
    r: int
    dt: float
    ii: np.ndarray
    lag0: int
    rows_c: int
    harm: np.ndarray  # FFT rows of the contact harmonics -(J-1)..J-1
    low: np.ndarray  # modes kept one by one in the contact functional
    lam_v: np.ndarray  # eigenvalues of the virtual modes that stand for the others
    w_c: np.ndarray  # (n nB) x (low + virtual): phi_p(x_n) M_pb of the contact functional (float32)
    w_v: np.ndarray  # n x (q nB): sum_p l_j(u_p) phi_p(x_n) M_pb, the virtual modes' boundary terms (j, b)
    phi_hi: np.ndarray  # n x (modes above the cut): phi_p(x_n)
    basis: np.ndarray  # (modes above the cut) x q: l_j(u_p)
    wm: np.ndarray  # nd x n x q: sum_p l_j(u_p) phi_p(x_n) phi_p(e_d), the virtual modes' modal terms
    pm_e: np.ndarray  # (nd nB) x r: phi_p(e_d) M_pb of the elongation functional
    phiphi_e: np.ndarray  # r x nd^2: phi_p(e_d) phi_p(e_d')
    lt: LagTransform
    cols: dict  # columns of each family of lag functions in the accumulator
    profile: dict


def _build_context(cb: ContactBlock, s: PfemSettings, period: float, J: int,
                   profile: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, _BuildContext]:
    """Frequency grid and tapered weights, contact samples and the fixed quantities of the build."""
    n, dt = s.samples_per_span, s.dt_s
    omega, w = operator_grid(s, cb.block.alpha, cb.block.beta)
    w = w * spectral_taper(omega, s.omega_max, s.taper)
    t0 = time.perf_counter()
    fim = FixedInterfaceModel.build(cb.block, period)
    profile["fixed-interface model (eigh)"] = time.perf_counter() - t0
    x = np.arange(n) * s.speed_m_s * dt
    psi_c, phi_c = fim.functionals(cb.contact_shapes(x))
    nd, nB, r = cb.n_droppers, len(fim.boundary), len(fim.lam)
    if nd:
        psi_e, phi_e = fim.functionals(cb.dropper_shapes()[0])
        win = dropper_windows(cb.dropper_x_m, s.speed_m_s, dt, n)
    else:
        psi_e, phi_e, win = np.zeros((0, nB)), np.zeros((0, r)), np.zeros(0, dtype=int)
    low, lam_v, basis = _virtual_modes(fim.lam, float(omega[-1]), cb.block.alpha, cb.block.beta)
    m_qb, q = fim.M_qB, len(lam_v)
    w_low = (phi_c[:, None, low] * m_qb[low].T[None]).reshape(n * nB, -1)
    w_virtual = (phi_c[:, None, ~low] * m_qb[~low].T[None]).reshape(n * nB, -1) @ basis
    pm_e = (phi_e[:, None, :] * m_qb.T[None]).reshape(nd * nB, r)
    phiphi_e = (phi_e[:, None, :] * phi_e[None, :, :]).reshape(nd * nd, r).T
    wm = np.einsum("np,dp,pj->dnj", phi_c[:, ~low], phi_e[:, ~low], basis, optimize=True)
    rows_c, r_lo = 2 * J - 1, int(low.sum())
    sizes = {"g": r_lo + q, "dc": nd * (r_lo + nB + q * nB), "cd": nd * rows_c, "dd": nd * nd}
    ends = np.cumsum(list(sizes.values()))
    cols = {k: slice(int(e - v), int(e)) for (k, v), e in zip(sizes.items(), ends, strict=True)}
    lag0 = 2 * n
    ctx = _BuildContext(fim, psi_c, phi_c, psi_e, phi_e, win, n, nd, nB, r, dt, np.arange(n), lag0, rows_c,
                        np.mod(np.arange(-(J - 1), J), n), low, lam_v, np.hstack([w_low, w_virtual]).astype(np.float32),
                        w_virtual.reshape(n, nB, q).transpose(0, 2, 1).reshape(n, q * nB), phi_c[:, ~low], basis, wm,
                        pm_e, phiphi_e, LagTransform(float(omega[-1]) * dt, lag0), cols, profile)
    return omega, w, x, ctx


@dataclass
class _FrequencySums:
    """The sums over the frequency grid: the spread lag-function coefficients and the contact boundary part."""

    grid: np.ndarray  # uniform-grid coefficients of every lag function (LagTransform rows x functions)
    H2: np.ndarray  # boundary part: contact harmonics x contact load
    buffer: np.ndarray  # one chunk's coefficients (frequencies x functions, complex64: the spreading's input), reused

    @classmethod
    def zeros(cls, ctx: _BuildContext, chunk: int) -> _FrequencySums:
        """All sums at zero, sized for the build."""
        n_functions = max(s.stop for s in ctx.cols.values())
        return cls(np.zeros((ctx.lt.n_rows, n_functions), dtype=complex), np.zeros((ctx.rows_c, ctx.n), dtype=complex),
                   np.zeros((chunk, n_functions), dtype=np.complex64))


def _tick(ctx: _BuildContext, key: str, t0: float) -> float:
    now = time.perf_counter()
    ctx.profile[key] = ctx.profile.get(key, 0.0) + now - t0
    return now


def _functionals(ctx: _BuildContext, c: np.ndarray, inv_d: np.ndarray, inv_dv: np.ndarray):
    """Xi(w, x) = psi(x) - c sum_p phi_p(x) M_pB / d_p (the boundary part of the response functional,
    `FixedInterfaceModel.dynamic_constraint`) at the contact samples (n x n_B x k, the modes above the cut
    through the virtual modes) and at the dropper elongations (nd x n_B x k)."""
    kc = len(c)
    q = np.concatenate([c[:, None] * inv_d[:, ctx.low], c[:, None] * inv_dv], axis=1).T
    modal = (ctx.w_c @ np.ascontiguousarray(q, dtype=np.complex64).view(np.float32)).view(np.complex64)
    xi_c = ctx.psi_c.astype(np.float32)[:, :, None] - modal.reshape(ctx.n, ctx.nB, kc)  # complex64
    xi_e = ctx.psi_e[:, :, None] - ((c[:, None] * inv_d) @ ctx.pm_e.T).T.reshape(ctx.nd, ctx.nB, kc)
    return xi_c, xi_e


def _phases(x: np.ndarray, n: int) -> np.ndarray:
    """exp(i x_k m) for m = 0..n-1 (rows), complex64, from sqrt(n) + n / sqrt(n) exponentials per x_k."""
    b = int(np.ceil(np.sqrt(n)))
    low = np.exp(1j * np.outer(np.arange(b), x)).astype(np.complex64)
    high = np.exp(1j * np.outer(np.arange(0, n, b), x)).astype(np.complex64)
    return (high[:, None, :] * low[None, :, :]).reshape(-1, len(x))[:n]


def _accumulate_chunk(ctx: _BuildContext, acc: _FrequencySums, om: np.ndarray, wk: np.ndarray) -> None:
    """Add one chunk of frequencies (eq. 19): the contact boundary part Xi^T P S^-1 P^H Xi reduced to the
    output harmonics, and the coefficients of every lag function, spread onto the lag transform's grid."""
    t0 = time.perf_counter()
    n, nd, nR, rows_c, kc = ctx.n, ctx.nd, ctx.nB // 2, ctx.rows_c, len(om)
    c, dp, S, _ = ctx.fim.coefficients(om)
    inv_d = 1.0 / dp
    inv_dv = 1.0 / ((1 + 1j * om * ctx.fim.beta)[:, None] * ctx.lam_v[None, :] + c[:, None])  # virtual modes
    xi_c, xi_e = _functionals(ctx, c, inv_d, inv_dv)
    t0 = _tick(ctx, "frequency loop: functionals Xi, S", t0)
    E = np.exp(1j * om * ctx.fim.period_s)  # P = [E I; I]: P^T Xi = E Xi_L + Xi_R, P^H Xi = conj(E) Xi_L + Xi_R
    e32 = E.astype(np.complex64)  # the contact side in complex64 (measured: operators within 1e-6)
    ph = _phases(om * ctx.dt, n)  # exp(i w_k n dt) [n, k]
    x_out = e32 * xi_c[:, :nR] + xi_c[:, nR:]
    a_c = sfft.fft(ph[:, None, :] * x_out, axis=0, workers=-1)[ctx.harm]  # contact harmonics [j, a, k]
    xe_in = np.conj(E) * xi_e[:, :nR] + xi_e[:, nR:]
    A = np.concatenate([a_c, E * xi_e[:, :nR] + xi_e[:, nR:]])  # output functionals [row, a, k]
    V = np.linalg.solve(np.transpose(S, (0, 2, 1)), A.transpose(2, 1, 0))  # S^-T P^T A [k, a, row]
    U = V * wk[:, None, None]
    y_in = np.conj(ph)[:, None, :] * (np.conj(e32) * xi_c[:, :nR] + xi_c[:, nR:])  # unit load at n_hat, its instant
    u_c = U[:, :, :rows_c].transpose(2, 1, 0).reshape(rows_c, nR * kc).astype(np.complex64)
    acc.H2 += u_c @ y_in.reshape(n, nR * kc).T
    t0 = _tick(ctx, "frequency loop: contact boundary part (FFT, 3x3 solves, products)", t0)
    coef = acc.buffer[:kc]  # reused: a fresh array per chunk costs its page faults again
    coef[:, ctx.cols["g"]] = np.concatenate([inv_d[:, ctx.low], inv_dv], axis=1) * wk[:, None]
    if nd:
        _dropper_coefficients(ctx, coef, c, inv_d, inv_dv, wk, E, U, xe_in)
    rows, kernel = ctx.lt.spreading(om * ctx.dt)
    acc.grid[rows] += (kernel.astype(np.float32) @ coef.view(np.float32)).view(np.complex64)
    _tick(ctx, "frequency loop: lag-function coefficients and spreading", t0)


def _dropper_coefficients(ctx: _BuildContext, coef: np.ndarray, c: np.ndarray, inv_d: np.ndarray, inv_dv: np.ndarray,
                          wk: np.ndarray, E: np.ndarray, U: np.ndarray, xe_in: np.ndarray) -> None:
    """Per frequency, the coefficients of the dropper lag functions (Paper C eqs. 26-34): contact-to-dropper
    by the terms of the contact functional (modal: w phi_p(e_d) / d_p; boundary: Xi_e^T P S^-1 P^H Xi_c
    with Xi_c = psi - c sum_p phi_p M_pB / d_p, one function per psi_b, per mode below the cut and per virtual
    mode and b; the modal part of the modes above the cut comes from the virtual modes' g_j), the
    dropper-to-contact boundary part by contact harmonic, and dropper-to-dropper. Written in place."""
    kc, nd, nB, rows_c, low = len(c), ctx.nd, ctx.nB, ctx.rows_c, ctx.low
    r, q = int(low.sum()), len(ctx.lam_v)
    u3 = U[:, :, rows_c:]  # [k, a, d], weights included
    u_b = np.concatenate([np.conj(E)[:, None, None] * u3, u3], axis=1).transpose(0, 2, 1)  # conj(P) U: [k, d, b]
    dc = coef[:, ctx.cols["dc"]].reshape(kc, nd, r + nB + q * nB)
    mu = (u_b.reshape(kc * nd, nB) @ ctx.fim.M_qB[low].T).reshape(kc, nd, r)  # sum_b M_pb U_bd
    modal = dc[:, :, :r]
    np.multiply(mu, -c[:, None, None], out=modal)
    modal += wk[:, None, None] * ctx.phi_e[None, :, low]
    modal *= inv_d[:, None, low]
    dc[:, :, r:r + nB] = u_b
    dc[:, :, r + nB:] = ((-c[:, None] * inv_dv)[:, None, :, None] * u_b[:, :, None, :]).reshape(kc, nd, q * nB)
    np.matmul(xe_in.transpose(2, 0, 1), U[:, :, :rows_c], out=coef[:, ctx.cols["cd"]].reshape(kc, nd, rows_c))
    coef[:, ctx.cols["cd"]] *= -1.0
    boundary = np.matmul(u3.transpose(0, 2, 1), xe_in.transpose(2, 1, 0)).reshape(kc, nd * nd)  # [k, observed, loaded]
    coef[:, ctx.cols["dd"]] = -(wk[:, None] * (inv_d @ ctx.phiphi_e) + boundary)


def _contact_operator(ctx: _BuildContext, G: np.ndarray, H2: np.ndarray, J: int) -> np.ndarray:
    """The contact-to-contact operator (unreduced modal part by lag, plus the boundary harmonics), reduced to J:
    the modes below the cut one lag (diagonal) at a time, sum_p phi_p(x_n) phi_p(x_n-m) g_p(m), those above
    through the virtual modes, sum_j (sum_p l_j(u_p) phi_p(x_n) phi_p(x_n_hat)) g_j(n - n_hat)."""
    n, ii, lag0, phi = ctx.n, ctx.ii, ctx.lag0, ctx.phi_c[:, ctx.low]
    r = phi.shape[1]
    cc1 = np.empty((n, n))
    flat = cc1.reshape(-1)
    for m in range(-(n - 1), n):
        a, b = max(m, 0), n + min(m, 0)
        start = a * n + a - m  # element (a, a - m), then down the diagonal
        flat[start:start + (b - a) * (n + 1):n + 1] = (phi[a:b] * phi[a - m:b - m]) @ G[:r, m + lag0]
    toe = ii[:, None] - ii[None, :] + lag0
    for j in range(len(ctx.lam_v)):
        cc1 += ((ctx.phi_hi * ctx.basis[:, j]) @ ctx.phi_hi.T) * G[r + j, toe]
    return _reduce(cc1, _combine(H2, J), J, n)


def _dropper_to_dropper(dd_lag: np.ndarray, win: np.ndarray, n: int, lag0: int, Jd: int) -> np.ndarray:
    """dd[d, i', e, j]: harmonic j over the window index i of dd_lag[e, d, i - i' + win_e - win_d] (the Toeplitz
    dropper-to-dropper operator, Paper D sec. 3.7), every column at once by prefix sums of the sliding DFT."""
    nd = len(win)
    m = np.arange(-(n - 1), n)
    twiddle = np.exp(-2j * np.pi * np.outer(np.arange(Jd), m) / n)  # [j, m]
    ip = np.arange(n)
    back = np.exp(-2j * np.pi * np.outer(ip, np.arange(Jd)) / n)  # [i', j]
    dd = np.empty((nd, n, nd, Jd), dtype=complex)
    for d in range(nd):
        f = dd_lag[np.arange(nd)[:, None], d, m[None, :] + (win[:, None] - win[d]) + lag0]  # [e, m]
        prefix = np.zeros((nd, Jd, 2 * n), dtype=complex)
        np.cumsum(f[:, None, :] * twiddle[None], axis=2, out=prefix[:, :, 1:])
        window = prefix[:, :, 2 * n - 1 - ip] - prefix[:, :, n - 1 - ip]  # sum over i = 0..N-1: [e, j, i']
        dd[d] = window.transpose(2, 0, 1) * back[:, None, :]
    return dd


def _dropper_operators(ctx: _BuildContext, acc: _FrequencySums, G: np.ndarray, J: int,
                       Jd: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The per-dropper operators dc, cd and dd assembled from the lag functions and boundary sums."""
    n, nd, ii, lag0, win, rows_c, lt = ctx.n, ctx.nd, ctx.ii, ctx.lag0, ctx.win, ctx.rows_c, ctx.lt
    if nd == 0:
        return np.zeros((n, 0, Jd), dtype=complex), np.zeros((n, 0, n)), np.zeros((0, n, 0, Jd), dtype=complex)
    lags = np.arange(-lag0, lag0 + 1)
    f_cd = lt.evaluate(acc.grid[:, ctx.cols["cd"]], lags).reshape(nd, rows_c, len(lags))
    dd_lag = lt.evaluate(acc.grid[:, ctx.cols["dd"]], lags).real.reshape(nd, nd, len(lags))
    low, r = ctx.low, int(ctx.low.sum())
    shapes = np.hstack([ctx.phi_c[:, low], ctx.psi_c, ctx.w_v])  # the contact functional's terms, as the dc functions
    toe = ii[:, None] - ii[None, :] + n - 1  # [row, col] -> row - col + N - 1
    dc = np.empty((n, nd, Jd), dtype=complex)
    cd = np.empty((n, nd, n))
    per = shapes.shape[1]
    for d in range(nd):
        first = ctx.cols["dc"].start + d * per
        L = lt.evaluate(acc.grid[:, first:first + per], np.arange(win[d] - n + 1, win[d] + n)).real
        Y = shapes @ L + ctx.wm[d] @ G[r:, lag0 + win[d] - n + 1:lag0 + win[d] + n]  # [n_hat, lag - win_d + N - 1]
        dc1 = Y[ii[None, :], toe]  # [i, n_hat]: lag win_d + i - n_hat
        dc[:, d, :] = sfft.rfft(dc1, axis=0)[:Jd].T  # Paper D sec. 3.7: N_hd harmonics over the window
        g = G[:, lag0 - win[d] - n + 1:lag0 - win[d] + n]
        Y = ctx.phi_c[:, low] @ (ctx.phi_e[d, low][:, None] * g[:r]) + ctx.wm[d] @ g[r:]
        cd1 = -Y[ii[:, None], toe]  # [n, i']: lag n - t', load = -elongation
        t = win[d] + ii
        red = _reduce(cd1, _combine(f_cd[d][:, lag0 - t], J), J, n)  # [n, i']
        cd[np.mod(t, n), d, :] = red.T  # by the phase of the correction instant
    return dc, cd, _dropper_to_dropper(dd_lag, win, n, lag0, Jd)


def _chunk_bounds(cells: np.ndarray, chunk: int, span_cells: float) -> list[int]:
    """Chunks of at most `chunk` frequencies spanning at most `span_cells` cells of the lag transform's grid."""
    bounds = [0]
    while bounds[-1] < len(cells):
        k0 = bounds[-1]
        k1 = min(k0 + chunk, len(cells))
        bounds.append(k0 + max(1, int(np.searchsorted(cells[k0:k1], cells[k0] + span_cells, side="right"))))
    return bounds


def build_operators(cb: ContactBlock, s: PfemSettings, progress=None, chunk: int = 256,
                    span_cells: float = 32.0) -> PfemOperators:
    """All operators of a block at one speed and step (Paper C eqs. 19-33, Paper D eqs. 11-12)."""
    t_start = time.perf_counter()
    n, dt = s.samples_per_span, s.dt_s
    period = n * dt
    if abs(period * s.speed_m_s - cb.block.length_m) > 1e-6 * cb.block.length_m:
        raise ValueError("samples_per_span x dt x speed must equal the block length")
    J, Jd = s.n_harmonics, s.n_harmonics_dropper
    profile: dict = {}
    omega, w, x, ctx = _build_context(cb, s, period, J, profile)
    _tick(ctx, "setup (grid, functionals, virtual modes)", t_start)
    profile["setup (grid, functionals, virtual modes)"] -= profile["fixed-interface model (eigh)"]
    acc = _FrequencySums.zeros(ctx, chunk)
    bounds = _chunk_bounds(omega * dt / ctx.lt.h, chunk, span_cells)
    for k0, k1 in zip(bounds[:-1], bounds[1:], strict=False):
        _accumulate_chunk(ctx, acc, omega[k0:k1], w[k0:k1])
        if progress is not None:
            progress(k1, len(omega))
    t0 = time.perf_counter()
    G = ctx.lt.evaluate(acc.grid[:, ctx.cols["g"]], np.arange(-ctx.lag0, ctx.lag0 + 1)).real
    t0 = _tick(ctx, "lag functions g_p (FFT)", t0)
    cc = _contact_operator(ctx, G, acc.H2, J)
    t0 = _tick(ctx, "contact operator (diagonal loop, reduction)", t0)
    dc, cd, dd = _dropper_operators(ctx, acc, G, J, Jd)
    _tick(ctx, "dropper operators (lag functions, dc, cd, dd)", t0)
    nd = ctx.nd
    z0 = cb.z0(x) if cb.z0 is not None else np.zeros(n)
    info = {"build_s": time.perf_counter() - t_start, "n_frequencies": len(omega), "grid": s.grid,
            "omega_max": float(omega[-1]), "modes": ctx.r, "boundary_dofs": int(ctx.nB),
            "modes_one_by_one": int(ctx.low.sum()), "virtual_modes": len(ctx.lam_v), "chunks": len(bounds) - 1,
            "numerics_version": NUMERICS_VERSION, "profile_s": {k: round(v, 4) for k, v in profile.items()}}
    empty = np.zeros(0)
    ops = PfemOperators(s, np.ascontiguousarray(cc.T), dc, cd, dd, np.asarray(z0, dtype=float), ctx.win,
                        cb.dropper_tension_N if nd else empty, cb.dropper_stiffness_N_m if nd else empty,
                        cb.dropper_x_m if nd else empty, info)
    return to_span_origin(ops, cb.origin_m, cb.block.length_m) if cb.origin_m else ops


def to_span_origin(ops: PfemOperators, origin_m: float, span_m: float) -> PfemOperators:
    """The operators of a block that begins at `origin_m` along the span, re-indexed so that sample 0 is
    the support: a contact sample b of the block is span sample b + s (mod N), s = origin / (V dt). The
    periodic response is the same; only the time origin of the contact point moves, so every index
    that counts samples (loads, observed heights, correction phases, window starts) shifts by s and the
    droppers are put back in span order. Window-relative indices and harmonics are unchanged."""
    st = ops.settings
    shift = origin_m / (st.speed_m_s * st.dt_s)
    s = int(round(shift))
    if abs(shift - s) > 1e-6:
        raise ValueError("the block's origin must lie on a contact sample")
    x = np.mod(ops.dropper_x_m + origin_m, span_m)
    order = np.argsort(x)
    cc = np.roll(ops.cc, (s, s), axis=(0, 1))
    dc = np.roll(ops.dc, s, axis=0)[:, order]
    cd = np.roll(ops.cd, (s, s), axis=(0, 2))[:, order]
    dd = ops.dd[order][:, :, order]
    win = dropper_windows(x[order], st.speed_m_s, st.dt_s, ops.n)
    return PfemOperators(st, np.ascontiguousarray(cc), np.ascontiguousarray(dc), np.ascontiguousarray(cd),
                         np.ascontiguousarray(dd), np.roll(ops.z0, s), win, ops.dropper_tension_N[order],
                         ops.dropper_stiffness_N_m[order], x[order], {**ops.info, "block_origin_m": origin_m})
