"""The PFEM impulse-response operators of one block in the periodic form of Paper D eqs. (11)-(12):
contact-to-contact I_cc, contact-to-dropper I_dc, dropper-to-contact I_cd and dropper-to-dropper I_dd
(Paper C sec. 3.2 and 5.2), the contact height and the dropper elongations frequency-reduced to N_h
and N_hd harmonics (Paper D sec. 3.5, 3.7).

Each operator entry is the sum of eq. (19) (with the 1/(2 pi) of NOTES.md) over the frequency grid.
Built without the naive N_c^2 x N_f complex terms:
- the fixed-interface modal part of the receptance, sum_p phi_p(x) phi_p(y) / d_p(w), is transformed
  mode by mode into lag functions g_p(m) (one matrix product over the frequency grid for all modes and
  lags), then summed lag by lag;
- the boundary part, Xi(w, x)^T P S^-1 P^H Xi(w, y), has rank n_R (3 for a catenary); its sum over
  the contact points is contracted with the output harmonics first (matrix products), so only the
  2 N_h - 1 harmonics the HIL uses are ever formed. The frequency grid is graded (`pfem.graded_grid`)
  and the transform tapered near w_max (`spectral_taper`); both are measured departures from Paper C.

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
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from pantohil.models.catenary.pfem.frf import FixedInterfaceModel, frequency_grid, graded_grid, transform_weights
from pantohil.models.catenary.pfem.blocks import ContactBlock


@dataclass(frozen=True)
class PfemSettings:
    """Discretisation of the operators (Paper C sec. 6: dw = 0.025 rad/s, w_max = 750 rad/s)."""

    speed_m_s: float
    dt_s: float
    samples_per_span: int
    n_harmonics: int  # N_h: harmonics 0..N_h-1 kept in the contact height
    n_harmonics_dropper: int  # N_hd: harmonics kept in the dropper elongations
    omega_max: float = 750.0
    grid: str = "graded"  # "graded": dw = resolution (alpha + beta w^2); "uniform": dw = d_omega
    resolution: float = 0.094
    d_omega: float = 0.025
    max_step_rad_s: float = 0.5
    taper: float = 0.25  # fraction of [0, w_max] over which the transform is tapered to zero


@dataclass
class PfemOperators:
    """Operators stored by the column the HIL step uses, so that each update reads contiguous memory.

    cc[m]          : height at every sample n per unit contact force at sample m (N x N)
    dc[m, d]       : harmonics 0..N_hd-1 (over the window index) of the elongation of dropper d per
                     unit contact force at m (N x N_d x N_hd, complex, rfft convention)
    cd[m, d]       : height at every n per unit correction of dropper d at the instant of phase m
    dd[d, i, e]    : harmonics of the elongation of dropper e per unit correction of dropper d at its
                     window index i (N_d x N x N_d x N_hd, complex)
    """

    settings: PfemSettings
    cc: np.ndarray
    dc: np.ndarray
    cd: np.ndarray
    dd: np.ndarray
    z0: np.ndarray  # static contact-point height at the N samples, unreduced
    window_start: np.ndarray  # first instant of each dropper's window (may be negative)
    dropper_tension_N: np.ndarray
    dropper_stiffness_N_m: np.ndarray
    dropper_x_m: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of contact samples N of the block."""
        return self.cc.shape[0]

    @property
    def n_droppers(self) -> int:
        """Number of droppers of the block."""
        return len(self.dropper_x_m)


def dropper_windows(x_m: np.ndarray, speed_m_s: float, dt_s: float, n: int) -> np.ndarray:
    """First instant of each dropper's correction window: N samples centred on its passage."""
    return np.round(np.asarray(x_m) / (speed_m_s * dt_s)).astype(int) - n // 2


def _real_times_complex(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A @ B for real A and complex B, as one real matrix product."""
    B = np.ascontiguousarray(B)
    return (A @ B.view(np.float64)).view(np.complex128)


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


@dataclass(frozen=True)
class _BuildContext:
    """The fixed quantities of one operator build: model, functionals, windows, lags and contact harmonics."""

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
    lags: np.ndarray
    E_c: np.ndarray
    rows_c: int
    t_win: np.ndarray


@dataclass
class _FrequencySums:
    """The sums over the frequency grid that the chunks accumulate (modal lag functions, boundary parts)."""

    G: np.ndarray  # fixed-interface modal lag functions g_p(m)
    H2: np.ndarray  # boundary part: contact harmonics x contact load
    H2_dc: np.ndarray  # boundary part: elongation at window index i x contact load
    H2_cd: np.ndarray  # contact harmonics x dropper load lag
    dd_lag: np.ndarray

    @classmethod
    def zeros(cls, ctx: _BuildContext) -> _FrequencySums:
        """All sums at zero, sized for the build."""
        nd, n, rows_c, n_lags = ctx.nd, ctx.n, ctx.rows_c, len(ctx.lags)
        return cls(np.zeros((ctx.r, n_lags)), np.zeros((rows_c, n), dtype=complex),
                   np.zeros((nd, n, n), dtype=complex), np.zeros((nd, rows_c, n_lags), dtype=complex),
                   np.zeros((nd, nd, n_lags)))


def _build_context(cb: ContactBlock, s: PfemSettings, period: float,
                   J: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, _BuildContext]:
    """Frequency grid and tapered weights, contact samples and the fixed quantities of the build."""
    n, dt = s.samples_per_span, s.dt_s
    omega, w = operator_grid(s, cb.block.alpha, cb.block.beta)
    w = w * spectral_taper(omega, s.omega_max, s.taper)
    fim = FixedInterfaceModel.build(cb.block, period)
    x = np.arange(n) * s.speed_m_s * dt
    psi_c, phi_c = fim.functionals(cb.contact_shapes(x))
    nd = cb.n_droppers
    nB, r = len(fim.boundary), len(fim.lam)
    if nd:
        elong, _ = cb.dropper_shapes()
        psi_e, phi_e = fim.functionals(elong)
        win = dropper_windows(cb.dropper_x_m, s.speed_m_s, dt, n)
    else:
        psi_e, phi_e = np.zeros((0, nB)), np.zeros((0, r))
        win = np.zeros(0, dtype=int)
    ii = np.arange(n)
    lag0 = 2 * n
    lags = np.arange(-lag0, lag0 + 1)
    jc = np.arange(-(J - 1), J)
    E_c = np.exp(-2j * np.pi * np.outer(jc, ii) / n)
    t_win = (win[:, None] + ii[None, :]) * dt  # [d, i] instants of each window
    ctx = _BuildContext(fim, psi_c, phi_c, psi_e, phi_e, win, n, nd, nB, r, dt, ii, lag0, lags, E_c, len(jc), t_win)
    return omega, w, x, ctx


def _accumulate_dropper_chunk(ctx: _BuildContext, acc: _FrequencySums, om: np.ndarray, wk: np.ndarray,
                              B: np.ndarray, dp: np.ndarray, S: np.ndarray, P: np.ndarray, U: np.ndarray,
                              Yc: np.ndarray, Xi_e: np.ndarray) -> None:
    """Add one chunk of frequencies to the dropper sums (contact-to-dropper, dropper-to-contact, dropper-to-dropper)."""
    nd, rows_c, kc, phi_e = ctx.nd, ctx.rows_c, len(om), ctx.phi_e
    Md = np.einsum("kbd,nkb->dkn", U[:, :, rows_c:], Yc)  # [d, k, n_hat]
    for d in range(nd):
        acc.H2_dc[d] += np.exp(1j * np.outer(ctx.t_win[d], om)) @ Md[d]  # [i, n_hat]
    s_cd = -np.einsum("kbj,dkb->djk", U[:, :, :rows_c], Xi_e)  # load = -elongation functional
    acc.H2_cd += (s_cd.reshape(-1, kc) @ np.conj(B)).reshape(nd, rows_c, len(ctx.lags))  # exp(-i w t' dt)
    modal = np.einsum("dp,kp,ep->kde", phi_e, 1.0 / dp, phi_e)
    XP = np.einsum("dkb,kbr->kdr", Xi_e, P)
    PX = np.einsum("kbr,dkb->krd", np.conj(P), Xi_e)
    I_dd = -(modal + XP @ np.linalg.solve(S, PX))  # [k, observed, loaded]
    acc.dd_lag += np.real(np.einsum("k,kde,km->dem", wk, I_dd, B))


def _accumulate_chunk(ctx: _BuildContext, acc: _FrequencySums, om: np.ndarray, wk: np.ndarray) -> None:
    """Add one chunk of frequencies (eq. 19) to the modal lag functions and the boundary-part sums."""
    n, nd, nB, r, dt, lag0, rows_c, fim = ctx.n, ctx.nd, ctx.nB, ctx.r, ctx.dt, ctx.lag0, ctx.rows_c, ctx.fim
    kc = len(om)
    c, dp, S, P = fim.coefficients(om)
    B = np.exp(1j * np.outer(om, ctx.lags * dt))  # [k, lag]
    acc.G += np.real((wk[:, None] / dp).T @ B)
    Q = np.ascontiguousarray(
        ((c[:, None] / dp)[:, :, None] * fim.M_qB[None]).transpose(1, 0, 2).reshape(r, kc * nB)
    )
    Xi_c = ctx.psi_c[:, None, :] - _real_times_complex(ctx.phi_c, Q).reshape(n, kc, nB)  # [n, k, B]
    ph = B[:, lag0:lag0 + n].T  # exp(i w_k n dt) [n, k]
    A_c = (ctx.E_c @ (ph[:, :, None] * Xi_c).reshape(n, kc * nB)).reshape(rows_c, kc, nB)
    Xi_e = ctx.psi_e[:, None, :] - _real_times_complex(ctx.phi_e, Q).reshape(nd, kc, nB)  # [d, k, B]
    A = np.concatenate([A_c, Xi_e]) if nd else A_c  # output functionals: contact harmonics, elongations
    PTA = np.einsum("kbr,xkb->krx", P, A)
    V = np.linalg.solve(np.transpose(S, (0, 2, 1)), PTA)  # S^-T P^T A
    U = (np.conj(P) @ V) * wk[:, None, None]  # [k, B, row]
    Yc = np.conj(ph)[:, :, None] * Xi_c  # a unit load at contact point n_hat at its instant
    acc.H2 += U[:, :, :rows_c].transpose(2, 0, 1).reshape(rows_c, kc * nB) @ Yc.reshape(n, kc * nB).T
    if nd:
        _accumulate_dropper_chunk(ctx, acc, om, wk, B, dp, S, P, U, Yc, Xi_e)


def _contact_operator(ctx: _BuildContext, acc: _FrequencySums, J: int) -> np.ndarray:
    """The contact-to-contact operator (unreduced modal part by lag, plus the boundary harmonics), reduced to J."""
    n, ii, lag0, phi_c, G = ctx.n, ctx.ii, ctx.lag0, ctx.phi_c, acc.G
    cc1 = np.empty((n, n))
    for m in range(-(n - 1), n):  # one lag (diagonal) at a time: sum_p phi_p(x_n) phi_p(x_n-m) g_p(m)
        rows = ii[max(m, 0):n + min(m, 0)]
        cc1[rows, rows - m] = (phi_c[rows] * phi_c[rows - m]) @ G[:, m + lag0]
    return _reduce(cc1, _combine(acc.H2, J), J, n)


def _dropper_operators(ctx: _BuildContext, acc: _FrequencySums, J: int,
                       Jd: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The per-dropper operators dc, cd and dd assembled from the lag functions and boundary sums."""
    n, nd, ii, lag0, win, G = ctx.n, ctx.nd, ctx.ii, ctx.lag0, ctx.win, acc.G
    dc = np.empty((n, nd, Jd), dtype=complex)
    cd = np.empty((n, nd, n))
    dd = np.empty((nd, n, nd, Jd), dtype=complex)
    for d in range(nd):
        Y = ctx.phi_c @ (ctx.phi_e[d][:, None] * G)  # [n_hat or n, lag]
        t = win[d] + ii
        dc1 = Y[ii[None, :], t[:, None] - ii[None, :] + lag0] + np.real(acc.H2_dc[d])  # [i, n_hat]: lag t - n_hat
        dc[:, d, :] = sfft.rfft(dc1, axis=0)[:Jd].T  # Paper D sec. 3.7: N_hd harmonics over the window
        cd1 = -Y[ii[:, None], ii[:, None] - t[None, :] + lag0]  # [n, i']: lag n - t', load = -elongation
        red = _reduce(cd1, _combine(acc.H2_cd[d][:, t + lag0], J), J, n)  # [n, i']
        cd[np.mod(t, n), d, :] = red.T  # by the phase of the correction instant
        for e in range(nd):  # column i' of the Toeplitz operator, reduced over the observed index i
            cols = acc.dd_lag[e, d, ii[:, None] - ii[None, :] + win[e] - win[d] + lag0]  # [i, i']
            dd[d, :, e, :] = sfft.rfft(cols, axis=0)[:Jd].T
    return dc, cd, dd


def build_operators(cb: ContactBlock, s: PfemSettings, progress=None, chunk: int = 300) -> PfemOperators:
    """All operators of a block at one speed and step (Paper C eqs. 19-33, Paper D eqs. 11-12)."""
    t_start = time.perf_counter()
    n, dt = s.samples_per_span, s.dt_s
    period = n * dt
    if abs(period * s.speed_m_s - cb.block.length_m) > 1e-6 * cb.block.length_m:
        raise ValueError("samples_per_span x dt x speed must equal the block length")
    J, Jd = s.n_harmonics, s.n_harmonics_dropper
    omega, w, x, ctx = _build_context(cb, s, period, J)
    nd, win = ctx.nd, ctx.win
    acc = _FrequencySums.zeros(ctx)
    for k0 in range(0, len(omega), chunk):
        om = omega[k0:k0 + chunk]
        wk = w[k0:k0 + chunk]
        _accumulate_chunk(ctx, acc, om, wk)
        if progress is not None:
            progress(min(k0 + len(om), len(omega)), len(omega))
    cc = _contact_operator(ctx, acc, J)
    dc, cd, dd = _dropper_operators(ctx, acc, J, Jd)
    z0 = cb.z0(x) if cb.z0 is not None else np.zeros(n)
    info = {"build_s": time.perf_counter() - t_start, "n_frequencies": len(omega), "grid": s.grid,
            "omega_max": float(omega[-1]), "modes": ctx.r, "boundary_dofs": int(ctx.nB)}
    empty = np.zeros(0)
    ops = PfemOperators(s, np.ascontiguousarray(cc.T), dc, cd, dd, np.asarray(z0, dtype=float), win,
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
