"""Stability of the virtual HIL iteration (Paper D sec. 4 and appendix, eqs. A.1-A.16).

The virtual HIL test in contact is linear: from one virtual span to the next its state X^b (the
catenary's iteration state, the pantograph's integrator state, the force in hand and the heights in
flight through the loop latency) obeys X^(b+1) = A X^b + B (Paper D eq. 13); the spectral radius of A
decides convergence and is the rate per span. Three constructions of the same radius:

- `span_map`: A itself, by running the loop of models/hil/loop.py on every unit state (any operator, both
  strategies; dense, the reference the others are tested against);
- `reduced_span_map` (span-by-span): A restricted to the range of I_cc. The components of z outside it
  only decay by (1 - mu_c) per span and feed nothing back, so rho(A) = max(rho(A_r), |1 - mu_c|) with A_r
  of size 2 rank(I_cc) + pantograph instead of 2N + pantograph;
- `step_matrix` (step-by-step, circulant I_cc): for a circulant operator the step-by-step loop is
  time-invariant from one step to the next (the relaxed forces form a delay line of N samples), so A is
  the N-th power of a one-step matrix M and rho(A) = rho(M)^N.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from pantohil.models.hil.loop import HilSettings
from pantohil.models.pantograph.linear import LinearPantograph


@dataclass
class SpanMap:
    """The span-to-span map X^(b+1) = A X^b + B of the HIL iteration (Paper D eq. 13), with its state blocks."""
    A: np.ndarray
    blocks: dict  # name -> slice of the state vector
    floor: float = 0.0  # spectral radius of the part left out of A (reduced maps)
    power: int = 1  # A is a one-step matrix whose power is the span map

    @property
    def spectral_radius(self) -> float:
        """rho(A)^power, at least the radius of the part a reduced map leaves out (Paper D eq. 13)."""
        rho = float(np.max(np.abs(np.linalg.eigvals(self.A)))) ** self.power
        return max(rho, self.floor)


def circulant_dense(kernel: np.ndarray) -> np.ndarray:
    """The N x N circulant operator whose column m is np.roll(kernel, m)."""
    n = len(kernel)
    return kernel[(np.arange(n)[:, None] - np.arange(n)[None, :]) % n]


def _layout(sizes: dict) -> tuple[dict, int]:
    blocks, start = {}, 0
    for name, size in sizes.items():
        blocks[name] = slice(start, start + size)
        start += size
    return blocks, start


class QueuedRankOne:
    """The step-by-step map's rank-one updates X[i] += outer(C[i][j][:, m], delta_j) of P contact points (Paper D
    eq. 10 on every unit state at once; X is P x N x dim, C[i][j] N x N), queued and applied a block of steps at a
    time as matrix products; a row read in between is the applied row plus the queued updates' share of it. The
    same sums as updating X at every step, in another order (equal to rounding), without rewriting all of X at
    each step when one row of it is read."""

    BLOCK = 32

    def __init__(self, X: np.ndarray, C):
        self.X, self.C = X, C
        self.columns = np.zeros(self.BLOCK, dtype=int)
        self.points = X.shape[0]
        self.deltas = np.zeros((self.points, self.BLOCK, X.shape[2]))
        self.count = 0

    def open(self, m: int) -> None:
        """Queue the updates of column m (each point's delta zero until `set`)."""
        if self.count == self.BLOCK:
            self.flush()
        self.columns[self.count] = m
        self.deltas[:, self.count] = 0.0
        self.count += 1

    def set(self, j: int, delta: np.ndarray) -> None:
        """Point j's delta for the column opened last."""
        self.deltas[j, self.count - 1] = delta

    def row(self, i: int, r: int) -> np.ndarray:
        """X[i, r] with the queued updates."""
        k = self.columns[:self.count]
        return self.X[i, r] + sum(self.C[i][j][r, k] @ self.deltas[j, :self.count] for j in range(self.points))

    def flush(self) -> None:
        """Apply the queued updates to X."""
        k = self.columns[:self.count]
        for i in range(self.points):
            for j in range(self.points):
                self.X[i] += self.C[i][j][:, k] @ self.deltas[j, :self.count]
        self.count = 0


def span_map(I_cc: np.ndarray, pan: LinearPantograph, settings: HilSettings, latency_steps: int) -> SpanMap:
    """A of X^(b+1) = A X^b (Paper D eqs. A.1-A.16) for the loop of models/hil/loop.py, with `latency_steps`
    between a force sample and the height it produces (1 = the thesis's unavoidable step)."""
    n = I_cc.shape[0]
    lag = latency_steps - 1  # heights in flight between the catenary and the pantograph
    span = settings.update == "span"
    blocks, dim = _layout({"z_older": n if span else 0, "z": n if span else 0, "rf": 0 if span else n,
                           "pantograph": pan.size, "force": 1, "in_flight": lag})
    X = np.eye(dim)
    if span:
        z_older, z = X[blocks["z_older"]].copy(), X[blocks["z"]].copy()
    else:  # the catenary's z is I rf in step-by-step updating: keep them consistent
        rf = X[blocks["rf"]].copy()
        z = I_cc @ rf
        z_updates = QueuedRankOne(z[None], [[I_cc]])
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
                z_older, z = z, mu * (I_cc @ block_force) + (1 - mu) * z
        else:  # Paper D eq. (10)
            delta = mu * (force - rf[n_bar])
            rf[n_bar] += delta
            z_updates.open(n_bar)
            z_updates.set(0, delta)
            command = z_updates.row(0, target)
        flight.append(command)
        z_act = flight.popleft()
        pan_state = pan.Pp @ pan_state + np.outer(pan.pz, z_act) + np.outer(pan.pf, force)
        force = pan.c @ pan_state + pan.cz * z_act
    rows = [z_older, z] if span else [rf]
    rows += [pan_state, force[None, :]]
    rows += [np.vstack(list(flight))] if lag else []
    return SpanMap(np.vstack(rows), blocks)


def range_basis(I_cc: np.ndarray, rtol: float = 1e-10) -> np.ndarray:
    """Orthonormal basis of the range of I_cc (the harmonics the frequency reduction keeps)."""
    u, s, _ = np.linalg.svd(I_cc)
    return u[:, s > rtol * s[0]]


def circulant_range_basis(kernel: np.ndarray, rtol: float = 1e-10) -> np.ndarray:
    """Real Fourier basis of the harmonics present in a circulant kernel (its range), without an SVD."""
    n = len(kernel)
    spec = np.abs(np.fft.rfft(kernel))
    return fourier_basis(n, np.nonzero(spec > rtol * spec.max())[0])


def fourier_basis(n: int, harmonics) -> np.ndarray:
    """Orthonormal real Fourier basis of the given harmonics over a span of n samples: a cosine for the
    mean and the Nyquist harmonic, a cosine and a sine for every other."""
    t = np.arange(n)
    cols = []
    for k in harmonics:
        if k == 0 or 2 * k == n:
            cols.append(np.cos(2 * np.pi * k * t / n) / np.sqrt(n))
        else:
            cols += [np.cos(2 * np.pi * k * t / n) * np.sqrt(2 / n), np.sin(2 * np.pi * k * t / n) * np.sqrt(2 / n)]
    return np.column_stack(cols)


@dataclass
class ReducedSpanParts:
    """The span-by-span map on the range of I_cc split by its dependence on mu_c: every row but the new
    iterate's is independent of mu, and that row is mu P + (1 - mu) a (Paper D eq. A.8), so a search over mu
    runs the pantograph over the span once."""
    a: np.ndarray  # the rows of the current iterate a: z_older's new value, and (1 - mu) a
    P: np.ndarray  # Q^T I_cc F: the iterate the span's forces give
    rows_after: np.ndarray  # pantograph, force and heights in flight at the span's end
    blocks: dict

    def at(self, mu: float) -> SpanMap:
        """A at relaxation mu (Paper D eq. A.8 in the basis)."""
        a_new = mu * self.P + (1 - mu) * self.a
        return SpanMap(np.vstack([self.a, a_new, self.rows_after]), self.blocks, floor=abs(1 - mu))


def reduced_span_parts(I_cc: np.ndarray, pan: LinearPantograph, delay_steps: int, latency_steps: int,
                       basis: np.ndarray | None = None) -> ReducedSpanParts:
    """Span-by-span A (Paper D eqs. A.1-A.11) on z = Q a, z_older = Q c with Q a basis of range(I_cc), in the
    parts that do not depend on the relaxation."""
    Q = range_basis(I_cc) if basis is None else basis
    n, r = Q.shape
    lag = latency_steps - 1
    blocks, dim = _layout({"z_older": r, "z": r, "pantograph": pan.size, "force": 1, "in_flight": lag})
    X = np.eye(dim)
    c, a = X[blocks["z_older"]], X[blocks["z"]]
    targets = (np.arange(n) + delay_steps) % n
    w_new = (np.arange(n) + 1) / n
    # every command of the span at once, Paper D eq. (3) with the delay rotation (A.11)
    commands = (1 - w_new)[:, None] * (Q[targets] @ c) + w_new[:, None] * (Q[targets] @ a)
    pan_state = X[blocks["pantograph"]].copy()
    force = X[blocks["force"]][0].copy()
    in_flight = [X[blocks["in_flight"]][i] for i in range(lag)]
    z_act_all = np.vstack(in_flight + [commands])  # heights reaching the pantograph, in order
    block_force = np.empty((n, dim))
    Pp, pz, pf, cc, cz = pan.Pp, pan.pz, pan.pf, pan.c, pan.cz
    for n_bar in range(n):
        block_force[n_bar] = force
        z_act = z_act_all[n_bar]
        pan_state = Pp @ pan_state + np.outer(pz, z_act) + np.outer(pf, force)
        force = cc @ pan_state + cz * z_act
    after = [pan_state, force[None, :]] + ([commands[n - lag:]] if lag else [])
    return ReducedSpanParts(a, Q.T @ (I_cc @ block_force), np.vstack(after), blocks)


def reduced_span_map(I_cc: np.ndarray, pan: LinearPantograph, settings: HilSettings, latency_steps: int,
                     basis: np.ndarray | None = None) -> SpanMap:
    """Span-by-span A (Paper D eqs. A.1-A.11) on z = Q a, z_older = Q c with Q a basis of range(I_cc)."""
    if settings.update != "span":
        raise ValueError("reduced_span_map is for span-by-span updating")
    parts = reduced_span_parts(I_cc, pan, settings.delay_steps, latency_steps, basis)
    return parts.at(settings.relaxation)


def step_matrix(kernel: np.ndarray, pan: LinearPantograph, settings: HilSettings, latency_steps: int) -> SpanMap:
    """One-step matrix M of the step-by-step loop (Paper D eqs. A.12-A.16) for a circulant I_cc; A = M^N.

    State: g_k = the relaxed force of the sample k steps ahead (k = 0..N-1, g_0 is updated now), the
    pantograph, the force in hand and the heights in flight.
    """
    if settings.update != "step":
        raise ValueError("step_matrix is for step-by-step updating")
    n = len(kernel)
    lag = latency_steps - 1
    blocks, dim = _layout({"rf": n, "pantograph": pan.size, "force": 1, "in_flight": lag})
    g, p, f, fl = blocks["rf"], blocks["pantograph"], blocks["force"].start, blocks["in_flight"]
    mu, D = settings.relaxation, settings.delay_steps
    kappa = kernel[(D - np.arange(n)) % n]  # I_cc(n + D, n + k)
    v = np.zeros(dim)  # the relaxed force written at this step, Paper D eq. (10)
    v[g.start], v[f] = 1 - mu, mu
    command = np.zeros(dim)
    command[g] = kappa
    command[g.start] = 0.0
    command += kappa[0] * v
    if lag:
        z_act = np.zeros(dim)
        z_act[fl.start] = 1.0
    else:
        z_act = command
    M = np.zeros((dim, dim))
    M[g.start:g.stop - 1, g.start + 1:g.stop] = np.eye(n - 1)  # the delay line moves one sample on
    M[g.stop - 1] = v
    M[p] = np.outer(pan.pz, z_act) + np.outer(pan.pf, np.eye(dim)[f])
    M[p, p] += pan.Pp
    M[f] = pan.c @ M[p] + pan.cz * z_act
    if lag:
        M[fl.start:fl.stop - 1, fl.start + 1:fl.stop] = np.eye(lag - 1)
        M[fl.stop - 1] = command
    return SpanMap(M, blocks, power=n)
