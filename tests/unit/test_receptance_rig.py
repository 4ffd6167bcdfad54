"""The periodic operator (Paper B eqs. 6-11, Paper D eqs. 4-8) and the rig model (Paper B sec. 4)."""
import math

import numpy as np
import pytest

from pantohil.models.catenary.asm.string import AsmParameters, receptance_direct
from pantohil.models.catenary.receptance import CirculantOperator, asm_operator, harmonic_count, reduce_harmonics
from pantohil.models.rig.chain import Rig, RigParameters

CAT = AsmParameters(31500.0, 1.4735, 51.15, 0.0125, 1e-4)


def test_harmonic_count_keeps_all_harmonics_up_to_fmax():
    assert harmonic_count(25.0, 936, 1e-3) == 24  # 23 x 1.068 Hz = 24.6 Hz
    assert harmonic_count(10.0, 936, 1e-3) == 10
    assert harmonic_count(1 / 0.936 * 5, 936, 1e-3) == 6  # f_max exactly on harmonic 5 keeps it


def test_circulant_operator_matches_its_dense_form():
    op = CirculantOperator(np.random.default_rng(0).normal(size=50))
    f = np.random.default_rng(1).normal(size=50)
    dense = op.dense()
    assert op.apply(f) == pytest.approx(dense @ f, abs=1e-12)
    for m in (0, 7, 49):
        assert op.column(m) == pytest.approx(dense[:, m])


def test_asm_operator_applies_the_frf_harmonic_by_harmonic():
    n, dt, v = 936, 1e-3, 250 / 3.6
    op = asm_operator(CAT, v, n, dt, 24)
    t = np.arange(n) * dt
    for k in (1, 7, 23, 30):
        f = np.cos(2 * math.pi * k * t / (n * dt))
        u = op.apply(f)
        h = receptance_direct(CAT, 2 * math.pi * k / (n * dt), v) if k < 24 else 0.0
        assert u == pytest.approx((h * np.exp(2j * math.pi * k * t / (n * dt))).real, abs=1e-12)


def test_reduce_harmonics():
    t = np.arange(100) / 100
    x = 1 + np.cos(2 * math.pi * 3 * t) + np.sin(2 * math.pi * 20 * t)
    assert reduce_harmonics(x, 4) == pytest.approx(1 + np.cos(2 * math.pi * 3 * t), abs=1e-12)


def test_pure_delay():
    rig = Rig(RigParameters(delay_steps=3), 1e-3)
    out = [rig.step(float(i), 0.0)[0] for i in range(1, 8)]
    assert out == [0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0]
    assert RigParameters(delay_steps=3).latency_steps(1e-3) == 3


def test_decimation_with_linear_drive_ramp():
    # N_com = 4: heights 4, 8, ... reach the drive; it ramps to each over the next 4 steps (Paper B sec. 4)
    rig = Rig(RigParameters(comm_decimation=4), 1e-3)
    out = [rig.step(float(i), 0.0)[0] for i in range(0, 12)]
    assert out[:4] == pytest.approx([0.0, 0.0, 0.0, 0.0])
    assert out[4:8] == pytest.approx([1.0, 2.0, 3.0, 4.0])
    assert out[8:12] == pytest.approx([5.0, 6.0, 7.0, 8.0])
    assert RigParameters(comm_decimation=4).latency_steps(1e-3) == 4


def test_servo_and_loadcell_have_unit_static_gain_and_offset_noise_add():
    p = RigParameters(servo_bandwidth_hz=30.0, loadcell_cutoff_hz=30.0, force_offset_N=160.0)
    rig = Rig(p, 1e-3)
    for _ in range(2000):
        z, f = rig.step(0.01, 100.0)
    assert z == pytest.approx(0.01, rel=1e-9) and f == pytest.approx(260.0, rel=1e-9)
    a = Rig(RigParameters(noise_std_N=2.0, noise_seed=7), 1e-3)
    b = Rig(RigParameters(noise_std_N=2.0, noise_seed=7), 1e-3)
    fa = np.array([a.step(0.0, 0.0)[1] for _ in range(5000)])
    fb = np.array([b.step(0.0, 0.0)[1] for _ in range(5000)])
    assert np.array_equal(fa, fb) and fa.std() == pytest.approx(2.0, rel=0.05)
