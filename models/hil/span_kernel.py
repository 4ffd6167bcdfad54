"""The virtual HIL's steps compiled a block at a time: the periodic iteration with step-by-step updating on a
circulant operator (Paper D eqs. 2 and 10), the rig's delay, drive ramp, servo and load cell (models/rig/chain.py)
and the chain pantograph's HHT step with unilateral contact (models/pantograph/lumped.py), in the fmpy master's
Jacobi order (at step k each model gets the others' outputs of step k-1).

Each kernel repeats its Python model's operations in the same order, so that a block stepped here equals the
models stepped one call at a time to the bit: `ChainPantograph.step` forms its products as numpy's
pairwise row sums, which `_row_products` repeats. `SpanKernel.of` takes the models that it covers and gives
None for the others (compensation, a hold, noise, a rig file, PFEM), which the engine steps in Python."""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from pantohil.models.catenary.receptance import CirculantOperator
from pantohil.models.compiled import compiled, inlined
from pantohil.models.hil.loop import PeriodicHil
from pantohil.models.pantograph.lumped import ChainPantograph
from pantohil.models.rig.chain import Rig

ROW_FIELDS = ("command", "z_at_sample", "force_used", "actuator", "measured", "contact_force", "head_height")
_IN, _STATE = 4, 7  # the block's inputs (cmd, act, meas, f); the rig's and pantograph's scalars (see `_scalars`)


@inlined
def _row_products(P, x, out):
    """out = (P * x).sum(axis=1) in numpy's order: pairwise with eight partial sums from eight terms on."""
    rows, cols = P.shape
    r = np.empty(8)
    for i in range(rows):
        if cols < 8:
            s = 0.0
            for j in range(cols):
                s += P[i, j] * x[j]
        else:
            for q in range(8):
                r[q] = P[i, q] * x[q]
            j = 8
            while j + 8 <= cols:
                for q in range(8):
                    r[q] += P[i, j + q] * x[j + q]
                j += 8
            s = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
            while j < cols:
                s += P[i, j] * x[j]
                j += 1
        out[i] = s


@inlined
def _filter(b, a, s, x):
    """One sample of a discrete filter in transposed direct form II (`_DiscreteFilter.__call__`)."""
    y = b[0] * x + s[0]
    m = len(s)
    for i in range(m):
        nxt = s[i + 1] if i + 1 < m else 0.0
        s[i] = b[i + 1] * x - a[i + 1] * y + nxt
    return y


def _block(count, k, n, mu, delay, ramp, doubled, z, fr, lf, line, ints, sc, servo, loadcell, P_free, P_act, x,
           new, inputs, limits, rows):
    """Up to `count` steps; returns (steps taken, 1 if the last one diverged). `ints` = [k, delay head, drive
    count, decimation, servo on, load cell on]; `sc` = [ref_old, ref_new, offset, head_ref, k_c, force, z]."""
    cmd, act, meas, f = inputs[0], inputs[1], inputs[2], inputs[3]
    nd = len(line)
    for step in range(count):
        label = k % n  # the catenary: Paper D eqs. (2), (10)
        if not math.isnan(meas):
            lf[label] = meas
            delta = mu * (meas - fr[label])
            fr[label] += delta
            if delta != 0.0:
                col = doubled[n - label:2 * n - label]  # a view: the loop below then vectorises
                for i in range(n):
                    z[i] += delta * col[i]
        c_new = z[(label + delay) % n]
        k += 1
        if ramp > 0 and k < ramp:
            c_new *= k / ramp
        zr = cmd  # the rig's height path: delay, drive ramp, servo
        if nd > 0:
            zr = line[ints[1]]
            line[ints[1]] = cmd
            ints[1] = (ints[1] + 1) % nd
        dec = ints[3]
        if dec > 1:
            if ints[2] % dec == 0:
                sc[0], sc[1] = sc[1], zr
            ints[2] += 1
            j = (ints[2] - 1) % dec + 1
            zr = sc[0] + (sc[1] - sc[0]) * j / dec
        a_new = _filter(servo[0], servo[1], servo[2], zr) if ints[4] else zr
        m_new = _filter(loadcell[0], loadcell[1], loadcell[2], f) if ints[5] else f
        m_new += sc[2]
        x[-3], x[-2] = act, sc[5]  # the pantograph's HHT step
        _row_products(P_free, x, new)
        gap = sc[3] + new[0] - act
        if gap > 0.0:
            _row_products(P_act, x, new)
            gap = sc[3] + new[0] - act
        x[:len(new)] = new
        sc[6] = act
        sc[5] = sc[4] * gap if gap > 0.0 else 0.0
        cmd, act, meas, f = c_new, a_new, m_new, sc[5]
        used = lf[label]
        rows[step, 0], rows[step, 1], rows[step, 2], rows[step, 3] = cmd, z[label], used, act
        rows[step, 4], rows[step, 5], rows[step, 6] = meas, f, sc[3] + x[0]
        if not (abs(used) <= limits[0] and abs(cmd) <= limits[1]):
            ints[0] = k
            inputs[0], inputs[1], inputs[2], inputs[3] = cmd, act, meas, f
            return step + 1, 1
    ints[0] = k
    inputs[0], inputs[1], inputs[2], inputs[3] = cmd, act, meas, f
    return count, 0


def _filter_arrays(flt) -> tuple:
    """A `_DiscreteFilter`'s (b, a, state) as arrays; empty ones for a missing filter."""
    if flt is None:
        return np.zeros(1), np.zeros(1), np.zeros(0)
    return np.array(flt.b, dtype=float), np.array(flt.a, dtype=float), np.array(flt.state, dtype=float)


class SpanKernel:
    """The three models' state in arrays for the compiled block, and back (`run`)."""

    def __init__(self, fn, hil: PeriodicHil, rig: Rig, pan: ChainPantograph):
        self.fn, self.hil, self.rig, self.pan = fn, hil, rig, pan
        self.doubled = hil.op._doubled
        self.new = np.empty(pan._step_free.shape[0])

    @classmethod
    def of(cls, hil, rig, pan) -> SpanKernel | None:
        """The kernel for these models, or None where it does not cover them or kernels are not compiled."""
        if not (type(hil) is PeriodicHil and type(rig) is Rig and type(pan) is ChainPantograph):
            return None
        s = hil.s
        if (s.update != "step" or hil.comp is not None or s.hold_steps > 0 or rig.p.noise_std_N > 0
                or type(hil.op) is not CirculantOperator or hil.force_estimate is not hil.last_force):
            return None
        fn = compiled(_block)
        return None if fn is None else cls(fn, hil, rig, pan)

    def run(self, count: int, inputs: np.ndarray, limits: np.ndarray, rows: np.ndarray) -> tuple[int, bool]:
        """Up to `count` steps from `inputs` = [command, actuator, measured, contact force] (updated in place),
        their rows (`ROW_FIELDS`) into `rows`; the models' state is theirs again afterwards. Returns the steps
        taken and whether the last one is beyond the limits (or NaN)."""
        hil, rig, pan = self.hil, self.rig, self.pan
        s = hil.s
        line = np.array(rig._delay, dtype=float) if rig._delay.maxlen else np.zeros(0)
        ints = np.array([hil.k, 0, rig._count, rig.p.comm_decimation, rig._servo is not None,
                         rig._loadcell is not None], dtype=np.int64)
        sc = np.array([rig._ref_old, rig._ref_new, rig.p.force_offset_N, pan.head_ref, pan.kc, pan.force, pan.z])
        servo, loadcell = _filter_arrays(rig._servo), _filter_arrays(rig._loadcell)
        taken, diverged = self.fn(count, hil.k, hil.n, s.relaxation, s.delay_steps, s.ramp_steps, self.doubled,
                                  hil.z, hil.force_relaxed, hil.last_force, line, ints, sc, servo, loadcell,
                                  pan._step_free, pan._step_act, pan._x, self.new, inputs, limits, rows)
        hil.k = int(ints[0])
        if rig._delay.maxlen:
            rig._delay = deque(np.roll(line, -int(ints[1])).tolist(), maxlen=rig._delay.maxlen)
        rig._count, rig._ref_old, rig._ref_new = int(ints[2]), float(sc[0]), float(sc[1])
        for flt, (_, _, state) in ((rig._servo, servo), (rig._loadcell, loadcell)):
            if flt is not None:
                flt.state = state.tolist()
        pan.force, pan.z = float(sc[5]), float(sc[6])
        return int(taken), bool(diverged)
