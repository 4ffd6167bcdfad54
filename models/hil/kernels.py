"""The compiled kernels' arithmetic (models/compiled.py): the virtual HIL's steps a block at a time, and the
helpers they share with the models' Python paths.

Each function repeats its Python model's operations in the same order, so that a block stepped here equals the
models stepped one call at a time to the bit: a sum of products is numpy's pairwise row sum
(`row_products`), never a BLAS product, whose fused multiply-adds no loop repeats. Every function of this
module is plain Python that numba compiles; a kernel's compiled cache is keyed on this file, so its helpers
live here too."""
from __future__ import annotations

import math

import numpy as np

from pantohil.models.compiled import inlined


PAIRWISE_BLOCK = 128  # numpy's PW_BLOCKSIZE: a longer sum is split in two (at a multiple of 8), recursively
PAIRWISE_MAX = 248  # the longest sum whose two halves are blocks: what `pairwise_dot` repeats


@inlined
def _pairwise_block(a, b, start, n):
    """(a * b)[start:start + n].sum() for n <= PAIRWISE_BLOCK in numpy's order: one after the other below
    eight, else eight partial sums combined pairwise, then the rest one after the other."""
    if n < 8:
        s = 0.0
        for j in range(start, start + n):
            s += a[j] * b[j]
        return s
    m = start + n - n % 8
    i = start
    r0, r1, r2, r3 = a[i] * b[i], a[i + 1] * b[i + 1], a[i + 2] * b[i + 2], a[i + 3] * b[i + 3]
    r4, r5, r6, r7 = a[i + 4] * b[i + 4], a[i + 5] * b[i + 5], a[i + 6] * b[i + 6], a[i + 7] * b[i + 7]
    for j in range(start + 8, m, 8):
        r0 += a[j] * b[j]
        r1 += a[j + 1] * b[j + 1]
        r2 += a[j + 2] * b[j + 2]
        r3 += a[j + 3] * b[j + 3]
        r4 += a[j + 4] * b[j + 4]
        r5 += a[j + 5] * b[j + 5]
        r6 += a[j + 6] * b[j + 6]
        r7 += a[j + 7] * b[j + 7]
    s = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for j in range(m, start + n):
        s += a[j] * b[j]
    return s


@inlined
def pairwise_dot(a, b):
    """(a * b).sum() of two 1-D arrays of at most PAIRWISE_MAX values, in numpy's order (pairwise_sum)."""
    n = len(a)
    if n <= PAIRWISE_BLOCK:
        return _pairwise_block(a, b, 0, n)
    half = n // 2
    half -= half % 8
    return _pairwise_block(a, b, 0, half) + _pairwise_block(a, b, half, n - half)


@inlined
def row_products(P, x, out, first=0, stop=-1):
    """out[i] = (P * x).sum(axis=1)[i] for rows first..stop-1 (-1: all), in numpy's order (`pairwise_dot`)."""
    for i in range(first, P.shape[0] if stop < 0 else stop):
        out[i] = pairwise_dot(P[i], x)


@inlined
def solve_small(A, b):
    """x with A x = b by Gaussian elimination with partial pivoting, for the few slack droppers of Paper C
    eq. (40); A and b are overwritten. The same arithmetic in Python and compiled."""
    m = len(b)
    for c in range(m):
        p = c
        for i in range(c + 1, m):
            if abs(A[i, c]) > abs(A[p, c]):
                p = i
        if p != c:
            for j in range(m):
                A[c, j], A[p, j] = A[p, j], A[c, j]
            b[c], b[p] = b[p], b[c]
        for i in range(c + 1, m):
            f = A[i, c] / A[c, c]
            for j in range(c, m):
                A[i, j] -= f * A[c, j]
            b[i] -= f * b[c]
    x = np.empty(m)
    for i in range(m - 1, -1, -1):
        s = b[i]
        for j in range(i + 1, m):
            s -= A[i, j] * x[j]
        x[i] = s / A[i, i]
    return x


@inlined
def _filter(b, a, s, x):
    """One sample of a discrete filter in transposed direct form II (`_DiscreteFilter.__call__`)."""
    y = b[0] * x + s[0]
    m = len(s)
    for i in range(m):
        nxt = s[i + 1] if i + 1 < m else 0.0
        s[i] = b[i + 1] * x - a[i + 1] * y + nxt
    return y


@inlined
def _rig_step(cmd, f, line, ints, sc, servo, loadcell):
    """The rig's step (`Rig.step`): the height path (delay, drive ramp, servo) and the force path (load cell,
    offset); `ints` = [k, delay head, drive count, decimation, servo on, load cell on], `sc` = [ref_old,
    ref_new, offset, ...]."""
    zr = cmd
    nd = len(line)
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
    return a_new, m_new + sc[2]


@inlined
def _pantograph_step(act, P_free, P_act, x, new, sc):
    """The chain pantograph's HHT step with unilateral contact (`ChainPantograph.step`): the head's row decides
    the contact state; `sc[3:7]` = [head_ref, k_c, force, z]. Returns the contact force."""
    x[-3], x[-2] = act, sc[5]
    row_products(P_free, x, new, 0, 1)
    gap = sc[3] + new[0] - act
    if gap > 0.0:
        row_products(P_act, x, new)
        gap = sc[3] + new[0] - act
    else:
        row_products(P_free, x, new, 1)
    x[:len(new)] = new
    sc[6] = act
    sc[5] = sc[4] * gap if gap > 0.0 else 0.0
    return sc[5]


@inlined
def _ramped(command, k, ramp):
    """The initial ramp's scale of the command of the step that makes k steps (Paper D sec. 3.6)."""
    if ramp > 0 and k < ramp:
        return command * (k / ramp)
    return command


def asm_block(count, n, mu, delay, ramp, doubled, z, fr, lf, line, ints, sc, servo, loadcell, P_free, P_act, x,
               new, inputs, limits, rows):
    """Up to `count` steps of the ASM iteration (`PeriodicHil.step`, step-by-step: Paper D eqs. 2 and 10), the
    rig and the pantograph; returns (steps taken, 1 if the last one is beyond the limits)."""
    cmd, act, meas, f = inputs[0], inputs[1], inputs[2], inputs[3]
    k, diverged = ints[0], 0
    for step in range(count):
        label = k % n
        if not math.isnan(meas):
            lf[label] = meas
            delta = mu * (meas - fr[label])
            fr[label] += delta
            if delta != 0.0:
                col = doubled[n - label:2 * n - label]  # a view: the loop below then vectorises
                for i in range(n):
                    z[i] += delta * col[i]
        k += 1
        c_new = _ramped(z[(label + delay) % n], k, ramp)
        a_new, m_new = _rig_step(cmd, f, line, ints, sc, servo, loadcell)
        f = _pantograph_step(act, P_free, P_act, x, new, sc)
        cmd, act, meas = c_new, a_new, m_new
        used = lf[label]
        rows[step, 0], rows[step, 1], rows[step, 2], rows[step, 3] = cmd, z[label], used, act
        rows[step, 4], rows[step, 5], rows[step, 6] = meas, f, sc[3] + x[0]
        if not (abs(used) <= limits[0] and abs(cmd) <= limits[1]):  # also NaN
            count, diverged = step + 1, 1
            break
    ints[0] = k
    inputs[0], inputs[1], inputs[2], inputs[3] = cmd, act, meas, f
    return count, diverged


@inlined
def _add_scaled(target, scale, source):
    """target += scale * source, element by element (arrays of one shape, flattened)."""
    t, v = target.reshape(-1), source.reshape(-1)
    for i in range(len(t)):
        t[i] += scale * v[i]


@inlined
def _slack_systems(n_bar, act, na, slack, dl, old, dd_at, B, f0, kd):
    """The new corrections of the active droppers `act[:na]` of phase n_bar, by Paper C eq. (40) for the slack
    ones (0 for the others): `PfemHil._correct`'s several-dropper branch."""
    new = np.zeros(na)
    s = np.empty(na, np.int64)
    ns = 0
    for i in range(na):
        if slack[act[i]]:
            s[ns] = i
            ns += 1
    if ns == 0:
        return new
    D = np.empty((ns, na))  # D[r, a]: elongation of slack dropper r per unit correction of active dropper a
    old_a = np.empty(na)
    for i in range(na):
        old_a[i] = old[act[i]]
    for ri in range(ns):
        d = act[s[ri]]
        for ai in range(na):
            D[ri, ai] = pairwise_dot(dd_at[n_bar, act[ai], d], B[d])
    rhs = np.empty(ns)
    for ri in range(ns):
        d = act[s[ri]]
        rhs[ri] = -f0[d] - kd[d] * (dl[d] - pairwise_dot(D[ri], old_a))
    if ns == 1:
        new[s[0]] = rhs[0] / (1.0 + kd[act[s[0]]] * D[0, s[0]])
        return new
    A = np.empty((ns, ns))
    for ri in range(ns):
        for ci in range(ns):
            A[ri, ci] = (1.0 if ri == ci else 0.0) + kd[act[s[ri]]] * D[ri, s[ci]]
    x = solve_small(A, rhs)
    for ri in range(ns):
        new[s[ri]] = x[ri]
    return new


@inlined
def dropper_corrections(n_bar, basis_at, elong, correction_at, slack_below, dd_at, f0, kd, mu_d, z, cd):
    """Paper C eqs. (36)-(40) at each dropper's instant of phase n_bar (`PfemHil._correct`, in its order)."""
    B = basis_at[n_bar]
    nd = B.shape[0]
    old = correction_at[n_bar]
    dl = np.empty(nd)
    slack = np.empty(nd, np.bool_)
    act = np.empty(nd, np.int64)
    na = 0
    for d in range(nd):
        dl[d] = pairwise_dot(B[d], elong[d])
        slack[d] = dl[d] < slack_below[d]
        if slack[d] or old[d] != 0.0:
            act[na] = d
            na += 1
    if na == 1:
        a = act[0]
        new = 0.0
        if slack[a]:
            daa = pairwise_dot(dd_at[n_bar, a, a], B[a])
            new = (-f0[a] - kd[a] * (dl[a] - daa * old[a])) / (1.0 + kd[a] * daa)
        change = mu_d * (new - old[a])
        old[a] += change
        _add_scaled(z, change, cd[n_bar, a])
        _add_scaled(elong, change, dd_at[n_bar, a])
    elif na > 1:
        new_a = _slack_systems(n_bar, act, na, slack, dl, old, dd_at, B, f0, kd)
        change = np.empty(na)
        for i in range(na):
            change[i] = mu_d * (new_a[i] - old[act[i]])
            old[act[i]] += change[i]
        for i in range(na):
            _add_scaled(z, change[i], cd[n_bar, act[i]])
            _add_scaled(elong, change[i], dd_at[n_bar, act[i]])


def pfem_block(count, n, mu, delay, ramp, span_update, cc, dc, z, fr, lf, z_older, z_block, nd, basis_at, elong,
               correction_at, slack_below, dd_at, f0, kd, mu_d, cd, line, ints, sc, servo, loadcell, P_free, P_act,
               x, new, inputs, limits, rows):
    """Up to `count` steps of the PFEM iteration with dropper slackening (`PfemHil.step`: Paper C eqs. 34-40,
    Paper D eqs. 2, 3 and 10), the rig and the pantograph; returns (steps taken, 1 if the last one is beyond
    the limits)."""
    cmd, act, meas, f = inputs[0], inputs[1], inputs[2], inputs[3]
    k, diverged = ints[0], 0
    for step in range(count):
        label = k % n
        if not math.isnan(meas):
            lf[label] = meas
            delta = mu * (meas - fr[label])
            if delta != 0.0:
                fr[label] += delta
                _add_scaled(z, delta, cc[label])
                if nd:
                    _add_scaled(elong, delta, dc[label])
        if nd:
            dropper_corrections(label, basis_at, elong, correction_at, slack_below, dd_at, f0, kd, mu_d, z, cd)
        target = (label + delay) % n
        if span_update:
            w_new = (label + 1) / n
            c_new = (1.0 - w_new) * z_older[target] + w_new * z_block[target]
            if label == n - 1:
                z_older[:] = z_block
                z_block[:] = z
        else:
            c_new = z[target]
        k += 1
        c_new = _ramped(c_new, k, ramp)
        a_new, m_new = _rig_step(cmd, f, line, ints, sc, servo, loadcell)
        f = _pantograph_step(act, P_free, P_act, x, new, sc)
        cmd, act, meas = c_new, a_new, m_new
        used = lf[label]
        rows[step, 0], rows[step, 1], rows[step, 2], rows[step, 3] = cmd, z[label], used, act
        rows[step, 4], rows[step, 5], rows[step, 6] = meas, f, sc[3] + x[0]
        if not (abs(used) <= limits[0] and abs(cmd) <= limits[1]):  # also NaN
            count, diverged = step + 1, 1
            break
    ints[0] = k
    inputs[0], inputs[1], inputs[2], inputs[3] = cmd, act, meas, f
    return count, diverged
