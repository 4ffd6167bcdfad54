"""Periodic blocks for the PFEM: the academic string of Paper C's appendix and one span of a catenary file
(Paper C sec. 2)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from pantohil.models.catenary.fe.definition import CatenaryDefinition, CatenaryError
from pantohil.models.catenary.fe.model import build_section, form_find
from pantohil.models.catenary.pfem.frf import PeriodicBlock


def linear_shapes(nodes_x: np.ndarray, x: np.ndarray, ndof: int, dof_of_node: np.ndarray) -> sparse.csr_matrix:
    """Rows of linear (string element) shape functions at points x (Paper C Appendix, matrix N)."""
    x = np.asarray(x, dtype=float)
    e = np.clip(np.searchsorted(nodes_x, x, side="right") - 1, 0, len(nodes_x) - 2)
    s = (x - nodes_x[e]) / (nodes_x[e + 1] - nodes_x[e])
    rows = np.repeat(np.arange(len(x)), 2)
    cols = np.stack([dof_of_node[e], dof_of_node[e + 1]], axis=1).ravel()
    vals = np.stack([1 - s, s], axis=1).ravel()
    return sparse.csr_matrix((vals, (rows, cols)), shape=(len(x), ndof))


def hermite_shapes(nodes_x: np.ndarray, x: np.ndarray, ndof: int, w_dof: np.ndarray) -> sparse.csr_matrix:
    """Rows of cubic (beam element) shape functions on (w1, theta1, w2, theta2), theta = w_dof + 1."""
    x = np.asarray(x, dtype=float)
    e = np.clip(np.searchsorted(nodes_x, x, side="right") - 1, 0, len(nodes_x) - 2)
    h = nodes_x[e + 1] - nodes_x[e]
    s = (x - nodes_x[e]) / h
    vals = np.stack(
        [1 - 3 * s**2 + 2 * s**3, h * (s - 2 * s**2 + s**3), 3 * s**2 - 2 * s**3, h * (-(s**2) + s**3)], axis=1
    )
    cols = np.stack([w_dof[e], w_dof[e] + 1, w_dof[e + 1], w_dof[e + 1] + 1], axis=1)
    rows = np.repeat(np.arange(len(x)), 4)
    return sparse.csr_matrix((vals.ravel(), (rows, cols.ravel())), shape=(len(x), ndof))


@dataclass
class ContactBlock:
    """A periodic block with its contact line and, for a catenary, its droppers."""

    block: PeriodicBlock
    contact_shapes: object  # x [m] within the block -> sparse rows (points x dofs)
    dropper_x_m: np.ndarray = None  # dropper abscissae in the block
    dropper_lower: np.ndarray = None  # dof of the dropper's contact-wire end
    dropper_upper: np.ndarray = None  # dof of its messenger end
    dropper_tension_N: np.ndarray = None  # static tension f_d0
    dropper_stiffness_N_m: np.ndarray = None  # axial stiffness k_d
    z0: object = None  # x -> static contact-wire height
    origin_m: float = 0.0  # abscissa along the span of the block's left end (0: a support)

    @property
    def n_droppers(self) -> int:
        """Number of droppers of the block (0 for a string)."""
        return 0 if self.dropper_x_m is None else len(self.dropper_x_m)

    def dropper_shapes(self) -> tuple[sparse.csr_matrix, sparse.csr_matrix]:
        """(elongation rows u_sup - u_inf, correction-load rows +1 at the lower end, -1 at the upper:
        Paper C eqs. 26, 31)."""
        n, nd = self.block.ndof, self.n_droppers
        r = np.arange(nd)
        elong = sparse.csr_matrix(
            (np.r_[np.ones(nd), -np.ones(nd)], (np.r_[r, r], np.r_[self.dropper_upper, self.dropper_lower])),
            shape=(nd, n),
        )
        return elong, -elong


def appendix_block(T=22000.0, mu=1.3, Le=0.75, k=300.0, c=10.0) -> ContactBlock:
    """Paper C Appendix A: two string elements (nodes L, I, R) and a spring-damper on the right node."""
    m = mu * Le / 6 * np.array([[2, 1], [1, 2]])
    ke = T / Le * np.array([[1, -1], [-1, 1]])
    M = np.zeros((3, 3))
    K = np.zeros((3, 3))
    for a in (0, 1):
        M[a:a + 2, a:a + 2] += m
        K[a:a + 2, a:a + 2] += ke
    K[2, 2] += k
    C = np.zeros((3, 3))
    C[2, 2] = c
    nodes = np.array([0.0, Le, 2 * Le])
    blk = PeriodicBlock(M, K, C, [0], [2], 2 * Le)
    return ContactBlock(blk, lambda x: linear_shapes(nodes, x, 3, np.arange(3)))


def _dropper_and_support_terms(cat: CatenaryDefinition, ndof: int, lower, upper, kd: np.ndarray,
                               dropper_mass_kg: np.ndarray, cw_support: int, mw_support: int):
    """What a block adds to its wires' matrices (Paper C sec. 2): each dropper as a bar of stiffness k_d
    between its ends, the steady arm on the contact wire and an elastic messenger support at the block's
    one support; lumped at the dropper ends half the dropper's mass and the clamps, and the arm's mass.
    Returns the stiffness terms (sparse) and the lumped masses (per dof)."""
    r, c, v = [], [], []
    for lo, hi, k in zip(lower, upper, kd, strict=True):
        r += [lo, lo, hi, hi]
        c += [lo, hi, lo, hi]
        v += [k, -k, -k, k]
    r.append(cw_support)
    c.append(cw_support)
    v.append(cat.steady_arm_stiffness_N_m)
    if cat.messenger_support_stiffness_N_m > 0:
        r.append(mw_support)
        c.append(mw_support)
        v.append(cat.messenger_support_stiffness_N_m)
    lump = np.zeros(ndof)
    np.add.at(lump, lower, dropper_mass_kg + cat.clamp_mass_contact_kg)
    np.add.at(lump, upper, dropper_mass_kg + cat.clamp_mass_messenger_kg)
    lump[cw_support] += cat.steady_arm_mass_kg
    return sparse.csr_matrix((v, (r, c)), shape=(ndof, ndof)), lump


def catenary_block(cat: CatenaryDefinition) -> ContactBlock:
    """One span of a catenary file as a periodic block (Paper C sec. 2, Fig. 2), linearised about the
    form-found static state of the central span of three: wires as tensioned beams, droppers as bars,
    the steady arm and the messenger support (when elastic) on the left support only, so that each
    support counts once along the line."""
    if cat.stitch is not None:
        raise CatenaryError("catenary: a stitched catenary's block does not begin at a support "
                            "(use shifted_catenary_block)")
    ff = form_find(cat, 3)
    nd = len(cat.dropper_positions_m)
    lengths = ff.dropper_lengths_m[nd:2 * nd]
    tensions = ff.dropper_tensions_N[nd:2 * nd]
    sec = build_section(cat, 1)
    kd = cat.dropper_axial_stiffness_N / lengths
    g = [d[1] for d in sec.droppers]
    up = [d[2] for d in sec.droppers]
    cw0, mw0 = sec.cw_w[0], sec.mw_w[0]
    cwN, mwN = sec.cw_w[-1], sec.mw_w[-1]
    K_extra, lump = _dropper_and_support_terms(cat, sec.ndof, g, up, kd, cat.dropper_mass_kg_m * lengths / 2, cw0, mw0)
    elastic = cat.messenger_support_stiffness_N_m > 0
    K = sec.K_wires + K_extra
    M = sec.M_wires + sparse.diags(lump)
    keep = np.ones(sec.ndof, dtype=bool)
    if not elastic:
        keep[[mw0, mwN]] = False  # messenger held at the supports
    idx = np.flatnonzero(keep)
    new = -np.ones(sec.ndof, dtype=int)
    new[idx] = np.arange(len(idx))
    K = K.tocsr()[idx][:, idx]
    M = M.tocsr()[idx][:, idx]
    C = cat.alpha_1_s * M + cat.beta_s * K
    left = [cw0, cw0 + 1, mw0, mw0 + 1]
    right = [cwN, cwN + 1, mwN, mwN + 1]
    pairs = [(new[a], new[b]) for a, b in zip(left, right, strict=False) if keep[a]]
    blk = PeriodicBlock(M, K, C, [p[0] for p in pairs], [p[1] for p in pairs], cat.span_m, cat.alpha_1_s, cat.beta_s)
    nodes = sec.x
    w_dof = new[sec.cw_w]
    from pantohil.models.catenary.fe.model import contact_wire_profile

    return ContactBlock(blk, lambda x: hermite_shapes(nodes, x, len(idx), w_dof),
                        np.array(cat.dropper_positions_m, dtype=float), new[np.array(g)], new[np.array(up)],
                        tensions, kd, z0=lambda x: contact_wire_profile(ff, 1, x))


def block_origin_m(cat: CatenaryDefinition, samples_per_span: int) -> float:
    """Where the periodic block of a catenary begins along the span: at the support (0) when nothing
    crosses it but the wires; for a stitched catenary, whose stitch wire spans the support, at the
    contact sample nearest the middle of the dropper interval nearest mid-span, so that the block holds
    the whole stitch with its droppers and its ends lie far from every dropper. A whole number of
    samples, so that shifting the contact point's time origin back is exact."""
    if cat.stitch is None:
        return 0.0
    L = cat.span_m
    xd = np.array(cat.dropper_positions_m, dtype=float)
    mids = 0.5 * (xd[1:] + xd[:-1])
    mid = mids[int(np.argmin(np.abs(mids - L / 2)))]
    step = L / samples_per_span
    return float(round(mid / step) * step)


def shifted_catenary_block(cat: CatenaryDefinition, origin_m: float) -> ContactBlock:
    """One span of a catenary file as a periodic block from `origin_m` to `origin_m` + L (Paper C sec. 2
    with the block's ends inside a span): the block holds one support, with its steady arm, messenger
    support and stitch wire (and the stitch droppers) whole, so that any catenary the FE builder
    accepts is periodic in it. Linearised about the form-found state of the central span of three.
    Abscissae (contact shapes, droppers, z0) are block coordinates x' = x - origin_m."""
    L = cat.span_m
    if not 0.0 < origin_m < L:
        raise CatenaryError(f"catenary: a shifted block must begin inside the span (got {origin_m:g} m)")
    a, b = origin_m, origin_m + L
    if cat.stitch is not None and not (a < L - cat.stitch_length_m / 2 and L + cat.stitch_length_m / 2 < b):
        raise CatenaryError("stitch_wire.length_m: the stitch wire must lie within the block from "
                            f"{a:g} m to {b:g} m")
    ff = form_find(cat, 3)
    nd = len(cat.dropper_positions_m)
    lengths = ff.dropper_lengths_m[nd:2 * nd]
    tensions = ff.dropper_tensions_N[nd:2 * nd]
    sec = build_section(cat, 2, extra_keys=(origin_m,), window_m=(a, b))
    nodes = np.flatnonzero((sec.x >= a - 1e-9) & (sec.x <= b + 1e-9))
    inner_stitch = [w for seg in sec.stitch_w for w in seg[1:-1]]
    dofs = np.concatenate([sec.cw_w[nodes], sec.cw_w[nodes] + 1, sec.mw_w[nodes], sec.mw_w[nodes] + 1,
                           np.array(inner_stitch, dtype=int), np.array(inner_stitch, dtype=int) + 1])
    in_block = [(k, d) for k, d in enumerate(sec.droppers) if a - 1e-9 <= d[0] < b - 1e-9]
    order = np.argsort([d[0] for _, d in in_block])
    in_block = [in_block[i] for i in order]
    span_index = np.array([k % nd for k, _ in in_block])
    g = np.array([d[1] for _, d in in_block])
    up = np.array([d[2] for _, d in in_block])
    kd = cat.dropper_axial_stiffness_N / lengths[span_index]
    n_all = sec.ndof
    support = sec.node(L)
    cw_s, mw_s = sec.cw_w[support], sec.mw_w[support]
    K_extra, lump = _dropper_and_support_terms(cat, n_all, g, up, kd, cat.dropper_mass_kg_m * lengths[span_index] / 2,
                                               cw_s, mw_s)
    if cat.messenger_support_stiffness_N_m <= 0:
        dofs = dofs[dofs != mw_s]  # messenger held at the support
    K = sec.K_wires + K_extra
    M = sec.M_wires + sparse.diags(lump)
    idx = np.sort(dofs)
    new = -np.ones(n_all, dtype=int)
    new[idx] = np.arange(len(idx))
    K = K.tocsr()[idx][:, idx]
    M = M.tocsr()[idx][:, idx]
    C = cat.alpha_1_s * M + cat.beta_s * K
    first, last = nodes[0], nodes[-1]
    left = [sec.cw_w[first], sec.cw_w[first] + 1, sec.mw_w[first], sec.mw_w[first] + 1]
    right = [sec.cw_w[last], sec.cw_w[last] + 1, sec.mw_w[last], sec.mw_w[last] + 1]
    blk = PeriodicBlock(M, K, C, [new[i] for i in left], [new[i] for i in right], L, cat.alpha_1_s, cat.beta_s)
    x_block = sec.x[nodes] - a
    w_dof = new[sec.cw_w[nodes]]
    from pantohil.models.catenary.fe.model import contact_wire_profile

    return ContactBlock(blk, lambda x: hermite_shapes(x_block, x, len(idx), w_dof),
                        np.array([d[0] for _, d in in_block]) - a, new[g], new[up], tensions[span_index], kd,
                        z0=lambda x: contact_wire_profile(ff, 1, np.mod(np.asarray(x) + a, L)), origin_m=a)


def periodic_block(cat: CatenaryDefinition, samples_per_span: int) -> ContactBlock:
    """The PFEM block of a catenary file: from a support when nothing but the wires crosses it, else
    shifted into the span (`block_origin_m`)."""
    origin = block_origin_m(cat, samples_per_span)
    return catenary_block(cat) if origin == 0.0 else shifted_catenary_block(cat, origin)
