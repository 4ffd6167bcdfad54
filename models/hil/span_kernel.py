"""The virtual HIL's steps compiled a block at a time (models/hil/kernels.py): the periodic iteration (ASM with
step-by-step updating, Paper D eqs. 2 and 10; PFEM with dropper slackening and either updating, Paper C eqs.
34-40, Paper D eq. 3), the rig's delay, drive ramp, servo and load cell (models/rig/chain.py) and the chain
pantograph's HHT step with unilateral contact (models/pantograph/lumped.py), in the fmpy master's Jacobi order
(at step k each model gets the others' outputs of step k-1), equal to the models stepped one call at a time to
the bit. `SpanKernel.of` takes the models the blocks cover and gives None for the others (rig compensation, a
hold, noise, a rig file, the rigid mass, ASM with span-by-span updating), which the engine steps in Python."""
from __future__ import annotations

from collections import deque

import numpy as np

from pantohil.models.catenary.receptance import CirculantOperator
from pantohil.models.compiled import compiled
from pantohil.models.hil.droppers import PfemHil
from pantohil.models.hil.kernels import PAIRWISE_MAX, asm_block, pfem_block
from pantohil.models.hil.loop import PeriodicHil
from pantohil.models.pantograph.lumped import ChainPantograph
from pantohil.models.rig.chain import Rig

ROW_FIELDS = ("command", "z_at_sample", "force_used", "actuator", "measured", "contact_force", "head_height")


def _filter_arrays(flt) -> tuple:
    """A `_DiscreteFilter`'s (b, a, state) as arrays; empty ones for a missing filter."""
    if flt is None:
        return np.zeros(1), np.zeros(1), np.zeros(0)
    return np.array(flt.b, dtype=float), np.array(flt.a, dtype=float), np.array(flt.state, dtype=float)


def _asm_arguments(hil: PeriodicHil):
    """The ASM block's catenary arguments, or None where it does not cover the iteration (span-by-span)."""
    s = hil.s
    if type(hil) is not PeriodicHil or s.update != "step" or type(hil.op) is not CirculantOperator:
        return None
    return asm_block, lambda: (hil.n, s.relaxation, s.delay_steps, s.ramp_steps, hil.op._doubled, hil.z,
                               hil.force_relaxed, hil.last_force)


def _pfem_arguments(hil: PfemHil):
    """The PFEM block's catenary arguments, or None where it does not cover the iteration (sums too long for
    `pairwise_dot`, state arrays not contiguous)."""
    if type(hil) is not PfemHil or hil._basis_at.shape[-1] > PAIRWISE_MAX:
        return None
    state = (hil.z, hil.force_relaxed, hil.last_force, hil.elongation, hil.correction_at)
    if not all(a.flags.c_contiguous for a in state):
        return None
    s, ops = hil.s, hil.ops
    cc, dc, basis_at, dd_at, cd = (np.ascontiguousarray(a, dtype=float)
                                   for a in (ops.cc, hil._dc, hil._basis_at, hil._dd_at, ops.cd))
    f0, kd, below = (np.ascontiguousarray(a, dtype=float) for a in (hil.f0, hil.kd, hil._slack_below))

    def arguments():
        if hil._z_older is hil._z_block:  # the block writes both in place
            hil._z_older = hil._z_block.copy()
        return (hil.n, s.relaxation, s.delay_steps, s.ramp_steps, int(s.update == "span"), cc, dc, hil.z,
                hil.force_relaxed, hil.last_force, hil._z_older, hil._z_block, hil.nd, basis_at, hil.elongation,
                hil.correction_at, below, dd_at, f0, kd, float(hil.mu_d), cd)
    return pfem_block, arguments


class SpanKernel:
    """The three models' state in arrays for the compiled block, and back (`run`)."""

    ROW_FIELDS = ROW_FIELDS

    def __init__(self, fn, catenary_arguments, hil, rig: Rig, pan: ChainPantograph):
        self.fn, self.catenary_arguments, self.hil, self.rig, self.pan = fn, catenary_arguments, hil, rig, pan
        self.new = np.empty(pan._step_free.shape[0])

    @classmethod
    def of(cls, hil, rig, pan) -> SpanKernel | None:
        """The kernel for these models, or None where it does not cover them or kernels are not compiled."""
        if not (type(rig) is Rig and type(pan) is ChainPantograph) or rig.p.noise_std_N > 0:
            return None
        if (getattr(hil, "comp", None) is not None or hil.s.hold_steps > 0 or hil.force_estimate is not hil.last_force
                or pan._step_free.shape[1] > PAIRWISE_MAX):
            return None
        found = _asm_arguments(hil) or _pfem_arguments(hil)
        fn = None if found is None else compiled(found[0])
        return None if fn is None else cls(fn, found[1], hil, rig, pan)

    def run(self, count: int, inputs: np.ndarray, limits: np.ndarray, rows: np.ndarray) -> tuple[int, bool]:
        """Up to `count` steps from `inputs` = [command, actuator, measured, contact force] (updated in place),
        their rows (`ROW_FIELDS`) into `rows`; the models' state is theirs again afterwards. Returns the steps
        taken and whether the last one is beyond the limits (or NaN)."""
        hil, rig, pan = self.hil, self.rig, self.pan
        line = np.array(rig._delay, dtype=float) if rig._delay.maxlen else np.zeros(0)
        ints = np.array([hil.k, 0, rig._count, rig.p.comm_decimation, rig._servo is not None,
                         rig._loadcell is not None], dtype=np.int64)
        sc = np.array([rig._ref_old, rig._ref_new, rig.p.force_offset_N, pan.head_ref, pan.kc, pan.force, pan.z])
        servo, loadcell = _filter_arrays(rig._servo), _filter_arrays(rig._loadcell)
        taken, diverged = self.fn(count, *self.catenary_arguments(), line, ints, sc, servo, loadcell,
                                  pan._step_free, pan._step_act, pan._x, self.new, inputs, limits, rows)
        hil.k = int(ints[0])
        if getattr(hil, "nd", 0):
            hil.current_correction = hil.correction_at[(hil.k - 1) % hil.n]
        if rig._delay.maxlen:
            rig._delay = deque(np.roll(line, -int(ints[1])).tolist(), maxlen=rig._delay.maxlen)
        rig._count, rig._ref_old, rig._ref_new = int(ints[2]), float(sc[0]), float(sc[1])
        for flt, (_, _, state) in ((rig._servo, servo), (rig._loadcell, loadcell)):
            if flt is not None:
                flt.state = state.tolist()
        pan.force, pan.z = float(sc[5]), float(sc[6])
        return int(taken), bool(diverged)
