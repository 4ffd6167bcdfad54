"""The PFEM of a stitched catenary (Paper D sec. 5, Fig. 8a): a periodic block from mid-span to mid-span
holds the support with its stitch wire and stitch droppers, and reproduces the FE builder's catenary."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import ROOT
from pantohil.models.catenary.fe.asm_fit import dominant_wavelength
from pantohil.models.catenary.fe.analysis import analyse
from pantohil.models.catenary.fe.definition import load_definition
from pantohil.models.catenary.fe.model import form_find, vertical_stiffness
from pantohil.models.catenary.pfem.frf import FixedInterfaceModel
from pantohil.models.catenary.pfem.blocks import block_origin_m, periodic_block

STITCHED = ROOT / "models" / "data" / "catenaries" / "paper_a_stitched.toml"
N_250_2MS = 468  # 65 m at 250 km/h and dt = 2 ms


@pytest.fixture(scope="module")
def stitched():
    cat = load_definition(STITCHED)
    cb = periodic_block(cat, N_250_2MS)
    return cat, cb, FixedInterfaceModel.build(cb.block, 1.0)


def test_the_block_begins_on_a_contact_sample_and_holds_the_whole_stitch(stitched):
    cat, cb, _ = stitched
    step = cat.span_m / N_250_2MS
    assert cb.origin_m == pytest.approx(round(cb.origin_m / step) * step, abs=1e-9)
    assert cb.origin_m < cat.span_m - cat.stitch_length_m / 2  # the stitch wire's left end is inside
    assert cb.origin_m + cat.span_m > cat.span_m + cat.stitch_length_m / 2
    assert min(abs(cb.origin_m - x) for x in cat.dropper_positions_m) > 2.0  # far from every dropper
    assert cb.n_droppers == len(cat.dropper_positions_m)
    assert (
        block_origin_m(load_definition(ROOT / "models" / "data" / "catenaries" / "benchmark_simple.toml"), 792) == 0.0
    )


def test_the_block_reproduces_the_fe_vertical_stiffness_along_the_span(stitched):
    """The stitched PFEM block: the static single-load stiffness of the infinite periodic
    block (Bloch synthesis at w -> 0) against the FE builder's central span of 5 (measured 0.04 %)."""
    cat, cb, fim = stitched
    L = cat.span_m
    x = np.linspace(0.0, L, 53)[:-1]
    S = cb.contact_shapes(np.mod(x - cb.origin_m, L))
    flex = np.array([fim.point_response(1e-9, S[i], S[i], np.array([0]), 512)[0, 0, 0].real for i in range(len(x))])
    x_fe, k_fe = vertical_stiffness(form_find(cat, 5), 2)
    k_fe = np.interp(x, x_fe, k_fe)
    assert np.max(np.abs(1.0 / flex - k_fe) / k_fe) < 0.02


def test_the_block_radiates_the_fe_wavelengths(stitched):
    """The wavelength a fixed harmonic force radiates along the contact wire of the
    infinite periodic block (Floquet-Bloch synthesis over 17 blocks) against the FE builder's 12-span
    section with absorbing ends, at the propagating frequencies of the ASM fit (every 1 Hz from 5 to 40
    Hz here; measured at all 128 of them: max 1.37 %, RMS 0.19 %)."""
    cat, cb, fim = stitched
    L = cat.span_m
    an = analyse(cat)
    xb = np.arange(0.0, L, 0.25)
    S = cb.contact_shapes(xb)
    Sy = cb.contact_shapes(np.array([np.mod(0.5 * L - cb.origin_m, L)]))
    blocks = np.arange(-8, 9)
    x_global = (blocks[:, None] * L + xb[None, :] + cb.origin_m).ravel()
    errors = []
    for f, lam_fe, moving in zip(an.wave_frequencies_hz, an.wavelengths_m, an.propagating, strict=True):
        if not moving or abs(f - round(f)) > 1e-9:
            continue
        u = fim.point_response(2 * np.pi * f, S, Sy, blocks, 4096)[:, :, 0].ravel()
        errors.append(dominant_wavelength(x_global, u, 0.5 * L, L) / lam_fe - 1.0)
    assert len(errors) >= 25
    assert np.max(np.abs(errors)) < 0.02
