"""The finite-element catenary builder: element matrices against closed forms, form-finding,
vertical stiffness (Paper A Fig. 7) and the ASM fit (Paper A sec. 4, Table 1); the CLI is in
tests/system/test_catenary_cli.py."""

import numpy as np
import pytest
from conftest import CATENARIES_DIR as CATENARIES
from pantohil.models.catenary.asm.string import AsmParameters, wavelength_at_rest
from pantohil.models.catenary.fe.analysis import analyse
from pantohil.models.catenary.fe.definition import Wire, load_definition
from pantohil.models.catenary.fe.model import GRAVITY_M_S2, beam_matrices, form_find


@pytest.fixture(scope="module")
def paper_a():
    return analyse(load_definition(CATENARIES / "paper_a_stitched.toml"))


def _string(n: int, length: float, wire: Wire):
    """Assemble a single wire of n elements, ends fixed: (K, f) on the free dofs."""
    h = length / n
    K = np.zeros((2 * n + 2, 2 * n + 2))
    f = np.zeros(2 * n + 2)
    for e in range(n):
        ke, _, q = beam_matrices(h, wire)
        K[2 * e:2 * e + 4, 2 * e:2 * e + 4] += ke
        f[2 * e:2 * e + 4] += q
    free = np.r_[1:2 * n, 2 * n + 1]  # w fixed at both ends, slopes free
    return K[np.ix_(free, free)], f[free], free


def test_tensioned_string_sags_as_the_parabola():
    # taut string under its weight: mid-span sag w L^2 / (8 T), exactly (the element is exact for it)
    wire = Wire(tension_N=15000.0, mass_kg_m=1.2, bending_stiffness_N_m2=0.0)
    K, f, free = _string(40, 60.0, wire)
    z = np.linalg.solve(K, f)
    mid = list(free).index(40)
    assert z[mid] == pytest.approx(-1.2 * GRAVITY_M_S2 * 60.0**2 / (8 * 15000.0), rel=1e-9)


def test_point_load_stiffness_of_a_string_converges():
    # a unit force at the middle of a taut string of length 2a: stiffness 2 T / a. The C1 (Hermite)
    # elements cannot follow the kink under the load, so they are stiffer and converge with the mesh.
    wire = Wire(tension_N=20000.0, mass_kg_m=1.0, bending_stiffness_N_m2=0.0)
    errors = []
    for n in (20, 40, 160):  # element sizes 2, 1 and 0.25 m (the catenary mesh)
        K, _, free = _string(n, 40.0, wire)
        rhs = np.zeros(len(free))
        rhs[list(free).index(n)] = 1.0
        k = 1.0 / np.linalg.solve(K, rhs)[list(free).index(n)]
        errors.append(k / (2 * 20000.0 / 20.0) - 1.0)
    assert errors[0] > errors[1] > errors[2] > 0
    assert errors[2] < 5e-3


@pytest.mark.parametrize("name", ["paper_a_stitched", "benchmark_simple"])
def test_form_finding_meets_the_design_heights_with_droppers_in_tension(name):
    cat = load_definition(CATENARIES / f"{name}.toml")
    ff = form_find(cat, 3)
    assert ff.max_height_error_m < 1e-3
    assert np.all(ff.dropper_tensions_N > 0) and np.all(ff.dropper_lengths_m > 0)
    # the weight of a span is carried by its droppers and one steady arm (+ clamps)
    per_span = len(cat.dropper_positions_m)
    span_weight = (cat.contact.mass_kg_m * cat.span_m + per_span * cat.clamp_mass_contact_kg) * GRAVITY_M_S2
    carried = ff.dropper_tensions_N[per_span:2 * per_span].sum() + ff.steady_arm_forces_N[1]
    assert carried == pytest.approx(span_weight + cat.steady_arm_mass_kg * GRAVITY_M_S2
                                    + cat.dropper_mass_kg_m * ff.dropper_lengths_m[per_span:2 * per_span].sum() / 2
                                    * GRAVITY_M_S2, rel=2e-3)


def test_leading_harmonics_of_the_paper_a_profile_are_the_dropper_pass_ones(paper_a):
    # Paper A Fig. 12: harmonics 7 and 8 dominate (no pre-sag, so the first is small)
    assert {h["harmonic"] for h in paper_a.harmonics[:2]} == {7, 8}


def test_paper_a_vertical_stiffness(paper_a):
    # Paper A sec. 4.1: mean 2538.7 N/m; Fig. 7: highest near the supports, lowest in mid-span
    assert paper_a.mean_stiffness_N_m == pytest.approx(2538.7, rel=0.15)
    x, k = np.array(paper_a.stiffness_x_m), np.array(paper_a.stiffness_N_m)
    near = k[(x < 10) | (x > 55)].mean()
    middle = k[(x > 25) & (x < 40)].mean()
    assert near > middle * 1.1
    assert k[np.argmin(np.abs(x - 32.5))] < paper_a.mean_stiffness_N_m


def test_paper_a_asm_fit(paper_a):
    """Paper A Table 1: mu = 1.4652 / 1.4790 / 1.4735 kg/m over 5-20 / 10-20 / 10-40 Hz. Checked:
    the 10-40 Hz value within 15 % and the three within 2 % of each other (measured: 1.4749 / 1.4808 /
    1.4653, 1.06 % apart, each within 0.7 % of the printed value)."""
    fits = {tuple(f["band_hz"]): f["density_kg_m"] for f in paper_a.fits}
    assert fits[(10.0, 40.0)] == pytest.approx(1.4735, rel=0.15)
    values = list(fits.values())
    assert (max(values) - min(values)) / min(values) <= 0.02
    for band, printed in (((5.0, 20.0), 1.4652), ((10.0, 20.0), 1.4790), ((10.0, 40.0), 1.4735)):
        assert fits[band] == pytest.approx(printed, rel=0.015)
    # the fitted string reproduces the propagating FE wavelengths from 10 to 40 Hz: 1.8 % RMS; up to 6 % at
    # the edges of the periodic structure's stop bands (Bragg dispersion the string cannot have)
    p = AsmParameters(paper_a.contact_tension_N, fits[(10.0, 40.0)], paper_a.support_stiffness_N_m2,
                      paper_a.alpha_1_s, paper_a.beta_s)
    dev = np.array(
        [
            lam / wavelength_at_rest(p, 2 * np.pi * f) - 1
            for f, lam, ok in zip(paper_a.wave_frequencies_hz, paper_a.wavelengths_m, paper_a.propagating, strict=False)
            if ok and f >= 10
        ]
    )
    assert len(dev) > 100 and np.sqrt(np.mean(dev**2)) < 0.025 and np.max(np.abs(dev)) < 0.07


def _with_heights(name: str, heights, **catenary):
    import tomllib

    from pantohil.models.catenary.fe.definition import build_definition

    raw = tomllib.loads((CATENARIES / f"{name}.toml").read_text(encoding="utf-8"))
    raw["catenary"].update({"contact_wire_heights_m": list(heights), **catenary})
    return build_definition(raw)


def test_heights_at_the_droppers_equal_to_the_pre_sag_give_the_pre_sag_catenary():
    """The benchmark-like catenary's 55 mm pre-sag written as its heights at the droppers form-finds to the same
    dropper lengths and tensions (form-finding holds the contact wire at the droppers only)."""
    presag = load_definition(CATENARIES / "benchmark_simple.toml")
    heights = presag.design_height(np.array(presag.dropper_positions_m))
    given = _with_heights("benchmark_simple", heights, presag_m=0.0)
    a, b = form_find(presag, 3), form_find(given, 3)
    assert np.abs(b.dropper_lengths_m - a.dropper_lengths_m).max() < 1e-12
    assert np.abs(b.dropper_tensions_N - a.dropper_tensions_N).max() < 1e-8


def test_form_finding_holds_the_contact_wire_at_the_heights_given():
    heights = [0.0, -0.02, -0.035, -0.04, -0.035, -0.02, 0.0]
    cat = _with_heights("paper_a_stitched", heights)
    ff = form_find(cat, 3)
    per_span = len(heights)
    at_droppers = np.array([ff.heights[d[1]] for d in ff.section.droppers])
    assert np.abs(at_droppers - np.tile(heights, len(at_droppers) // per_span)).max() < 1e-6
    assert np.all(ff.dropper_tensions_N > 0)


@pytest.mark.parametrize(("heights", "extra", "message"), [
    ([0.0] * 6, {}, "catenary.contact_wire_heights_m: 6 heights for 7 droppers"),
    ([0.0] * 7, {"presag_m": 0.05}, "catenary.contact_wire_heights_m: give either"),
    ([0.0, 0.0, 0.0, 1.5, 0.0, 0.0, 0.0], {}, "catenary.contact_wire_heights_m: dropper 4 would need a length"),
])
def test_heights_that_cannot_be_built_are_named(heights, extra, message):
    from pantohil.models.catenary.fe.definition import CatenaryError

    with pytest.raises(CatenaryError, match=message) as err:
        form_find(_with_heights("paper_a_stitched", heights, **extra), 3)
    assert err.value.key == "catenary.contact_wire_heights_m"
