"""Periodic blocks for the PFEM: the academic string of Paper C's appendix, a discretised ASM2 string
(the cross-check of the two periodic models) and one span of a catenary file (Paper C sec. 2)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from .asm import AsmParameters
from .catenary_def import CatenaryDefinition, CatenaryError
from .fe_catenary import build_section, form_find
from .pfem import PeriodicBlock


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
    vals = np.stack([1 - 3 * s**2 + 2 * s**3, h * (s - 2 * s**2 + s**3), 3 * s**2 - 2 * s**3, h * (-s**2 + s**3)], axis=1)
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

    @property
    def n_droppers(self) -> int:
        return 0 if self.dropper_x_m is None else len(self.dropper_x_m)

    def dropper_shapes(self) -> tuple[sparse.csr_matrix, sparse.csr_matrix]:
        """(elongation rows u_sup - u_inf, correction-load rows +1 at the lower end, -1 at the upper:
        Paper C eqs. 26, 31)."""
        n, nd = self.block.ndof, self.n_droppers
        r = np.arange(nd)
        elong = sparse.csr_matrix((np.r_[np.ones(nd), -np.ones(nd)], (np.r_[r, r], np.r_[self.dropper_upper, self.dropper_lower])),
                                  shape=(nd, n))
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


def string_block(cat: AsmParameters, span_m: float, n_elements: int) -> ContactBlock:
    """ASM2 (Paper A eq. 7) discretised with linear elements: tension T, density mu, distributed support
    kbar (consistent), C = alpha M + beta K. One node per element end; the last node is the next
    block's first."""
    Le = span_m / n_elements
    n = n_elements + 1
    i = np.arange(n_elements)
    rows = np.concatenate([i, i, i + 1, i + 1])
    cols = np.concatenate([i, i + 1, i, i + 1])
    mk = np.array([2, 1, 1, 2]) / 6.0 * Le
    kk = np.array([1, -1, -1, 1]) / Le
    M = sparse.csr_matrix((np.repeat(mk, n_elements) * cat.density_kg_m, (rows, cols)), shape=(n, n))
    K = sparse.csr_matrix((np.repeat(kk, n_elements) * cat.tension_N
                           + np.repeat(mk, n_elements) * cat.support_stiffness_N_m2, (rows, cols)), shape=(n, n))
    C = cat.alpha_1_s * M + cat.beta_s * K
    blk = PeriodicBlock(M, K, C, [0], [n - 1], span_m, cat.alpha_1_s, cat.beta_s)
    nodes = np.arange(n) * Le
    return ContactBlock(blk, lambda x: linear_shapes(nodes, x, n, np.arange(n)), z0=lambda x: np.zeros_like(x))


def catenary_block(cat: CatenaryDefinition) -> ContactBlock:
    """One span of a catenary file as a periodic block (Paper C sec. 2, Fig. 2), linearised about the
    form-found static state of the central span of three: wires as tensioned beams, droppers as bars,
    the steady arm and the messenger support (when elastic) on the left support only, so that each
    support counts once along the line."""
    if cat.stitch is not None:
        raise CatenaryError("catenary: a PFEM block of a stitched catenary is not supported yet (its stitch wire "
                            "crosses the block boundary)")
    ff = form_find(cat, 3)
    nd = len(cat.dropper_positions_m)
    lengths = ff.dropper_lengths_m[nd:2 * nd]
    tensions = ff.dropper_tensions_N[nd:2 * nd]
    sec = build_section(cat, 1)
    kd = cat.dropper_axial_stiffness_N / lengths
    g = [d[1] for d in sec.droppers]
    up = [d[2] for d in sec.droppers]
    r, c, v = [], [], []
    for a, b, k in zip(g, up, kd):
        r += [a, a, b, b]
        c += [a, b, a, b]
        v += [k, -k, -k, k]
    cw0, mw0 = sec.cw_w[0], sec.mw_w[0]
    cwN, mwN = sec.cw_w[-1], sec.mw_w[-1]
    r.append(cw0)
    c.append(cw0)
    v.append(cat.steady_arm_stiffness_N_m)
    elastic = cat.messenger_support_stiffness_N_m > 0
    if elastic:
        r.append(mw0)
        c.append(mw0)
        v.append(cat.messenger_support_stiffness_N_m)
    K = sec.K_wires + sparse.csr_matrix((v, (r, c)), shape=sec.K_wires.shape)
    lump = np.zeros(sec.ndof)
    dm = cat.dropper_mass_kg_m * lengths / 2
    np.add.at(lump, g, dm + cat.clamp_mass_contact_kg)
    np.add.at(lump, up, dm + cat.clamp_mass_messenger_kg)
    lump[cw0] += cat.steady_arm_mass_kg
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
    pairs = [(new[a], new[b]) for a, b in zip(left, right) if keep[a]]
    blk = PeriodicBlock(M, K, C, [p[0] for p in pairs], [p[1] for p in pairs], cat.span_m, cat.alpha_1_s, cat.beta_s)
    nodes = sec.x
    w_dof = new[sec.cw_w]
    from .fe_catenary import contact_wire_profile

    return ContactBlock(blk, lambda x: hermite_shapes(nodes, x, len(idx), w_dof),
                        np.array(cat.dropper_positions_m, dtype=float), new[np.array(g)], new[np.array(up)],
                        tensions, kd, z0=lambda x: contact_wire_profile(ff, 1, x))
