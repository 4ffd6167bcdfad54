"""The span-to-span map of the virtual HIL loop with the rig's chain in it (Paper D eq. 13 and appendix,
eqs. A.1-A.16, with the pure delay of eqs. A.10-A.11 replaced by the rig's dynamics).

The loop is the one of models/hil/rig_loop.py (and of the FMU master): catenary -> rig (height path) ->
pantograph -> rig (force path) -> catenary, Jacobi-stepped, one step per connection (4). The rig is the
rig file's chain (models/rig/drive_chain.py) without its motion-profile limits: linear, but periodically
time-varying (its N_com decimation and its drive's sub-reference clock repeat every p steps). The
compensation of the rig's response at the kept harmonics (models/rig/compensation.py) enters as the
circulant A (command = (A z)[n + D]) and B (the catenary takes I B f_meas).

- span-by-span: A of Paper D eq. (A.9) on the range of the kept harmonics (as `reduced_span_map`), with
  the state of the connections, the pantograph and the rig chain; the rig's clock makes the map of span b
  depend on b mod P (P = `pattern_spans`), so the rate per span is rho(A_{P-1} ... A_0)^(1/P);
- step-by-step (circulant I A B): the loop is time-invariant from step to step but for the rig's clock,
  so the map over the rig's pattern of p steps, M_p (the one-step matrix of eqs. A.12-A.16 carried over
  p steps), gives the rate per span rho(M_p)^(N/p).
Each is built by running the loop on the unit states (the dense construction of models/stability/maps.py);
with a pure-delay rig both equal the maps of models/stability/maps.py with that latency.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pantohil.models.pantograph.linear import LinearPantograph
from pantohil.models.rig.drive_chain import RigChain, RigSpec
from pantohil.models.rig.drive_chain import pattern_spans as chain_pattern_spans
from pantohil.models.rig.drive_chain import pattern_steps as chain_pattern_steps
from pantohil.models.stability.maps import SpanMap, _layout, circulant_dense, fourier_basis

LOOP_CONNECTIONS = 4  # catenary -> rig -> pantograph -> rig -> catenary, one step each (Jacobi)


def circulant_apply(kernel: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """C X for the circulant C of first column `kernel` (C[t, m] = kernel[(t - m) mod N]), by FFT."""
    n = len(kernel)
    spec = np.fft.rfft(kernel)[:, None] if columns.ndim == 2 else np.fft.rfft(kernel)
    return np.fft.irfft(spec * np.fft.rfft(columns, axis=0), n=n, axis=0)


def inverse_kernel(gains: np.ndarray | None, n: int) -> np.ndarray:
    """The circulant kernel with gain 1/G at harmonics 0..N_h-1 and 1 above (models/rig/compensation.py);
    the identity when `gains` is None (no compensation)."""
    spec = np.ones(n // 2 + 1, dtype=complex)
    if gains is not None:
        spec[: len(gains)] = 1.0 / np.asarray(gains, dtype=complex)
        spec[0] = spec[0].real
        if n % 2 == 0 and len(gains) == n // 2 + 1:
            spec[-1] = spec[-1].real
    return np.fft.irfft(spec, n=n)


def harmonic_basis(n: int, n_harmonics: int) -> np.ndarray:
    """Orthonormal real Fourier basis of harmonics 0..N_h-1 over a span of n samples (the range of any
    operator reduced by W~, Paper D eqs. 4-8)."""
    return fourier_basis(n, range(n_harmonics))


@dataclass
class RigLoop:
    """The linearised loop: pantograph step map, rig chain (None: ideal), compensation gains at the kept
    harmonics (None: not compensated), delay advance D and the model's dt."""

    pantograph: LinearPantograph
    rig: RigSpec | None
    dt_s: float
    delay_steps: int
    height_gains: np.ndarray | None = None  # G_z at harmonics 0..N_h-1 (compensated: A = G_z^-1)
    force_gains: np.ndarray | None = None  # G_f (B = G_f^-1)
    hold_steps: int = 0  # E: the catenary's commands leave E steps late (extra loop delay, Paper D sec. 4)

    def chain_at(self, step: int) -> RigChain | None:
        """The linear rig chain with its clocks at global step `step` (as in a run started at step 0)."""
        if self.rig is None:
            return None
        chain = RigChain(self.rig, self.dt_s, linear=True)
        for _ in range(step):
            chain.step(0.0, 0.0)
        return chain

    def rig_size(self) -> int:
        """Number of state values of the rig chain."""
        return 0 if self.rig is None else len(RigChain(self.rig, self.dt_s, linear=True).state())

    def pattern_steps(self) -> int:
        """Steps after which the rig's clocks repeat (1 without a rig)."""
        return 1 if self.rig is None else chain_pattern_steps(self.rig, self.dt_s)

    def pattern_spans(self, n: int) -> int:
        """Spans after which the rig's clocks are back at the same phase in the span."""
        return 1 if self.rig is None else chain_pattern_spans(self.rig, self.dt_s, n, limit=10**6)


class _Plant:
    """Everything after the catenary in one step of models/hil/rig_loop.py, as rows over the map's state:
    the command in the first connection, the actuator height, the measured force, the pantograph's force
    and state, the rig chain's state."""

    def __init__(self, loop: RigLoop, chain: RigChain | None, X: np.ndarray, blocks: dict):
        self.p, self.chain = loop.pantograph, chain
        self.cmd, self.act, self.meas, self.f = (X[blocks[k]][0].copy() for k in ("cmd", "act", "meas", "f"))
        self.x = X[blocks["pantograph"]].copy()
        self.held = [row.copy() for row in X[blocks["held"]]]
        if chain is not None:
            chain.set_state([row.copy() for row in X[blocks["rig"]]])

    def step(self, command: np.ndarray) -> None:
        """rig.step(cmd, f), pantograph.step(act), then the connections move on (Jacobi)."""
        if self.chain is None:
            act_new, meas_new = self.cmd, self.f
        else:
            act_new, meas_new = self.chain.step(self.cmd, self.f)
        p = self.p
        self.x = p.Pp @ self.x + np.outer(p.pz, self.act) + np.outer(p.pf, self.f)
        self.f = p.c @ self.x + p.cz * self.act
        if self.held:  # the extra loop delay E: the command leaves E steps late
            self.held.append(command)
            command = self.held.pop(0)
        self.cmd, self.act, self.meas = command, act_new, meas_new

    def rows(self) -> list:
        """The plant's rows of the next state, in the layout's order."""
        rig = [np.vstack(self.chain.state())] if self.chain is not None and self.chain.state() else []
        held = [np.vstack(self.held)] if self.held else []
        return [self.cmd[None], self.act[None], self.meas[None], self.f[None], self.x, *rig, *held]


def _plant_sizes(loop: RigLoop) -> dict:
    return {"cmd": 1, "act": 1, "meas": 1, "f": 1, "pantograph": loop.pantograph.size, "rig": loop.rig_size(),
            "held": loop.hold_steps}


@dataclass
class SpanParts:
    """The part of a span's map that does not depend on mu_c: the plant's rows of the next state and the
    force of the span projected on the kept harmonics, Q^T I B f^b, as linear functions of the state."""
    blocks: dict
    plant_rows: np.ndarray
    projected_force: np.ndarray


def rig_span_parts(loop: RigLoop, I_cc: np.ndarray, n_harmonics: int) -> list[SpanParts]:
    """Span-by-span (Paper D eqs. A.1-A.11, the rig chain in place of the delay) for each span b = 0..P-1 of
    the rig's pattern: X = [c, a, plant] with z^(b-2) = Q c, z^(b-1) = Q a and Q the kept harmonics; the
    commands are (A Q)[n + D] blended by eq. (3), the catenary takes I B f_meas."""
    n = I_cc.shape[0]
    Q = harmonic_basis(n, n_harmonics)
    targets = (np.arange(n) + loop.delay_steps) % n
    AQ = circulant_apply(inverse_kernel(loop.height_gains, n), Q)[targets]  # (A Q)[n + D], eq. (A.11)
    QtIB = Q.T @ (I_cc @ circulant_dense(inverse_kernel(loop.force_gains, n)))
    r = Q.shape[1]
    blocks, dim = _layout({"z_older": r, "z": r, **_plant_sizes(loop)})
    w_new = (np.arange(n) + 1) / n
    parts = []
    for b in range(loop.pattern_spans(n)):
        X = np.eye(dim)
        c, a = X[blocks["z_older"]], X[blocks["z"]]
        commands = (1 - w_new)[:, None] * (AQ @ c) + w_new[:, None] * (AQ @ a)  # Paper D eq. (3)
        plant = _Plant(loop, loop.chain_at(b * n), X, blocks)
        block_force = np.empty((n, dim))
        for n_bar in range(n):
            block_force[n_bar] = plant.meas
            plant.step(commands[n_bar])
        parts.append(SpanParts(blocks, np.vstack(plant.rows()), QtIB @ block_force))
    return parts


def rig_span_maps(parts: list[SpanParts], mu: float) -> list[SpanMap]:
    """The span maps at relaxation mu: [c, a] -> [a, mu Q^T I B f^b + (1 - mu) a] (eq. A.8), the plant's rows."""
    maps = []
    for part in parts:
        dim = part.plant_rows.shape[1]
        a = np.eye(dim)[part.blocks["z"]]
        a_new = mu * part.projected_force + (1 - mu) * a
        maps.append(SpanMap(np.vstack([a, a_new, part.plant_rows]), part.blocks, floor=abs(1 - mu)))
    return maps


def rig_step_map(loop: RigLoop, kernel: np.ndarray, mu: float) -> SpanMap:
    """Step-by-step with a circulant I_cc (Paper D eqs. A.12-A.16): the map over the rig's pattern of p steps,
    state g_k = relaxed force of the sample k steps ahead (k = 0..N-1) and the plant; A = M_p^(N/p)."""
    n = len(kernel)
    a_kernel = inverse_kernel(loop.height_gains, n)
    b_kernel = inverse_kernel(loop.force_gains, n)
    aib = circulant_apply(a_kernel, circulant_apply(b_kernel, kernel))  # kernel of A I B
    kappa = aib[(loop.delay_steps - np.arange(n)) % n]  # (A I B)(n + D, n + k)
    blocks, dim = _layout({"rf": n, **_plant_sizes(loop)})
    X = np.eye(dim)
    g = X[blocks["rf"]].copy()
    plant = _Plant(loop, loop.chain_at(0), X, blocks)
    p = loop.pattern_steps()
    for _ in range(p):
        v = (1 - mu) * g[0] + mu * plant.meas  # Paper D eq. (10)
        command = kappa[0] * v + kappa[1:] @ g[1:]
        g = np.vstack([g[1:], v[None]])  # the delay line moves one sample on
        plant.step(command)
    return SpanMap(np.vstack([g, *plant.rows()]), blocks, power=1)


def span_rate(maps: list[SpanMap]) -> float:
    """rho(A_{P-1} ... A_0)^(1/P), at least the floor |1 - mu| of the harmonics' complement."""
    product = maps[0].A
    for m in maps[1:]:
        product = m.A @ product
    rho = float(np.max(np.abs(np.linalg.eigvals(product)))) ** (1.0 / len(maps))
    return max(rho, maps[0].floor)


def step_rate(loop: RigLoop, kernel: np.ndarray, mu: float) -> float:
    """rho(M_p)^(N/p): the rate per span of step-by-step updating with the rig (circulant operator)."""
    m = rig_step_map(loop, kernel, mu)
    with np.errstate(over="ignore"):
        return float(np.max(np.abs(np.linalg.eigvals(m.A)))) ** (len(kernel) / loop.pattern_steps())
