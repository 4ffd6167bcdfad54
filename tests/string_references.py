"""The ASM2 string (Paper A eq. 7) discretised with linear finite elements, twice: as a periodic block for the
PFEM and as a finite section of n spans for the conventional HHT integration. The tests hold the
periodic models and the FE simulation against each other and against the ASM's closed form with them; the
product's catenaries are files (models/catenary/fe/definition.py) or the ASM itself."""
from __future__ import annotations

import numpy as np
from scipy import sparse

from pantohil.models.catenary.asm.string import AsmParameters
from pantohil.models.catenary.fe.simulation import ContactTrack, SectionModel, track_positions
from pantohil.models.catenary.pfem.blocks import ContactBlock, linear_shapes
from pantohil.models.catenary.pfem.frf import PeriodicBlock


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


def asm_string_section(asm, span_m: float, n_spans: int, elements_per_span: int, z0, speed_m_s: float,
                       dt_s: float) -> SectionModel:
    """ASM2 (Paper A eq. 7) as a finite FE string of n spans: linear elements, tension T, density mu,
    distributed support kbar, C = alpha M + beta K, ends absorbing (dashpots sqrt(T mu)). `z0(x)` is
    the static contact-line height, periodic over a span."""
    ne = n_spans * elements_per_span
    Le = span_m / elements_per_span
    n = ne + 1
    i = np.arange(ne)
    rows = np.concatenate([i, i, i + 1, i + 1])
    cols = np.concatenate([i, i + 1, i, i + 1])
    mk = np.repeat(np.array([2, 1, 1, 2]) / 6.0 * Le, ne)
    kk = np.repeat(np.array([1, -1, -1, 1]) / Le, ne)
    M = sparse.csr_matrix((mk * asm.density_kg_m, (rows, cols)), shape=(n, n))
    K = sparse.csr_matrix((kk * asm.tension_N + mk * asm.support_stiffness_N_m2, (rows, cols)), shape=(n, n))
    dash = np.zeros(n)
    dash[[0, -1]] = np.sqrt(asm.tension_N * asm.density_kg_m)
    n_steps = int(round(n_spans * span_m / (speed_m_s * dt_s)))
    x = np.minimum(np.arange(n_steps + 1) * speed_m_s * dt_s, n_spans * span_m - 1e-9)
    shapes = linear_shapes(np.arange(n) * Le, x, n, np.arange(n))
    supports = np.arange(0, n, elements_per_span)
    empty = np.zeros(0, dtype=int)
    return SectionModel(K, M, asm.alpha_1_s, asm.beta_s, dash, shapes, z0(np.mod(x, span_m)), x, empty, empty,
                        np.zeros(0), np.zeros(0), supports)


def asm_string_tracks(asm, span_m: float, n_spans: int, elements_per_span: int, z0, speed_m_s: float, dt_s: float,
                      offsets_m: tuple[float, ...]) -> tuple[SectionModel, list[ContactTrack]]:
    """`asm_string_section` with contact points at `offsets_m` from the first (models/catenary/fe/simulation.py's
    track_positions): the section (its contact line the first point's) and each point's track."""
    model = asm_string_section(asm, span_m, n_spans, elements_per_span, z0, speed_m_s, dt_s)
    n = n_spans * elements_per_span + 1
    nodes = np.arange(n) * (span_m / elements_per_span)
    tracks = []
    for x, entry in track_positions(n_spans, span_m, speed_m_s, dt_s, offsets_m):
        tracks.append(ContactTrack(linear_shapes(nodes, x, n, np.arange(n)).tocsr(), z0(np.mod(x, span_m)), x, entry))
    model.x_m, model.shapes, model.z_static = tracks[0].x_m, tracks[0].shapes, tracks[0].z_static
    return model, tracks
