"""2D (vertical plane) finite-element model of a catenary section of n equal spans (Paper A sec. 2,
Paper C sec. 2): wires as tensioned Euler-Bernoulli beams (bending EI plus the geometric stiffness of
the tension), droppers as two-node vertical bars, lumped clamp and steady-arm masses; consistent mass,
C = alpha M + beta K. Taut-wire (small-slope) approximation: each node carries a height w and a slope.

Static form-finding: the contact wire is solved with its heights prescribed at the dropper and
steady-arm points (design heights, pre-sag included); the reactions there are the dropper tensions
and steady-arm forces. The messenger (and stitch wire) carries those tensions and its own weight from
its supports; the dropper lengths follow, shortened by their elastic stretch. A coupled solve with
the droppers as bars of those lengths checks the design heights.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy import sparse
from scipy.sparse import linalg as spla
from scipy.sparse.csgraph import reverse_cuthill_mckee

from pantohil.models.catenary.fe.definition import CatenaryDefinition, CatenaryError, Wire

GRAVITY_M_S2 = 9.81


def beam_matrices(L: float, wire: Wire):
    """Element stiffness (bending + tension) and consistent mass of a tensioned beam, dofs (w1, t1, w2, t2)."""
    ei, T, m = wire.bending_stiffness_N_m2, wire.tension_N, wire.mass_kg_m
    kb = ei / L**3 * np.array([[12, 6 * L, -12, 6 * L], [6 * L, 4 * L * L, -6 * L, 2 * L * L],
                               [-12, -6 * L, 12, -6 * L], [6 * L, 2 * L * L, -6 * L, 4 * L * L]])
    kg = T / (30 * L) * np.array([[36, 3 * L, -36, 3 * L], [3 * L, 4 * L * L, -3 * L, -L * L],
                                  [-36, -3 * L, 36, -3 * L], [3 * L, -L * L, -3 * L, 4 * L * L]])
    me = m * L / 420 * np.array([[156, 22 * L, 54, -13 * L], [22 * L, 4 * L * L, 13 * L, -3 * L * L],
                                 [54, 13 * L, 156, -22 * L], [-13 * L, -3 * L * L, -22 * L, 4 * L * L]])
    q = -m * GRAVITY_M_S2 * L * np.array([0.5, L / 12, 0.5, -L / 12])  # own weight, consistent
    return kb + kg, me, q


def _grid(cat: CatenaryDefinition, n_spans: int, extra_keys: tuple = ()) -> np.ndarray:
    """Node abscissae of the section: supports, droppers, stitch ends, `extra_keys` (within a span), and
    no element longer than the mesh size."""
    L = cat.span_m
    keys = [0.0, *cat.dropper_positions_m, *extra_keys]
    if cat.stitch is not None:
        keys += [cat.stitch_length_m / 2, L - cat.stitch_length_m / 2]
    keys = np.unique(np.round(keys, 9))
    pts = []
    for j in range(n_spans):
        for a, b in zip(keys, [*keys[1:], L], strict=False):
            k = max(1, int(np.ceil((b - a) / cat.mesh_size_m - 1e-9)))
            pts.extend(j * L + a + (b - a) * np.arange(k) / k)
    pts.append(n_spans * L)
    return np.array(pts)


@dataclass
class Section:
    """Mesh and matrices of an n-span section; heights and dofs of every wire node."""

    cat: CatenaryDefinition
    n_spans: int
    x: np.ndarray  # contact-wire and messenger node abscissae (shared grid)
    stitch_x: list  # per stitch segment: node abscissae (ends are messenger nodes)
    ndof: int
    cw_w: np.ndarray  # dof of the height of each contact-wire node
    mw_w: np.ndarray
    stitch_w: list  # per segment: dofs of its heights (ends = messenger dofs)
    K_wires: sparse.csr_matrix
    M_wires: sparse.csr_matrix
    f_gravity: np.ndarray
    droppers: list  # (x, cw_dof, upper_dof, on_stitch)
    supports: list  # (x, cw_dof, mw_dof)

    def node(self, x: float) -> int:
        """Index of the node at abscissa x (ValueError if none lies there)."""
        i = int(np.argmin(np.abs(self.x - x)))
        if abs(self.x[i] - x) > 1e-6:
            raise ValueError(f"no node at x = {x}")
        return i


def _locate_droppers(cat: CatenaryDefinition, n_spans: int, x: np.ndarray, cw: np.ndarray, mw: np.ndarray,
                     stitch_x: list, stitch_w: list) -> list:
    """(x, contact-wire dof, upper dof, on the stitch wire) of every dropper of the section: a dropper
    within a stitch wire's reach of an interior support hangs from that stitch wire."""
    L = cat.span_m
    droppers = []
    for j in range(n_spans):
        for xd in cat.dropper_positions_m:
            xg = j * L + xd
            i = int(np.argmin(np.abs(x - xg)))
            upper, on_stitch = mw[i], False
            if cat.on_stitch(xd):
                seg = j if xd > L / 2 else j - 1  # the stitch wire of support j+1 or j (interior only)
                if 0 <= seg < len(stitch_x):
                    s = int(np.argmin(np.abs(stitch_x[seg] - xg)))
                    upper, on_stitch = stitch_w[seg][s], True
            droppers.append((xg, cw[i], upper, on_stitch))
    return droppers


def build_section(cat: CatenaryDefinition, n_spans: int, extra_keys: tuple = (),
                  window_m: tuple[float, float] | None = None) -> Section:
    """Mesh and wire matrices of n equal spans (anchored ends), with droppers and supports located.
    With `window_m` = (a, b) only the wire elements within [a, b] are assembled (a periodic block
    that does not begin at a support); `extra_keys` adds nodes at those abscissae of every span."""
    L = cat.span_m
    x = _grid(cat, n_spans, extra_keys)
    n = len(x)
    cw = np.arange(n) * 2
    mw = 2 * n + np.arange(n) * 2
    ndof = 4 * n
    stitch_x, stitch_w = [], []
    if cat.stitch is not None:
        half = cat.stitch_length_m / 2
        for j in range(1, n_spans):  # stitch wires at the interior supports
            xs = x[(x >= j * L - half - 1e-9) & (x <= j * L + half + 1e-9)]
            dofs = [mw[np.argmin(np.abs(x - xs[0]))]]
            for _ in xs[1:-1]:
                dofs.append(ndof)
                ndof += 2
            dofs.append(mw[np.argmin(np.abs(x - xs[-1]))])
            stitch_x.append(xs)
            stitch_w.append(np.array(dofs))
    rows, cols, kv, mv = [], [], [], []
    f = np.zeros(ndof)

    def add_chain(xs, wdofs, wire):
        for a in range(len(xs) - 1):
            if window_m is not None and not (window_m[0] - 1e-9 <= xs[a] and xs[a + 1] <= window_m[1] + 1e-9):
                continue
            ke, me, q = beam_matrices(xs[a + 1] - xs[a], wire)
            d = [wdofs[a], wdofs[a] + 1, wdofs[a + 1], wdofs[a + 1] + 1]
            for r in range(4):
                f[d[r]] += q[r]
                for c in range(4):
                    rows.append(d[r])
                    cols.append(d[c])
                    kv.append(ke[r, c])
                    mv.append(me[r, c])

    add_chain(x, cw, cat.contact)
    add_chain(x, mw, cat.messenger)
    for xs, wd in zip(stitch_x, stitch_w, strict=False):
        add_chain(xs, wd, cat.stitch)
    K = sparse.csr_matrix((kv, (rows, cols)), shape=(ndof, ndof))
    M = sparse.csr_matrix((mv, (rows, cols)), shape=(ndof, ndof))
    droppers = _locate_droppers(cat, n_spans, x, cw, mw, stitch_x, stitch_w)
    supports = [(j * L, cw[int(np.argmin(np.abs(x - j * L)))], mw[int(np.argmin(np.abs(x - j * L)))])
                for j in range(n_spans + 1)]
    return Section(cat, n_spans, x, stitch_x, ndof, cw, mw, stitch_w, K, M, f, droppers, supports)


@dataclass
class FormFinding:
    """The static configuration of a section and its linearised matrices."""

    section: Section
    heights: np.ndarray  # all dofs (heights and slopes)
    dropper_lengths_m: np.ndarray  # per dropper of the section
    dropper_tensions_N: np.ndarray
    steady_arm_forces_N: np.ndarray
    max_height_error_m: float
    K: sparse.csr_matrix  # linearised stiffness (wires, droppers, supports, steady arms)
    M: sparse.csr_matrix
    fixed: np.ndarray  # Dirichlet dofs (messenger supports if fixed, contact wire at the anchors)

    @property
    def C(self) -> sparse.csr_matrix:
        """Rayleigh damping C = alpha M + beta K of the linearised section."""
        cat = self.section.cat
        return (cat.alpha_1_s * self.M + cat.beta_s * self.K).tocsr()

    def free(self) -> np.ndarray:
        """Indices of the dofs not held fixed."""
        mask = np.ones(self.section.ndof, dtype=bool)
        mask[self.fixed] = False
        return np.flatnonzero(mask)


def _solve_dirichlet(K, f, fixed, values):
    """Solve K z = f with z[fixed] = values; return z and the reactions K z - f at the fixed dofs."""
    n = K.shape[0]
    z = np.zeros(n)
    z[fixed] = values
    free = np.setdiff1d(np.arange(n), fixed)
    Kff = K[free][:, free].tocsc()
    z[free] = spla.spsolve(Kff, f[free] - K[free][:, fixed] @ z[fixed])
    return z, (K @ z - f)[fixed]


def form_find(cat: CatenaryDefinition, n_spans: int = 3) -> FormFinding:
    """Dropper lengths and tensions that put the contact wire at its design heights under gravity."""
    sec = build_section(cat, n_spans)
    L = cat.span_m
    g = GRAVITY_M_S2
    cw_dofs = set(sec.cw_w.tolist()) | set((sec.cw_w + 1).tolist())  # heights and slopes of the contact wire
    d_cw = np.array([d[1] for d in sec.droppers])
    d_up = np.array([d[2] for d in sec.droppers])
    s_cw = np.array([s[1] for s in sec.supports])
    s_mw = np.array([s[2] for s in sec.supports])
    lengths = np.full(len(d_cw), cat.encumbrance_m)
    design_d = cat.design_height(np.array([d[0] for d in sec.droppers]) % L)
    for _ in range(3):  # dropper weights depend on their lengths
        dm = cat.dropper_mass_kg_m * lengths / 2
        f = sec.f_gravity.copy()
        np.add.at(f, d_cw, -(dm + cat.clamp_mass_contact_kg) * g)
        np.add.at(f, d_up, -(dm + cat.clamp_mass_messenger_kg) * g)
        f[s_cw] -= cat.steady_arm_mass_kg * g
        # contact wire alone, heights prescribed at droppers and supports
        up_dofs = set(range(sec.ndof)) - cw_dofs
        K_cw = _restrict(sec.K_wires, cw_dofs) + _identity_on(up_dofs, sec.ndof)
        fixed = np.concatenate([d_cw, s_cw])
        z_cw, react = _solve_dirichlet(K_cw, _mask(f, cw_dofs), fixed, np.concatenate([design_d, np.zeros(len(s_cw))]))
        tensions = react[: len(d_cw)]
        arm = react[len(d_cw):]
        # messenger and stitch wire: own weight, dropper tensions pulling down, supports at the encumbrance
        f_up = _mask(f, up_dofs)
        np.add.at(f_up, d_up, -tensions)
        K_up = _restrict(sec.K_wires, up_dofs) + _identity_on(cw_dofs, sec.ndof)
        z_up, _ = _solve_dirichlet(K_up, f_up, s_mw, np.full(len(s_mw), cat.encumbrance_m))
        lengths = z_up[d_up] - z_cw[d_cw]
    _check_droppers(cat, lengths, tensions)
    K, fixed, kd = _linearised_stiffness(cat, sec, lengths)
    dm = cat.dropper_mass_kg_m * lengths / 2
    lump = np.zeros(sec.ndof)
    np.add.at(lump, d_cw, dm + cat.clamp_mass_contact_kg)
    np.add.at(lump, d_up, dm + cat.clamp_mass_messenger_kg)
    lump[s_cw] += cat.steady_arm_mass_kg
    M = (sec.M_wires + sparse.diags(lump)).tocsr()
    # check: the coupled model with droppers of unstretched length (L - F/k) meets the design heights
    unstretched = lengths - tensions / kd
    f = sec.f_gravity.copy()
    np.add.at(f, d_cw, -(dm + cat.clamp_mass_contact_kg) * g - kd * unstretched)  # bar tension k (z_up - z_cw - L0)
    np.add.at(f, d_up, -(dm + cat.clamp_mass_messenger_kg) * g + kd * unstretched)
    f[s_cw] += -cat.steady_arm_mass_kg * g + arm  # the arm's static force; its spring acts about the design height 0
    fixed_static = np.concatenate([s_mw, [s_cw[0], s_cw[-1]]])
    vals = np.concatenate([np.full(len(s_mw), cat.encumbrance_m), [0.0, 0.0]])
    z, _ = _solve_dirichlet(K, f, fixed_static, vals)
    err = float(np.max(np.abs(z[d_cw] - design_d)))
    return FormFinding(sec, z, lengths, tensions, arm, err, K, M, fixed)  # z: the checked static heights


def _check_droppers(cat: CatenaryDefinition, lengths: np.ndarray, tensions: np.ndarray) -> None:
    """Every dropper of positive length and in tension, else CatenaryError naming the key to change."""
    per_span = len(cat.dropper_positions_m)
    for i in np.flatnonzero(lengths <= 0)[:1]:
        key = "catenary.contact_wire_heights_m" if cat.dropper_heights_m is not None else "catenary.presag_m"
        raise CatenaryError(f"{key}: dropper {i % per_span + 1} would need a length of {lengths[i]:.3f} m "
                            f"(the contact wire reaches the messenger: a lower contact wire or more encumbrance)",
                            key=key)
    for i in np.flatnonzero(tensions <= 0)[:1]:
        key = "catenary.presag_m" if cat.presag_m != 0 else "catenary.dropper_positions_m"
        if cat.dropper_heights_m is not None:
            key = "catenary.contact_wire_heights_m"
        raise CatenaryError(f"{key}: dropper {i % per_span + 1} would be in compression ({tensions[i]:.1f} N) to hold "
                            f"the design heights", key=key)


def _linearised_stiffness(cat: CatenaryDefinition, sec, lengths: np.ndarray):
    """(K, fixed dofs, dropper stiffnesses) about the static state: droppers as bars, steady arms as springs,
    messenger supports fixed or elastic."""
    d_cw = np.array([d[1] for d in sec.droppers])
    d_up = np.array([d[2] for d in sec.droppers])
    s_cw = np.array([s[1] for s in sec.supports])
    s_mw = np.array([s[2] for s in sec.supports])
    kd = cat.dropper_axial_stiffness_N / np.maximum(lengths, 1e-6)
    extra_r, extra_c, extra_v = [], [], []
    for a, b, k in zip(d_cw, d_up, kd, strict=False):
        extra_r += [a, a, b, b]
        extra_c += [a, b, a, b]
        extra_v += [k, -k, -k, k]
    for dof in s_cw:
        extra_r.append(dof)
        extra_c.append(dof)
        extra_v.append(cat.steady_arm_stiffness_N_m)
    if cat.messenger_support_stiffness_N_m > 0:
        for dof in s_mw:
            extra_r.append(dof)
            extra_c.append(dof)
            extra_v.append(cat.messenger_support_stiffness_N_m)
        fixed = np.array([s_cw[0], s_cw[-1]])
    else:
        fixed = np.concatenate([s_mw, [s_cw[0], s_cw[-1]]])
    K = (sec.K_wires + sparse.csr_matrix((extra_v, (extra_r, extra_c)), shape=sec.K_wires.shape)).tocsr()
    return K, fixed, kd


def _mask(v: np.ndarray, keep: set) -> np.ndarray:
    out = np.zeros_like(v)
    idx = np.array(sorted(keep), dtype=int)
    if len(idx):
        out[idx] = v[idx]
    return out


def _restrict(K: sparse.csr_matrix, keep: set) -> sparse.csr_matrix:
    """K with the rows and columns outside `keep` zeroed (the other wires decoupled)."""
    d = np.zeros(K.shape[0])
    d[np.array(sorted(keep), dtype=int)] = 1.0
    D = sparse.diags(d)
    return (D @ K @ D).tocsr()


def _identity_on(dofs: set, n: int) -> sparse.csr_matrix:
    d = np.zeros(n)
    d[np.array(sorted(dofs), dtype=int)] = 1.0
    return sparse.diags(d).tocsr()


def vertical_stiffness(ff: FormFinding, span_index: int) -> tuple[np.ndarray, np.ndarray]:
    """k_z(x) = 1 / (static contact-wire displacement under a unit vertical force at x), at every
    contact-wire node of one span (Paper A Fig. 7). Returns (x within the span, k_z)."""
    sec = ff.section
    L = sec.cat.span_m
    free = ff.free()
    pos = {d: i for i, d in enumerate(free)}
    lu = spla.splu(ff.K[free][:, free].tocsc())
    nodes = np.flatnonzero((sec.x >= span_index * L - 1e-9) & (sec.x <= (span_index + 1) * L + 1e-9))
    rhs = np.zeros((len(free), len(nodes)))
    for j, i in enumerate(nodes):
        rhs[pos[sec.cw_w[i]], j] = 1.0
    u = lu.solve(rhs)
    kz = np.array([1.0 / u[pos[sec.cw_w[i]], j] for j, i in enumerate(nodes)])
    return sec.x[nodes] - span_index * L, kz


def contact_wire_profile(ff: FormFinding, span_index: int, x_local: np.ndarray) -> np.ndarray:
    """z0 at any x of one span, by the cubic (Hermite) shape of the contact-wire beam elements."""
    sec = ff.section
    xs = sec.x
    xg = span_index * sec.cat.span_m + np.asarray(x_local, dtype=float)
    e = np.clip(np.searchsorted(xs, xg, side="right") - 1, 0, len(xs) - 2)
    a, b = xs[e], xs[e + 1]
    h = b - a
    s = (xg - a) / h
    w1, t1 = ff.heights[sec.cw_w[e]], ff.heights[sec.cw_w[e] + 1]
    w2, t2 = ff.heights[sec.cw_w[e + 1]], ff.heights[sec.cw_w[e + 1] + 1]
    return ((1 - 3 * s**2 + 2 * s**3) * w1 + h * (s - 2 * s**2 + s**3) * t1
            + (3 * s**2 - 2 * s**3) * w2 + h * (-s**2 + s**3) * t2)


def harmonic_responses(ff: FormFinding, omegas, x_load: float, absorbing: bool = True):
    """Contact-wire displacement (complex, per node) under a unit harmonic force at x_load, at rest, for
    each frequency in `omegas` (a generator). The section's matrices are banded after a reverse
    Cuthill-McKee ordering (bandwidth ~10), so each frequency is one banded LU solve.

    With `absorbing`, each wire end carries a dashpot sqrt(T m) (the impedance of a string), so that
    waves leave the section instead of coming back (Paper A sec. 4.2's long model, shortened).
    """
    sec = ff.section
    cat = sec.cat
    free = ff.free()
    pos = -np.ones(sec.ndof, dtype=int)
    pos[free] = np.arange(len(free))
    dash = np.zeros(sec.ndof)
    if absorbing:
        for dof, wire in ((sec.cw_w[1], cat.contact), (sec.cw_w[-2], cat.contact),
                          (sec.mw_w[1], cat.messenger), (sec.mw_w[-2], cat.messenger)):
            dash[dof] += np.sqrt(wire.tension_N * wire.mass_kg_m)
    mats = [A.tocsr()[free][:, free] for A in (ff.K, ff.M, ff.C + sparse.diags(dash))]
    perm = reverse_cuthill_mckee((abs(mats[0]) + abs(mats[1]) + abs(mats[2])).tocsr(), symmetric_mode=True)
    coo = [A[perm][:, perm].tocoo() for A in mats]
    bw = max(int(np.max(np.abs(c.row - c.col))) for c in coo)
    bands = []
    for c in coo:  # solve_banded's layout: ab[bw + i - j, j] = A[i, j]
        ab = np.zeros((2 * bw + 1, len(free)))
        np.add.at(ab, (bw + c.row - c.col, c.col), c.data)
        bands.append(ab)
    rhs = np.zeros(len(free), dtype=complex)
    rhs[pos[sec.cw_w[sec.node(x_load)]]] = 1.0
    rhs = rhs[perm]
    cw = np.asarray(sec.cw_w)
    on = pos[cw] >= 0
    for omega in omegas:
        u = np.empty(len(free), dtype=complex)
        u[perm] = sla.solve_banded((bw, bw), bands[0] - omega**2 * bands[1] + 1j * omega * bands[2], rhs,
                                   check_finite=False)
        out = np.zeros(len(sec.x), dtype=complex)
        out[on] = u[pos[cw[on]]]
        yield out
