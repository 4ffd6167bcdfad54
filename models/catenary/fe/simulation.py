"""Conventional time-domain simulation of a finite catenary section (Paper C sec. 6, Paper A sec. 5):
n equal spans with anchored ends, the pantograph entering at one end at constant speed.

The catenary is the linearised FE model of the section about its form-found static state
(`fe_catenary.form_find`), integrated with HHT (the thesis constants). Its effective matrix is
factorised once (banded Cholesky after a bandwidth-reducing ordering); the nonlinearities enter as
forces whose effect on the step is known through influence vectors, as in Gregori et al. (Paper C
ref. [25]): the penalty contact with the pantograph (the pantograph's HHT step is affine in the wire
height for a contact state, so the two are solved together, implicitly) and droppers that carry no
compression (a slack dropper gets the correction force that cancels its bar's force, Paper C eq. 39,
here exact at each step). A small active-set loop settles the contact state and the slack set.

Several pantographs (`simulate_points`: a case's second pantograph L behind or ahead of the first, Paper A
sec. 3.4) each have their own contact row, pantograph state and penalty contact; the active set solves all
their forces and the slack droppers' corrections together. With one point the step is the same arithmetic.
"""
from __future__ import annotations

import resource
import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy import sparse
from scipy.sparse.csgraph import reverse_cuthill_mckee

from pantohil.models.catenary.fe.definition import CatenaryDefinition
from pantohil.models.catenary.fe.model import form_find
from pantohil.models.pantograph.lumped import ChainPantograph, HhtConstants, PantographParameters
from pantohil.models.catenary.pfem.blocks import hermite_shapes

FE_PANTOGRAPHS = ("chain",)  # the models the section simulation steps: it needs the chain's contact step


@dataclass
class FeSimResult:
    """Time histories of a fem-sim run: position, contact force and state, dropper forces and corrections, uplift."""
    t_s: np.ndarray
    x_m: np.ndarray  # pantograph position
    force_N: np.ndarray
    contact: np.ndarray  # bool
    dropper_force_N: np.ndarray  # [step, dropper]: total dropper force (tension >= 0)
    dropper_correction_N: np.ndarray  # [step, dropper]
    support_uplift_m: np.ndarray  # [step, support]: contact-wire displacement at each support
    dropper_x_m: np.ndarray
    n_spans: int
    span_m: float
    wall_s: float
    peak_memory_bytes: int
    # with more than one contact point (simulate_points): each point's force and position at every step [step,
    # point] (0 N and NaN off the section) and the step before which each enters the section
    forces_N: np.ndarray | None = None
    positions_m: np.ndarray | None = None
    entry_steps: tuple[int, ...] = (0,)


class _Banded:
    """Cholesky factor of a sparse SPD matrix in a bandwidth-reducing ordering."""

    def __init__(self, A: sparse.csr_matrix):
        self.perm = reverse_cuthill_mckee(A.tocsr(), symmetric_mode=True)
        P = A.tocsr()[self.perm][:, self.perm].tocoo()
        bw = int(np.max(np.abs(P.row - P.col)))
        ab = np.zeros((bw + 1, A.shape[0]))
        upper = P.col >= P.row
        ab[bw + P.row[upper] - P.col[upper], P.col[upper]] = P.data[upper]
        self.cb = sla.cholesky_banded(ab, lower=False)
        self.bandwidth = bw

    def solve(self, b: np.ndarray) -> np.ndarray:
        out = np.empty_like(b)
        out[self.perm] = sla.cho_solve_banded((self.cb, False), b[self.perm], check_finite=False)
        return out


class _UnitResponses:
    """S e_j for the few dofs the contact point's element touches, kept while the pantograph is near."""

    def __init__(self, solver: _Banded, keep: int = 16):
        self.solver, self.keep, self.cache = solver, keep, {}

    def combination(self, dofs: np.ndarray, weights: np.ndarray, n: int) -> np.ndarray:
        """sum_j w_j S e_j over the given dofs (the response to a load spread by shape-function weights)."""
        out = np.zeros(n)
        for j, w in zip(dofs.tolist(), weights.tolist(), strict=True):
            if j not in self.cache:
                if len(self.cache) >= self.keep:
                    self.cache.pop(next(iter(self.cache)))
                e = np.zeros(n)
                e[j] = 1.0
                self.cache[j] = self.solver.solve(e)
            out += w * self.cache[j]
        return out


@dataclass
class SectionModel:
    """A finite section in the form the integrator needs: matrices on the free dofs, the contact line's
    shape rows and static height at every step, droppers (may be none) and the dofs whose
    displacement is recorded as support uplift."""

    K: sparse.csr_matrix
    M: sparse.csr_matrix
    alpha: float  # Rayleigh
    beta: float
    dashpots: np.ndarray | None  # extra diagonal damping (absorbing ends)
    shapes: sparse.csr_matrix  # [step + 1, dof] contact-line shape rows at x(t_k)
    z_static: np.ndarray  # [step + 1] static height of the contact line at x(t_k)
    x_m: np.ndarray  # [step + 1]
    d_lo: np.ndarray
    d_up: np.ndarray
    f0: np.ndarray
    kd: np.ndarray
    recorded: np.ndarray  # dofs recorded every step (support uplift)


def simulate_section(cat: CatenaryDefinition, pan: PantographParameters, n_spans: int, speed_m_s: float,
                     dt_s: float, droppers_slacken: bool = True, hht: HhtConstants | None = None,
                     progress=None, absorbing_ends: bool = True,
                     reference_height_m: float | None = None) -> FeSimResult:
    """Run the pantograph over an n-span section (Paper C sec. 6's conventional reference).

    With `absorbing_ends`, the contact wire's end heights are held by dashpots of the wire's impedance
    sqrt(T m) instead of rigidly (in the dynamics about the static state), so that the waves the
    pantograph leaves behind leave the section instead of coming back from the anchor: the central
    spans then approach the endless line the periodic models describe. The messenger stays held at
    every support."""
    t0 = time.perf_counter()
    ff = form_find(cat, n_spans)
    sec = ff.section
    L = cat.span_m
    n_steps = int(round(n_spans * L / (speed_m_s * dt_s)))
    x_all = np.minimum(np.arange(n_steps + 1) * speed_m_s * dt_s, n_spans * L - 1e-9)
    model, _ = form_found_model(cat, ff, x_all, x_all, absorbing_ends)
    res = integrate_section(model, pan, dt_s, droppers_slacken, hht, progress, reference_height_m)
    res.dropper_x_m = np.array([d[0] for d in sec.droppers])
    res.n_spans, res.span_m = n_spans, L
    res.wall_s = time.perf_counter() - t0
    return res


def form_found_model(cat: CatenaryDefinition, ff, contact_x_m: np.ndarray, track_x_m: np.ndarray,
                     absorbing_ends: bool = True) -> tuple[SectionModel, np.ndarray]:
    """A form-found section in the integrator's form, with the contact point at `contact_x_m` in the section
    at each step (`track_x_m`: its position along the line): the matrices on the free dofs (with
    `absorbing_ends`, the contact wire's end heights freed and held by dashpots of impedance sqrt(T m)), the
    contact line's shape rows and static heights, the droppers and the supports. Returns the model and its
    free dofs."""
    sec = ff.section
    ends = [sec.cw_w[0], sec.cw_w[-1]]
    free = np.union1d(ff.free(), ends) if absorbing_ends else ff.free()
    pos = -np.ones(sec.ndof, dtype=int)
    pos[free] = np.arange(len(free))
    dash = None
    if absorbing_ends:
        dash = np.zeros(len(free))
        dash[pos[ends]] = np.sqrt(cat.contact.tension_N * cat.contact.mass_kg_m)
    shapes, z_static = contact_line(ff, free, contact_x_m)
    model = SectionModel(ff.K.tocsr()[free][:, free], ff.M.tocsr()[free][:, free], cat.alpha_1_s, cat.beta_s, dash,
                         shapes, z_static, track_x_m,
                         pos[np.array([d[1] for d in sec.droppers])], pos[np.array([d[2] for d in sec.droppers])],
                         ff.dropper_tensions_N, cat.dropper_axial_stiffness_N / ff.dropper_lengths_m,
                         pos[np.array([s[1] for s in sec.supports])])
    return model, free


def contact_line(ff, free: np.ndarray, contact_x_m: np.ndarray) -> tuple[sparse.csr_matrix, np.ndarray]:
    """The contact line's shape rows on the free dofs and its static heights at the positions `contact_x_m` in a
    form-found section."""
    sec = ff.section
    rows = hermite_shapes(sec.x, contact_x_m, sec.ndof, sec.cw_w).tocsr()
    return rows[:, free].tocsr(), rows @ ff.heights


@dataclass
class ContactTrack:
    """A contact point's path over a section: its shape rows and static heights at its positions `x_m` (rows
    0..n), row 0 where it enters the section, before global step `entry_step`."""
    shapes: sparse.csr_matrix
    z_static: np.ndarray
    x_m: np.ndarray
    entry_step: int


def track_positions(n_spans: int, span_m: float, speed_m_s: float, dt_s: float,
                    offsets_m: tuple[float, ...]) -> list[tuple[np.ndarray, int]]:
    """Each contact point's positions over an n-span section and the step before which it enters, for points at
    `offsets_m` along the line from the first (the second pantograph: -L trailing, +L leading, Paper A sec. 3.4):
    the front point enters at step 0, each other one when it reaches the section's start, its offset kept
    exactly (it enters up to one step's travel past the start). Every point runs the section's n_steps; the
    front point's positions are simulate_section's."""
    L_sec = n_spans * span_m
    n_steps = int(round(L_sec / (speed_m_s * dt_s)))
    front = max(offsets_m)
    out = []
    for offset in offsets_m:
        behind = front - offset
        if behind == 0:
            x = np.minimum(np.arange(n_steps + 1) * speed_m_s * dt_s, L_sec - 1e-9)
            out.append((x, 0))
            continue
        entry = int(np.ceil(behind / (speed_m_s * dt_s) - 1e-9))
        x = np.clip((np.arange(n_steps + 1) + entry) * speed_m_s * dt_s - behind, 0.0, L_sec - 1e-9)
        out.append((x, entry))
    return out


def _section_operators(model: SectionModel, hht: HhtConstants, dt: float):
    """The section's factorised HHT matrix, its unit responses and the droppers' influence vectors."""
    K, M = model.K, model.M
    C = (model.alpha * M + model.beta * K).tocsr()
    dash = model.dashpots
    if dash is not None:
        C = (C + sparse.diags(dash)).tocsr()
    nf = K.shape[0]
    a, b, g = hht.alpha, hht.beta, hht.gamma
    solver = _Banded((M + (1 + a) * (g * dt * C + b * dt * dt * K)).tocsr())
    unit = _UnitResponses(solver)
    d_lo, d_up = model.d_lo, model.d_up
    nd = len(d_lo)
    scale = b * dt * dt * (1 + a)  # displacement per unit new force, through S = A_eff^-1
    G = np.zeros((nf, nd))
    for j in range(nd):  # droppers: correction loads +1 at the lower end, -1 at the upper
        rhs = np.zeros(nf)
        rhs[d_lo[j]], rhs[d_up[j]] = 1.0, -1.0
        G[:, j] = solver.solve(rhs) * scale
    E_dd = G[d_up] - G[d_lo]  # elongation of dropper i per unit correction of dropper j
    return K, M, dash, nf, solver, unit, nd, scale, G, E_dd


def _free_step(model: SectionModel, K, M, dash, solver, a, b, g, dt, u, v, acc, F_old):
    """HHT predictors and the free step (no new contact force or corrections): u_pred, v_pred, acc_free, u_free."""
    u_pred = u + dt * v + dt * dt * (0.5 - b) * acc
    v_pred = v + dt * (1 - g) * acc
    # a (C v + K u) - (1 + a)(C v_pred + K u_pred) with C = alpha M + beta K: two products
    rhs = (K @ (a * (model.beta * v + u) - (1 + a) * (model.beta * v_pred + u_pred))
           + M @ (model.alpha * (a * v - (1 + a) * v_pred)) - a * F_old)
    if dash is not None:
        rhs += dash * (a * v - (1 + a) * v_pred)
    acc_free = solver.solve(rhs)
    u_free = u_pred + b * dt * dt * acc_free
    return u_pred, v_pred, acc_free, u_free


@dataclass
class _Point:
    """A contact point in a step: its shape row (dofs `ri`, weights `rv`), load vector, unit response and free
    height, its dropper elongations per unit force, and its pantograph's affine step f = fa + fb z."""
    ri: np.ndarray
    rv: np.ndarray
    n_c: np.ndarray
    g_c: np.ndarray
    z_free: float
    z_per_fc: float
    dL_per_fc: np.ndarray
    fa: float
    fb: float

    def height_per_force_of(self, other: _Point) -> float:
        """Height at this point per unit contact force at the other (their coupling through the section)."""
        return float(self.rv @ other.g_c[self.ri])


def _contact_influence(model: SectionModel, unit, scale, nf, ri, rv, z_static_next, u_free):
    """The contact point's load vector, its unit response and the free wire height and dropper elongations
    (`ri`, `rv`: the dofs and weights of the contact line's shape row at the point)."""
    d_lo, d_up = model.d_lo, model.d_up
    n_c = np.zeros(nf)
    n_c[ri] = rv
    g_c = unit.combination(ri, rv, nf) * scale  # displacement per unit contact force
    z_free = z_static_next + rv @ u_free[ri]
    z_per_fc = float(rv @ g_c[ri])
    dL_free = u_free[d_up] - u_free[d_lo]
    dL_per_fc = g_c[d_up] - g_c[d_lo]
    return ri, rv, n_c, g_c, z_free, z_per_fc, dL_free, dL_per_fc


def _active_set_system(model: SectionModel, G, E_dd, points: list[_Point], in_contact: list[bool], idx, dL_free):
    """The linear system of an active set: unknowns the contact force of every point (0 for a point out of
    contact) and the corrections of the slack droppers `idx`."""
    f0, kd = model.f0, model.kd
    npts = len(points)
    nu = len(idx) + npts
    Amat = np.zeros((nu, nu))
    bvec = np.zeros(nu)
    for i, p in enumerate(points):
        if in_contact[i]:  # f_i - B_i (z_free + z_per_fc f_i + other points' and corrections' effects) = A_i
            Amat[i, i] = 1.0 - p.fb * p.z_per_fc
            for k, q in enumerate(points):
                if k != i:
                    Amat[i, k] = -p.fb * p.height_per_force_of(q)
            if len(idx):
                Amat[i, npts:] = -p.fb * (p.rv @ G[p.ri][:, idx])
            bvec[i] = p.fa + p.fb * p.z_free
        else:
            Amat[i, i] = 1.0
    for r, j in enumerate(idx):  # f0 + kd dL + corr = 0 with dL = dL_free + sum dL_per_fc f + E corr
        for k, q in enumerate(points):
            Amat[r + npts, k] = kd[j] * q.dL_per_fc[j]
        Amat[r + npts, npts:] = kd[j] * E_dd[j, idx]
        Amat[r + npts, r + npts] += 1.0
        bvec[r + npts] = -f0[j] - kd[j] * dL_free[j]
    return Amat, bvec


def _contact_changes(G, points: list[_Point], in_contact: list[bool], idx, fc_new, corr_new) -> bool:
    """Update each point's contact state from a solution of its active set (a point in contact whose force came
    out negative leaves; one out of contact that the wire would press into enters); whether any changed."""
    changed = False
    for i, p in enumerate(points):
        if in_contact[i] and fc_new[i] < 0:
            in_contact[i], changed = False, True
        elif not in_contact[i]:
            z_now = p.z_free + (p.rv @ (G[p.ri] @ corr_new) if len(idx) else 0.0)
            for k, q in enumerate(points):
                if k != i:
                    z_now += p.height_per_force_of(q) * fc_new[k]
            if p.fa + p.fb * z_now > 0:
                in_contact[i], changed = True, True
    return changed


def _solve_active_set(model: SectionModel, G, E_dd, nd, droppers_slacken, slack, points: list[_Point], dL_free):
    """Active-set loop of a step: every point's contact state, the slack set, the contact forces and the dropper
    corrections, solved together (Paper C sec. 6 with the pantographs' penalty contacts, Paper C eq. 39)."""
    f0, kd = model.f0, model.kd
    npts = len(points)
    in_contact = [True] * npts
    for _ in range(30):
        idx = np.flatnonzero(slack) if droppers_slacken else np.zeros(0, dtype=int)
        Amat, bvec = _active_set_system(model, G, E_dd, points, in_contact, idx, dL_free)
        sol = np.linalg.solve(Amat, bvec)
        fc_new = sol[:npts]
        corr_new = np.zeros(nd)
        corr_new[idx] = sol[npts:]
        dL = dL_free
        for k, q in enumerate(points):
            dL = dL + q.dL_per_fc * fc_new[k]
        dL = dL + E_dd @ corr_new
        changed = _contact_changes(G, points, in_contact, idx, fc_new, corr_new)
        if droppers_slacken:
            want = f0 + kd * dL + corr_new < -1e-9  # a tense dropper that would be compressed
            release = slack & (corr_new < 0)  # a slack dropper that would need to push
            if want.any() or release.any():
                slack = (slack | want) & ~release
                changed = True
        if not changed:
            break
    return in_contact, idx, fc_new, corr_new, slack


class SectionStepper:
    """The HHT step of a section with pantographs in penalty contact and slackening droppers (Paper C sec. 6):
    the state (displacement, velocity, acceleration, the last step's load, the slack set) and one step. The
    first pantograph starts settled on the section; further ones (`more_reference_heights_m`, the same model)
    settle where they enter it (`enter`)."""

    def __init__(self, model: SectionModel, pan: PantographParameters, dt_s: float, droppers_slacken: bool,
                 hht: HhtConstants, reference_height_m: float, z_static_start: float, keep_unit_responses: int = 16,
                 more_reference_heights_m: tuple[float, ...] = ()):
        self.model, self.dt, self.hht, self.droppers_slacken = model, dt_s, hht, droppers_slacken
        (self.K, self.M, self.dash, self.nf, self.solver, self.unit, self.nd, self.scale, self.G,
         self.E_dd) = _section_operators(model, hht, dt_s)
        self.unit.keep = keep_unit_responses
        self.pantographs = [ChainPantograph(pan, dt_s, h, hht) for h in (reference_height_m, *more_reference_heights_m)]
        self.pantograph = self.pantographs[0]
        self.f_c = self.pantograph.settle(float(z_static_start))
        self.u, self.v, self.acc = np.zeros(self.nf), np.zeros(self.nf), np.zeros(self.nf)
        self.F_old = np.zeros(self.nf)  # load vector of the previous step (contact + corrections)
        self.corr = np.zeros(self.nd)
        self.slack = np.zeros(self.nd, dtype=bool)

    def start_load(self, ri: np.ndarray, rv: np.ndarray) -> None:
        """The settled pantograph's force on the shape row where it starts, as the previous step's load."""
        self.F_old[ri] = rv * self.f_c

    def enter(self, point: int, ri: np.ndarray, rv: np.ndarray, z_static: float) -> float:
        """Pantograph `point` enters the section at the shape row (ri, rv): it settles on the wire's height there
        and its force joins the previous step's load; returns that force."""
        f = self.pantographs[point].settle(float(z_static + rv @ self.u[ri]))
        self.F_old[ri] += rv * f
        return f

    def step(self, ri: np.ndarray, rv: np.ndarray, z_static_next: float) -> float:
        """One step to the contact point with shape row (ri, rv) and static height z_static_next; returns the
        pantograph's contact force."""
        return self.step_points([(0, ri, rv, z_static_next)])[0]

    def step_points(self, rows: list[tuple]) -> list[float]:
        """One step with the pantographs on the section, each (pantograph, ri, rv, z_static_next): to the contact
        points with shape rows (ri, rv) and static heights z_static_next, solved together; returns their contact
        forces, in order."""
        model, hht, dt = self.model, self.hht, self.dt
        a, b, g = hht.alpha, hht.beta, hht.gamma
        u_pred, v_pred, acc_free, u_free = _free_step(model, self.K, self.M, self.dash, self.solver, a, b, g, dt,
                                                      self.u, self.v, self.acc, self.F_old)
        points, dL_free = [], u_free[model.d_up] - u_free[model.d_lo]
        for i, ri, rv, z_next in rows:
            ri, rv, n_c, g_c, z_free, z_per_fc, dL_free, dL_per_fc = _contact_influence(
                model, self.unit, self.scale, self.nf, ri, rv, z_next, u_free)
            # the pantograph's step is affine in the wire height: f = A + B z for a contact state
            fa = _pantograph_force(self.pantographs[i], 0.0)
            points.append(_Point(ri, rv, n_c, g_c, z_free, z_per_fc, dL_per_fc, fa,
                                 _pantograph_force(self.pantographs[i], 1.0) - fa))
        in_contact, idx, fc_new, corr, self.slack = _solve_active_set(
            model, self.G, self.E_dd, self.nd, self.droppers_slacken, self.slack, points, dL_free)
        self.corr = corr
        f_c = [fc_new[i] if in_contact[i] else 0.0 for i in range(len(points))]
        F_new, response = np.zeros(self.nf), 0.0
        for i, p in enumerate(points):
            F_new = p.n_c * f_c[i] if i == 0 else F_new + p.n_c * f_c[i]
            response = p.g_c * f_c[i] if i == 0 else response + p.g_c * f_c[i]
        if len(idx):
            np.add.at(F_new, model.d_lo[idx], corr[idx])
            np.add.at(F_new, model.d_up[idx], -corr[idx])
        acc_new = acc_free + (response + (self.G[:, idx] @ corr[idx] if len(idx) else 0.0)) / (b * dt * dt)
        self.u = u_pred + b * dt * dt * acc_new
        self.v = v_pred + g * dt * acc_new
        self.acc = acc_new
        self.F_old = F_new
        return [self.pantographs[i].step(float(z_next + p.rv @ self.u[p.ri]))
                for (i, _, _, z_next), p in zip(rows, points, strict=True)]

    def dropper_forces(self) -> np.ndarray:
        """Total force of every dropper now (tension >= 0)."""
        m = self.model
        return np.maximum(m.f0 + m.kd * (self.u[m.d_up] - self.u[m.d_lo]) + self.corr, 0.0)


def record_steps(st: SectionStepper, n_steps: int, progress=None, before_step=None):
    """Step a section along its contact rows from the first (where the settled pantograph starts), recording
    the contact force, the dropper forces and corrections and the recorded dofs at every step;
    `before_step(k)` runs before step k."""
    model = st.model
    shapes = model.shapes.tocsr()
    indptr, indices, data = shapes.indptr, shapes.indices, shapes.data
    st.start_load(indices[indptr[0]:indptr[1]], data[indptr[0]:indptr[1]])
    forces = np.zeros(n_steps)
    dforce = np.zeros((n_steps, st.nd), dtype=np.float32)
    dcorr = np.zeros((n_steps, st.nd), dtype=np.float32)
    uplift = np.zeros((n_steps, len(model.recorded)), dtype=np.float32)
    for k in range(n_steps):
        if before_step is not None:
            before_step(k)
        row = slice(indptr[k + 1], indptr[k + 2])
        forces[k] = st.step(indices[row], data[row], model.z_static[k + 1])
        dforce[k] = st.dropper_forces()
        dcorr[k] = st.corr
        uplift[k] = st.u[model.recorded]
        if progress is not None and k % 500 == 0:
            progress(k, n_steps)
    return forces, dforce, dcorr, uplift


def integrate_section(model: SectionModel, pan: PantographParameters, dt_s: float, droppers_slacken: bool = True,
                      hht: HhtConstants | None = None, progress=None,
                      reference_height_m: float | None = None) -> FeSimResult:
    """HHT time integration of a section with the pantograph in penalty contact and slackening droppers."""
    t0 = time.perf_counter()
    hht = hht if hht is not None else HhtConstants()
    z_static, x_all = model.z_static, model.x_m
    n_steps = len(x_all) - 1
    ref = float(z_static[0]) if reference_height_m is None else reference_height_m
    # the static state is under gravity only: the pantograph enters at the anchor, where the wire is held
    st = SectionStepper(model, pan, dt_s, droppers_slacken, hht, ref, float(z_static[0]))
    forces, dforce, dcorr, uplift = record_steps(st, n_steps, progress)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    return FeSimResult(np.arange(1, n_steps + 1) * dt_s, x_all[1:], forces, forces > 0, dforce, dcorr, uplift,
                       np.zeros(0), 0, 0.0, time.perf_counter() - t0, peak)


def simulate_points(cat: CatenaryDefinition, pan: PantographParameters, n_spans: int, speed_m_s: float,
                    dt_s: float, offsets_m: tuple[float, ...], reference_heights_m: tuple[float, ...],
                    droppers_slacken: bool = True, hht: HhtConstants | None = None, progress=None,
                    absorbing_ends: bool = True) -> FeSimResult:
    """Run pantographs (the same model, each with its reference height) at `offsets_m` from the first over an
    n-span section (Paper C sec. 6's reference with the contact points of Paper A sec. 3.4): the front one enters
    at step 0, the others when they reach the section, and the run lasts until the last has crossed it."""
    t0 = time.perf_counter()
    ff = form_find(cat, n_spans)
    positions = track_positions(n_spans, cat.span_m, speed_m_s, dt_s, offsets_m)
    model, free = form_found_model(cat, ff, positions[0][0], positions[0][0], absorbing_ends)
    tracks = [ContactTrack(model.shapes, model.z_static, x, entry) if i == 0 else
              ContactTrack(*contact_line(ff, free, x), x, entry) for i, (x, entry) in enumerate(positions)]
    res = integrate_points(model, tracks, pan, dt_s, reference_heights_m, droppers_slacken, hht, progress)
    res.dropper_x_m = np.array([d[0] for d in ff.section.droppers])
    res.n_spans, res.span_m = n_spans, cat.span_m
    res.wall_s = time.perf_counter() - t0
    return res


def integrate_points(model: SectionModel, tracks: list[ContactTrack], pan: PantographParameters, dt_s: float,
                     reference_heights_m: tuple[float, ...], droppers_slacken: bool = True,
                     hht: HhtConstants | None = None, progress=None) -> FeSimResult:
    """HHT time integration of a section with a pantograph on each track (penalty contacts and slackening
    droppers solved together at every step); the result's force_N, x_m and contact are the first track's, 0 N
    and NaN where it is off the section."""
    t0 = time.perf_counter()
    hht = hht if hht is not None else HhtConstants()
    n_total = max(tr.entry_step + len(tr.x_m) - 1 for tr in tracks)
    st = SectionStepper(model, pan, dt_s, droppers_slacken, hht, reference_heights_m[0],
                        float(tracks[0].z_static[0]), keep_unit_responses=16 * len(tracks),
                        more_reference_heights_m=tuple(reference_heights_m[1:]))
    forces, positions, dforce, dcorr, uplift = record_points(st, tracks, n_total, progress)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    return FeSimResult(np.arange(1, n_total + 1) * dt_s, positions[:, 0], forces[:, 0], forces[:, 0] > 0, dforce,
                       dcorr, uplift, np.zeros(0), 0, 0.0, time.perf_counter() - t0, peak, forces, positions,
                       tuple(tr.entry_step for tr in tracks))


def record_points(st: SectionStepper, tracks: list[ContactTrack], n_total: int, progress=None):
    """Step a section over n_total steps with a pantograph on each track while it is on the section (it settles
    where it enters), recording each one's contact force and position ([step, point]; 0 N and NaN off the
    section), the dropper forces and corrections and the recorded dofs at every step."""
    model = st.model
    rows = [(tr.shapes.indptr, tr.shapes.indices, tr.shapes.data) for tr in tracks]
    forces = np.zeros((n_total, len(tracks)))
    positions = np.full((n_total, len(tracks)), np.nan)
    dforce = np.zeros((n_total, st.nd), dtype=np.float32)
    dcorr = np.zeros((n_total, st.nd), dtype=np.float32)
    uplift = np.zeros((n_total, len(model.recorded)), dtype=np.float32)
    for k in range(n_total):
        on = []
        for i, (tr, (indptr, indices, data)) in enumerate(zip(tracks, rows, strict=True)):
            local = k - tr.entry_step + 1  # the row this step moves the point to
            if local == 1:
                st.enter(i, indices[indptr[0]:indptr[1]], data[indptr[0]:indptr[1]], tr.z_static[0])
            if 1 <= local < len(tr.x_m):
                row = slice(indptr[local], indptr[local + 1])
                on.append((i, indices[row], data[row], tr.z_static[local]))
                positions[k, i] = tr.x_m[local]
        for (i, *_), f in zip(on, st.step_points(on), strict=True):
            forces[k, i] = f
        dforce[k] = st.dropper_forces()
        dcorr[k] = st.corr
        uplift[k] = st.u[model.recorded]
        if progress is not None and k % 500 == 0:
            progress(k, n_total)
    return forces, positions, dforce, dcorr, uplift


def _pantograph_force(p: ChainPantograph, z_next: float) -> float:
    """The contact force the pantograph's next HHT step would give for a wire height z_next, in contact
    (without advancing it): its step is affine in z_next."""
    return p.contact_force_at(z_next)
