"""Closed-form steady state (Paper A eqs. 24-45)."""
import math

import numpy as np
import pytest

from pantohil.models.catenary.asm.string import receptance_behind, receptance_direct
from pantohil.models.case import load_case
from pantohil.models.pantograph.interface import receptance
from pantohil.models.catenary.asm.closed_form import (
    one_sided_harmonics,
    optimal_spacings,
    single_pantograph,
    synthesize,
    two_pantographs,
)


@pytest.fixture(scope="module")
def case():
    return load_case()


def test_one_sided_harmonics_round_trip():
    x = np.random.default_rng(1).normal(size=936)
    assert synthesize(one_sided_harmonics(x), 936) == pytest.approx(x, abs=1e-12)


def test_std_eq41_equals_time_domain_std(case):
    amps = one_sided_harmonics(case.z0_samples())
    ss = single_pantograph(case.catenary, case.pantograph, case.speed_m_s, case.span_m, amps, 130.0, 24)
    assert ss.std_N() == pytest.approx(np.std(ss.force_series(936)), rel=1e-12)
    assert ss.force_amplitudes_N[0] == 130.0


def test_dropper_pass_harmonics_dominate_the_profile(case):
    # Paper A Fig. 12: the 7th and 8th harmonics (dropper pass) are the largest; no pre-sag -> small 1st
    amps = np.abs(one_sided_harmonics(case.z0_samples()))[1:30]
    assert set(np.argsort(-amps)[:2] + 1) == {7, 8}


@pytest.mark.parametrize("spacing_m,factor", [(50.0, 1.5), (200.0, 3.0)])
def test_leading_pantograph_disturbs_the_trailing_one_more_than_the_reverse(case, spacing_m, factor):
    # Paper A sec. 5.3: the interference of the leading on the trailing pantograph is much greater
    amps = one_sided_harmonics(case.z0_samples())
    args = (case.catenary, case.pantograph, case.speed_m_s, case.span_m, amps, 130.0, 24)
    single = single_pantograph(*args).force_amplitudes_N[1:]
    lead, trail = two_pantographs(*args, spacing_m=spacing_m)
    phase = np.exp(1j * 2 * np.pi * np.arange(1, 24) * spacing_m / case.span_m)  # eq. (30): the leader is ahead
    d_lead = np.linalg.norm(lead.force_amplitudes_N[1:] - single * phase)
    d_trail = np.linalg.norm(trail.force_amplitudes_N[1:] - single)
    assert d_trail > factor * d_lead


def test_optimal_spacings_are_minima_of_the_trailing_force(case):
    # Paper A eq. (42) with H12 = 0: |F2(L)| = |z0 / (Hp + H22)| |1 - (interference)|; its minima lie at
    # the L_min of eq. (45) up to the neglected k3 wave and k2 damping.
    cat, pan, v = case.catenary, case.pantograph, 300 / 3.6
    w = 2 * math.pi * 10.0
    hp, h11 = receptance(pan, w)[0], receptance_direct(cat, w, v)
    L = np.linspace(5, 150, 6000)
    h21 = np.array([receptance_behind(cat, w, v, x) for x in L])
    f2 = np.abs(1 - h21 * np.exp(1j * w * L / v) / (hp + h11))
    minima = L[1:-1][(f2[1:-1] < f2[:-2]) & (f2[1:-1] < f2[2:])]
    lmin = optimal_spacings(cat, pan, v, w, 150.0)
    period = np.diff(lmin).mean()
    assert len(lmin) >= 3
    for x in lmin:
        if 10 < x < 140:
            assert np.min(np.abs(minima - x)) < 0.05 * period
