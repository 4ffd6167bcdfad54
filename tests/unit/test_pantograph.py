"""Pantograph models: statics, HHT harmonic response against the exact FRF (Paper A eq. 18), contact loss."""
import math

import numpy as np
import pytest

from pantohil.models.pantograph.interface import receptance, static_compliance_m_N
from pantohil.models.pantograph.lumped import ChainPantograph, RigidMass
from pantohil.models.parameters import PantographSection, pantograph_parameters

PAN = pantograph_parameters(PantographSection(), 120.0)  # Paper A Table A.3, k_c = 50 kN/m


def test_static_force_equals_uplift_at_reference_height():
    p = ChainPantograph(PAN, 1e-3, reference_height_m=0.02)
    assert p.settle(0.02) == pytest.approx(120.0, rel=1e-12)
    # lower wire: the pantograph is compressed by 1 cm through its static stiffness
    k_static = 1.0 / static_compliance_m_N(PAN)
    assert p.settle(0.01) == pytest.approx(120.0 + k_static * 0.01, rel=1e-9)


def _steady_harmonic(model, freq_hz, amp, dt, z_mean=0.0, periods=400):
    n = int(round(1 / (freq_hz * dt)))
    steps = n * periods
    t = np.arange(1, steps + 1) * dt
    z = z_mean + amp * np.sin(2 * math.pi * freq_hz * t)
    model.settle(z_mean)
    f = np.array([model.step(zi) for zi in z])
    tail, zt = f[-10 * n:], z[-10 * n:]
    ph = np.exp(-2j * math.pi * freq_hz * t[-10 * n:])
    return (tail @ ph) / (zt @ ph), f


@pytest.mark.parametrize("freq_hz,tol", [(2.0, 1e-3), (5.0, 2e-3), (10.0, 5e-3), (25.0, 1e-2)])
def test_hht_response_matches_the_exact_receptance(freq_hz, tol):
    # contact force / wire height = -1 / H_p (Paper A eqs. 18, 20); HHT at dt = 1 ms errs by O((w dt)^2)
    # plus its algorithmic damping. Frequencies near the head's contact resonance (14.8 Hz), where the
    # exact chain has almost no damping, are left out: there the algorithmic damping dominates.
    p = ChainPantograph(PAN, 1e-3)
    ratio, f = _steady_harmonic(p, freq_hz, 1e-4, 1e-3)
    exact = -1.0 / receptance(PAN, 2 * math.pi * freq_hz)[0]
    assert f[1000:].min() > 0  # never lost contact
    assert abs(ratio - exact) / abs(exact) < tol


def test_contact_loss_gives_zero_not_negative_force():
    p = ChainPantograph(PAN, 1e-3)
    _, f = _steady_harmonic(p, 8.0, 0.05, 1e-3)  # 5 cm at 8 Hz: the head cannot follow
    assert f.min() == 0.0
    assert (f == 0.0).mean() > 0.05
    assert np.all(f >= 0.0)


def test_rigid_mass_force_is_minus_m_times_acceleration():
    m = pantograph_parameters(PantographSection(masses_kg=(5.29,), stiffnesses_N_m=(0.0,), dampings_Ns_m=(0.0,),
                                                model="rigid_mass", gravity_m_s2=9.81), 0.0)
    r = RigidMass(m, 1e-3)
    ratio, f = _steady_harmonic(r, 10.0, 1e-3, 1e-3)
    w = 2 * math.pi * 10.0
    assert abs(ratio - 5.29 * w * w) / (5.29 * w * w) < 0.01  # f = -m z'' = m w^2 z
    assert f[-1000:].mean() == pytest.approx(-5.29 * 9.81, abs=1e-6)


def test_contact_frequency():
    assert PAN.contact_frequency_hz() == pytest.approx(math.sqrt(57000 / 6.6) / (2 * math.pi))
