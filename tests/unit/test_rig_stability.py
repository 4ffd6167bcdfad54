"""The span-to-span map with the rig's chain in the loop (models/stability/rig_map.py; Paper D eq. 13 and
appendix with the rig's dynamics in place of the pure delay): exact against the chain and the pure-delay
maps, and its rate per span against short in-process runs of the same loop (models/hil/rig_loop.py)."""
from pathlib import Path

import numpy as np
import pytest

from pantohil.models.case import load_case
from pantohil.models.catenary.receptance import asm_operator
from pantohil.models.hil.loop import HilSettings
from pantohil.models.hil.rig_loop import run_loop
from pantohil.models.pantograph.linear import linear_pantograph
from pantohil.models.rig.drive_chain import HeightPath, RigChain, RigSpec
from pantohil.models.rig.rig_file import load_rig_file
from pantohil.models.stability.map_point import best_relaxation, rig_problem_for
from pantohil.models.stability.maps import circulant_dense, circulant_range_basis, reduced_span_map, step_matrix
from pantohil.models.stability.rig_map import RigLoop, span_rate, rig_span_maps, rig_span_parts, step_rate

DATA = Path(__file__).resolve().parents[2] / "models" / "data"
CASES = DATA / "cases"


@pytest.mark.parametrize("rig", ["paper_b", "paper_d"])
def test_the_linear_chain_is_the_chain_below_its_limits(rig):
    """The map runs the chain itself on the rows of a state basis: below the motion profile's limits its
    outputs equal the chain's to the bit, and it is linear (twice the input, twice the output)."""
    spec = load_rig_file(DATA / "rigs" / f"{rig}.toml")
    dt = spec.model_step_s
    t = np.arange(400) * dt
    z = 1e-3 * (np.sin(2 * np.pi * 7 * t) + 0.5 * np.sin(2 * np.pi * 23 * t + 1))
    f = 10 * np.cos(2 * np.pi * 11 * t)
    chain = RigChain(spec, dt)
    ref = np.array([chain.step(a, b) for a, b in zip(z, f, strict=True)])
    lin = RigChain(spec, dt, linear=True)
    lin.set_state([np.zeros(2) for _ in lin.state()])
    out = np.array([np.array(lin.step(np.array([a, 2 * a]), np.array([b, 2 * b]))) for a, b in zip(z, f, strict=True)])
    assert np.array_equal(out[:, :, 0], ref)
    np.testing.assert_allclose(out[:, :, 1], 2 * ref, rtol=1e-12, atol=1e-15)
    with pytest.raises(ValueError, match="state values"):
        lin.set_state([0.0])


@pytest.mark.parametrize("rig_delay,mu", [(0, 0.1), (4, 0.3), (8, 0.1)])
def test_a_pure_delay_rig_gives_the_maps_of_the_latency(rig_delay, mu):
    """With a rig that is a pure delay d the rig map is Paper D's map with a latency of 4 connections + d
    (models/stability/maps.py), step-by-step and span-by-span, to 1e-9."""
    case = load_case(None, [])
    op = asm_operator(case.catenary, case.speed_m_s, case.samples_per_span, case.dt_s, case.n_harmonics)
    pan = linear_pantograph(case.pantograph, case.dt_s)
    lat = 4 + rig_delay
    loop = RigLoop(pan, RigSpec("delay", case.dt_s, HeightPath(delay_steps=rig_delay)), case.dt_s, lat)
    step_ref = step_matrix(op.kernel, pan, HilSettings("step", mu, lat), lat).spectral_radius
    assert step_rate(loop, op.kernel, mu) == pytest.approx(step_ref, rel=1e-9)
    dense = circulant_dense(op.kernel)
    span_ref = reduced_span_map(dense, pan, HilSettings("span", mu, lat), lat,
                                circulant_range_basis(op.kernel)).spectral_radius
    parts = rig_span_parts(loop, dense, case.n_harmonics)
    assert span_rate(rig_span_maps(parts, mu)) == pytest.approx(span_ref, rel=1e-9)
