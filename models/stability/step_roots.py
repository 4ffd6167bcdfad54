"""Spectral radius of step-by-step updating with a circulant I_cc in O(N r) (Paper D sec. 4, eqs. A.12-A.16).

In the z-domain of the one-step matrix M of models/stability/maps.py (`step_matrix`) the relaxed force of a
sample comes back after N steps, v = (1 - mu) lambda^-N v + mu f; the command is K(lambda) v with
K = kappa_0 + sum_k kappa_k lambda^(k-N); the pantograph closes the loop, f = H(lambda) lambda^-lag z.
So the eigenvalues of M are the zeros of

    f(lambda) = 1 - (1 - mu) lambda^-N - mu H(lambda) lambda^-lag K(lambda),

exactly those of the polynomial p = lambda^(N+lag) d_H f (degree N + lag + deg d_H = dim M), and the span
map's are sigma = lambda^N. Without the loop (H = 0) they are the N roots of lambda^N = 1 - mu, one per
"branch" around the circle. Away from the harmonics I_cc keeps, the loop only nudges its branch's root
(Newton from the unperturbed root converges at once); near them, and for the pantograph's and the
latency's own roots, the roots are found together by the Aberth-Ehrlich iteration with the others
deflated. Cost O(N r) per relaxation instead of the O(N^3) of dense eigenvalues; tested against them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pantohil.models.pantograph.linear import LinearPantograph


@dataclass
class StepLoop:
    """The one-step loop of step-by-step updating with a circulant operator, for its characteristic roots."""
    n: int
    lag: int
    kappa: np.ndarray  # I_cc(n + D, n + k), k = 0..N-1
    w: np.ndarray  # w^-p of the kept harmonics p
    b: np.ndarray  # their share of kappa: kappa_k = sum_p b_p w_p^k
    harmonics: np.ndarray  # branch indices j whose roots the kept harmonics disturb
    h_poles: np.ndarray
    h_residues: np.ndarray
    trace_pantograph: float  # trace of the one-step matrix's pantograph and force rows
    direct: float  # d(force)/d(command) within one step when the latency is one step (lag 0)

    def trace(self, mu: float) -> float:
        """trace(M): the sum of its eigenvalues, checks that the roots found are the right ones."""
        return self.trace_pantograph + (mu * self.direct if self.lag == 0 else 0.0)

    def H(self, lam):
        """The pantograph step's transfer H(lambda) = F / Z from its poles and residues."""
        return (self.h_residues / (lam[..., None] - self.h_poles)).sum(axis=-1)

    def dH(self, lam):
        """dH/dlambda of the pantograph step's transfer."""
        return -(self.h_residues / (lam[..., None] - self.h_poles) ** 2).sum(axis=-1)


def pantograph_transfer(pan: LinearPantograph) -> tuple[np.ndarray, np.ndarray]:
    """Poles and residues of H(lambda) = F/Z of the pantograph's step (state [x, f], output f)."""
    s = pan.size
    A = np.zeros((s + 1, s + 1))
    A[:s, :s], A[:s, s] = pan.Pp, pan.pf
    A[s, :s], A[s, s] = pan.c @ pan.Pp, pan.c @ pan.pf
    B = np.concatenate([pan.pz, [pan.c @ pan.pz + pan.cz]])
    vals, vecs = np.linalg.eig(A)
    return vals, vecs[s] * np.linalg.solve(vecs, B)


def step_loop(kernel: np.ndarray, pan: LinearPantograph, delay_steps: int, latency_steps: int,
              margin: int = 6, rtol: float = 1e-10) -> StepLoop:
    """The one-step loop of a circulant kernel, a pantograph and a delay advance: the harmonics kept,
    the pantograph's poles and residues and the trace terms the root check uses.
    """
    n = len(kernel)
    kappa = kernel[(delay_steps - np.arange(n)) % n]
    spec = np.fft.fft(kappa) / n
    kept = np.nonzero(np.abs(spec) > rtol * np.abs(spec).max())[0]
    # the harmonic p acts on the root near w^-p, branch (-p) mod N; take a margin of branches either side
    near = ((-kept)[:, None] + np.arange(-margin, margin + 1)[None, :]) % n
    poles, residues = pantograph_transfer(pan)
    trace = float(np.trace(pan.Pp) + pan.c @ pan.pf)
    return StepLoop(n, latency_steps - 1, kappa, np.exp(-2j * np.pi * kept / n), spec[kept], np.unique(near), poles,
                    residues, trace, float((pan.c @ pan.pz + pan.cz) * kappa[0]))


def _p_logderiv(loop: StepLoop, lam: np.ndarray, mu: float) -> np.ndarray:
    """p'/p for p = lambda^lag (lambda^N - (1 - mu)) d_H - mu n_H P_K, P_K = lambda^N K (polynomials: no
    overflow for the small roots of the pantograph and the latency), summed directly in O(N) per point."""
    n, lag = loop.n, loop.lag
    k = np.arange(n + 1)
    coef = np.concatenate([[0.0], loop.kappa[1:], [loop.kappa[0]]])  # P_K = kappa_0 lam^N + sum kappa_k lam^k
    powers = np.empty((len(lam), n + 1), dtype=complex)
    powers[:, 0] = 1.0
    powers[:, 1:] = lam[:, None]
    with np.errstate(under="ignore"):
        np.cumprod(powers, axis=1, out=powers)
    P_K = powers @ coef
    dP_K = powers[:, :-1] @ (k[1:] * coef[1:])
    diff = lam[:, None] - loop.h_poles
    d_H = np.prod(diff, axis=1)
    dlog_dH = (1.0 / diff).sum(axis=1)
    H = (loop.h_residues / diff).sum(axis=1)
    n_H = H * d_H
    dn_H = (loop.dH(lam) + H * dlog_dH) * d_H
    lam_n, lam_lag = powers[:, n], lam ** lag
    A = lam_lag * (lam_n - (1.0 - mu)) * d_H
    dA = A * dlog_dH + lam_lag * d_H * (n * lam_n / lam) + (lag * lam_lag / lam * (lam_n - (1.0 - mu)) * d_H
                                                             if lag else 0.0)
    B = mu * n_H * P_K
    dB = mu * (dn_H * P_K + n_H * dP_K)
    return (dA - dB) / (A - B)


def _logderiv(loop: StepLoop, lam: np.ndarray, mu: float) -> np.ndarray:
    """p'/p: from f in O(r) per point where lambda^-N is safe, from the polynomials near 0."""
    out = np.empty(len(lam), dtype=complex)
    small = np.abs(lam) < 0.5
    if small.any():
        out[small] = _p_logderiv(loop, lam[small], mu)
    big = ~small
    if big.any():
        z = lam[big]
        f, df = _f_far(loop, z, mu)
        out[big] = df / f + (loop.n + loop.lag) / z + (1.0 / (z[:, None] - loop.h_poles)).sum(axis=1)
    return out


def _f_far(loop: StepLoop, lam: np.ndarray, mu: float) -> tuple[np.ndarray, np.ndarray]:
    """f and f' with K = (1 - lambda^-N) S, S = sum_p b_p / (1 - w_p / lambda): O(r) per point. Near a kept
    harmonic both factors of a term are small; at the distances the roots keep from them (~1/N) the
    relative error is ~1e-13."""
    n, lag = loop.n, loop.lag
    inv = 1.0 / (lam[:, None] - loop.w[None, :])  # b_p / (1 - w_p / lambda) = b_p lambda / (lambda - w_p)
    S = lam * (inv @ loop.b)
    dS = -((inv * inv) @ (loop.b * loop.w))
    lam_n = lam ** (-n)
    K = (1.0 - lam_n) * S
    dK = n * lam_n / lam * S + (1.0 - lam_n) * dS
    H, dH = loop.H(lam), loop.dH(lam)
    lam_lag = lam ** (-lag)
    f = 1.0 - (1.0 - mu) * lam_n - mu * H * lam_lag * K
    df = (1.0 - mu) * n * lam_n / lam - mu * lam_lag * (dH * K + H * dK - lag * H * K / lam)
    return f, df


def _unperturbed(n: int, mu: float, branches: np.ndarray) -> np.ndarray:
    """Roots of lambda^N = 1 - mu (at mu = 1, where they all collapse to 0, a small circle instead)."""
    c = 1.0 - mu
    radius = max(abs(c), 1e-3) ** (1.0 / n)
    return radius * np.exp(1j * (2 * np.pi * branches + (np.pi if c < 0 else 0.0)) / n)


def _branch_roots(loop: StepLoop, mu: float, branches: np.ndarray, iterations: int = 8):
    """Newton on f from the unperturbed roots (1 - mu)^(1/N) w^j, for branches away from the harmonics.
    Returns the roots and a mask of those that settled close to their own start (the others are left to
    the Aberth iteration: a strongly disturbed branch may have been drawn to a neighbour's root).

    f has real coefficients, so for mu < 1 the root of branch N - j is the conjugate of branch j's: when every
    branch above N/2 has its mirror among the branches (sorted, as `np.setdiff1d` gives them), only the
    branches up to N/2 are solved."""
    n = loop.n
    upper = branches[2 * branches <= n]
    lower = branches[2 * branches > n]
    if mu < 1.0 and len(lower) and np.isin(n - lower, upper).all():
        lam_u, good_u = _newton_roots(loop, mu, upper, iterations)
        mirror = np.searchsorted(upper, n - lower)
        return (np.concatenate([lam_u, np.conj(lam_u[mirror])]),
                np.concatenate([good_u, good_u[mirror]]))
    return _newton_roots(loop, mu, branches, iterations)


def _newton_roots(loop: StepLoop, mu: float, branches: np.ndarray, iterations: int):
    """Newton on f from the unperturbed roots of `branches`; the roots and the mask of those that settled."""
    start = _unperturbed(loop.n, mu, branches)
    lam = start.copy()
    step = np.full(len(lam), np.inf, dtype=complex)
    moving = np.arange(len(lam))
    with np.errstate(all="ignore"):
        for _ in range(iterations):  # a root stops once its step is below the tolerance
            f, df = _f_far(loop, lam[moving], mu)
            step[moving] = f / df
            lam[moving] -= step[moving]
            moving = moving[~(np.abs(step[moving]) <= 1e-14)]
            if len(moving) == 0:
                break
    spacing = 2 * np.pi / loop.n * np.abs(start)
    good = np.isfinite(lam) & (np.abs(step) <= 1e-12) & (np.abs(lam - start) <= 0.25 * spacing)
    return lam, good


def step_eigenvalues(loop: StepLoop, mu: float, tol: float = 1e-12, max_iter: int = 200):
    """All eigenvalues of the one-step matrix (N + lag + pantograph of them) and whether they converged."""
    n = loop.n
    if not 0.0 < mu < 2.0:
        raise ValueError(f"relaxation must lie in (0, 2), got {mu}")
    far = np.setdiff1d(np.arange(n), loop.harmonics)
    roots, good = _branch_roots(loop, mu, far)
    passive = roots[good]
    # active: the disturbed branches, the pantograph's roots and the latency's roots (start near 0)
    start_branches = _unperturbed(n, mu, np.concatenate([loop.harmonics, far[~good]]))
    extra = np.concatenate([loop.h_poles * (1 + 1e-3j), 0.05 * np.exp(2j * np.pi * (np.arange(loop.lag) + 0.25)
                                                                         / max(loop.lag, 1))])
    z = np.concatenate([start_branches, extra]).astype(complex)
    converged = np.zeros(len(z), dtype=bool)
    with np.errstate(all="ignore"):
        for _ in range(max_iter):
            idx = np.nonzero(~converged)[0]
            if len(idx) == 0:
                break
            zi = z[idx]
            logderiv = _logderiv(loop, zi, mu)
            logderiv -= (1.0 / (zi[:, None] - passive)).sum(axis=1)  # deflate the branch roots found by Newton
            diff = zi[:, None] - z[None, :]
            diff[np.arange(len(idx)), idx] = np.inf
            newton = 1.0 / logderiv
            w = newton / (1.0 - newton * (1.0 / diff).sum(axis=1))
            # p has roots at 0 (the latency's: irrelevant to the radius, and log 0); p = 0 exactly: done
            tiny = (np.abs(zi) < 1e-8) | ~np.isfinite(w)
            w = np.where(tiny, 0.0, w)
            z[idx] = zi - w
            converged[idx] = tiny | (np.abs(w) <= tol * np.maximum(np.abs(zi), 1e-3))
    return np.concatenate([passive, z]), bool(converged.all())


def step_spectral_radius(loop: StepLoop, mu: float) -> float:
    """rho of the span map = max |lambda|^N; NaN if the iteration did not converge or the roots found do not
    add up to trace(M) (then use the dense eigenvalues of `step_matrix`)."""
    lam, ok = step_eigenvalues(loop, mu)
    if not ok or abs(lam.sum() - loop.trace(mu)) > 1e-8 * max(1.0, abs(loop.trace(mu))):
        return float("nan")
    with np.errstate(over="ignore"):
        return float(np.max(np.abs(lam)) ** np.float64(loop.n))
