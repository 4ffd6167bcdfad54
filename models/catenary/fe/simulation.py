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
    rows = hermite_shapes(sec.x, contact_x_m, sec.ndof, sec.cw_w).tocsr()
    model = SectionModel(ff.K.tocsr()[free][:, free], ff.M.tocsr()[free][:, free], cat.alpha_1_s, cat.beta_s, dash,
                         rows[:, free].tocsr(), rows @ ff.heights, track_x_m,
                         pos[np.array([d[1] for d in sec.droppers])], pos[np.array([d[2] for d in sec.droppers])],
                         ff.dropper_tensions_N, cat.dropper_axial_stiffness_N / ff.dropper_lengths_m,
                         pos[np.array([s[1] for s in sec.supports])])
    return model, free


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


def _solve_active_set(model: SectionModel, G, E_dd, nd, droppers_slacken, slack, fa, fb, ri, rv, z_free, z_per_fc,
                      dL_free, dL_per_fc):
    """Active-set loop of a step: contact state, slack set, contact force and dropper corrections, solved together."""
    f0, kd = model.f0, model.kd
    in_contact = True
    for _ in range(30):
        idx = np.flatnonzero(slack) if droppers_slacken else np.zeros(0, dtype=int)
        # unknowns: f_c (if in contact) and the corrections of the slack droppers
        nu = len(idx) + 1
        Amat = np.zeros((nu, nu))
        bvec = np.zeros(nu)
        if in_contact:  # f_c - B (z_free + z_per_fc f_c + sum g_c-effects of corrections) = A
            Amat[0, 0] = 1.0 - fb * z_per_fc
            if len(idx):
                Amat[0, 1:] = -fb * (rv @ G[ri][:, idx])
            bvec[0] = fa + fb * z_free
        else:
            Amat[0, 0] = 1.0
        for r, j in enumerate(idx):  # f0 + kd dL + corr = 0 with dL = dL_free + dL_per_fc f_c + E corr
            Amat[r + 1, 0] = kd[j] * dL_per_fc[j]
            Amat[r + 1, 1:] = kd[j] * E_dd[j, idx]
            Amat[r + 1, r + 1] += 1.0
            bvec[r + 1] = -f0[j] - kd[j] * dL_free[j]
        sol = np.linalg.solve(Amat, bvec)
        fc_new = sol[0]
        corr_new = np.zeros(nd)
        corr_new[idx] = sol[1:]
        dL = dL_free + dL_per_fc * fc_new + E_dd @ corr_new
        changed = False
        if in_contact and fc_new < 0:
            in_contact, changed = False, True
        elif not in_contact:
            z_now = z_free + (rv @ (G[ri] @ corr_new) if len(idx) else 0.0)
            if fa + fb * z_now > 0:
                in_contact, changed = True, True
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
    """The HHT step of a section with the pantograph in penalty contact and slackening droppers (Paper C sec. 6):
    the state (displacement, velocity, acceleration, the last step's load, the slack set) and one step."""

    def __init__(self, model: SectionModel, pan: PantographParameters, dt_s: float, droppers_slacken: bool,
                 hht: HhtConstants, reference_height_m: float, z_static_start: float, keep_unit_responses: int = 16):
        self.model, self.dt, self.hht, self.droppers_slacken = model, dt_s, hht, droppers_slacken
        (self.K, self.M, self.dash, self.nf, self.solver, self.unit, self.nd, self.scale, self.G,
         self.E_dd) = _section_operators(model, hht, dt_s)
        self.unit.keep = keep_unit_responses
        self.pantograph = ChainPantograph(pan, dt_s, reference_height_m, hht)
        self.f_c = self.pantograph.settle(float(z_static_start))
        self.u, self.v, self.acc = np.zeros(self.nf), np.zeros(self.nf), np.zeros(self.nf)
        self.F_old = np.zeros(self.nf)  # load vector of the previous step (contact + corrections)
        self.corr = np.zeros(self.nd)
        self.slack = np.zeros(self.nd, dtype=bool)

    def start_load(self, ri: np.ndarray, rv: np.ndarray) -> None:
        """The settled pantograph's force on the shape row where it starts, as the previous step's load."""
        self.F_old[ri] = rv * self.f_c

    def step(self, ri: np.ndarray, rv: np.ndarray, z_static_next: float) -> float:
        """One step to the contact point with shape row (ri, rv) and static height z_static_next; returns the
        pantograph's contact force."""
        model, hht, dt = self.model, self.hht, self.dt
        a, b, g = hht.alpha, hht.beta, hht.gamma
        u_pred, v_pred, acc_free, u_free = _free_step(model, self.K, self.M, self.dash, self.solver, a, b, g, dt,
                                                      self.u, self.v, self.acc, self.F_old)
        ri, rv, n_c, g_c, z_free, z_per_fc, dL_free, dL_per_fc = _contact_influence(
            model, self.unit, self.scale, self.nf, ri, rv, z_static_next, u_free)
        # the pantograph's step is affine in the wire height: f = A + B z for a contact state
        p = self.pantograph
        fa = _pantograph_force(p, 0.0)
        fb = _pantograph_force(p, 1.0) - fa
        in_contact, idx, fc_new, corr, self.slack = _solve_active_set(
            model, self.G, self.E_dd, self.nd, self.droppers_slacken, self.slack, fa, fb, ri, rv, z_free, z_per_fc,
            dL_free, dL_per_fc)
        self.corr = corr
        f_c = fc_new if in_contact else 0.0
        F_new = n_c * f_c
        if len(idx):
            np.add.at(F_new, model.d_lo[idx], corr[idx])
            np.add.at(F_new, model.d_up[idx], -corr[idx])
        acc_new = acc_free + (g_c * f_c + (self.G[:, idx] @ corr[idx] if len(idx) else 0.0)) / (b * dt * dt)
        self.u = u_pred + b * dt * dt * acc_new
        self.v = v_pred + g * dt * acc_new
        self.acc = acc_new
        self.F_old = F_new
        return p.step(float(z_static_next + rv @ self.u[ri]))

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


def _pantograph_force(p: ChainPantograph, z_next: float) -> float:
    """The contact force the pantograph's next HHT step would give for a wire height z_next, in contact
    (without advancing it): its step is affine in z_next."""
    return p.contact_force_at(z_next)
