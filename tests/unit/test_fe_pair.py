"""The finite-section FE simulation with two pantographs (models/catenary/fe/simulation.py, simulate_points and
integrate_points; `pantohil fem-sim` of a case with a [second_pantograph]): the one-pantograph result when the
second never shares the section with the first, the symmetry of leading and trailing, and the ASM2 closed form
of two pantographs (Paper A eqs. 24-25) on a long FE string."""
from __future__ import annotations

import numpy as np
from conftest import CATENARIES_DIR as CATENARIES
from pantohil.models.catenary.fe.definition import load_definition
from pantohil.models.catenary.fe.simulation import simulate_points, simulate_section, track_positions
from pantohil.models.parameters import PantographSection, pantograph_parameters

SPEED, DT = 250 / 3.6, 1e-3


def _benchmark():
    return load_definition(CATENARIES / "benchmark_simple.toml"), pantograph_parameters(PantographSection(), 130.0)


def test_track_positions_keep_the_spacing_and_enter_at_the_start():
    (front, e0), (rear, e1) = track_positions(5, 55.0, SPEED, DT, (0.0, -100.0))
    assert e0 == 0 and e1 == int(np.ceil(100.0 / (SPEED * DT)))
    assert 0.0 <= rear[0] < SPEED * DT
    # the rear point is where the front one was 100 m earlier, at the same instants (before the section's end)
    k = np.arange(len(rear) - 1 - e1)
    assert np.allclose(front[k + e1] - rear[k], 100.0, atol=1e-9)


def test_a_second_pantograph_that_never_shares_the_section_leaves_the_first_alone():
    """Trailing by more than the 5-span section (275 m), the second enters after the first has left: the
    first's force, dropper forces and corrections are the single run's to the bit (the one-point step of
    the N-point stepper is the single stepper's)."""
    cat, pan = _benchmark()
    single = simulate_section(cat, pan, 5, SPEED, DT, reference_height_m=5.3)
    pair = simulate_points(cat, pan, 5, SPEED, DT, (0.0, -300.0), (5.3, 5.3))
    n = len(single.force_N)
    assert pair.entry_steps == (0, int(np.ceil(300.0 / (SPEED * DT))))
    assert np.array_equal(pair.forces_N[:n, 0], single.force_N)
    assert np.array_equal(pair.dropper_force_N[:n], single.dropper_force_N)
    assert np.array_equal(pair.dropper_correction_N[:n], single.dropper_correction_N)
    assert np.all(pair.forces_N[n:, 0] == 0.0) and np.all(pair.forces_N[:pair.entry_steps[1], 1] == 0.0)
    assert np.all(pair.forces_N[pair.entry_steps[1]:, 1] > 0.0)  # the second crosses the whole section


def test_a_second_pantograph_whose_waves_cannot_reach_the_first_leaves_it_alone():
    """Trailing 150 m on the 5-span section, the second shares it with the first for its last 1.8 s; the contact
    wire's waves (sqrt(T / m) = 127.7 m/s, 58 m/s faster than the pantographs) close 105 m of the 150 in that
    time: the first's force is the single run's to 1e-9 N (measured 1.4e-10 N, the two-point solve's round-off)."""
    cat, pan = _benchmark()
    shared_s = (5 * cat.span_m - 150.0) / SPEED  # from the second's entry to the first's exit
    assert (np.sqrt(cat.contact.tension_N / cat.contact.mass_kg_m) - SPEED) * shared_s < 150.0
    single = simulate_section(cat, pan, 5, SPEED, DT, reference_height_m=5.3)
    pair = simulate_points(cat, pan, 5, SPEED, DT, (0.0, -150.0), (5.3, 5.3))
    n = len(single.force_N)
    assert pair.entry_steps[1] < n  # on the section together
    assert np.max(np.abs(pair.forces_N[:n, 0] - single.force_N)) < 1e-9


def test_leading_and_trailing_are_the_same_pair_seen_from_the_other_pantograph():
    """The second trailing 100 m behind the first is the first trailing 100 m behind the second: each
    pantograph's force (each with its own reference height) is the other run's other pantograph's, to 1e-9 N
    (measured: equal to the bit), and the waves of each reach the other (the pair differs from one alone)."""
    cat, pan = _benchmark()
    trailing = simulate_points(cat, pan, 5, SPEED, DT, (0.0, -100.0), (5.3, 5.31))
    leading = simulate_points(cat, pan, 5, SPEED, DT, (0.0, 100.0), (5.31, 5.3))
    assert trailing.entry_steps == leading.entry_steps[::-1]
    assert np.allclose(trailing.forces_N[:, 0], leading.forces_N[:, 1], rtol=0, atol=1e-9)
    assert np.allclose(trailing.forces_N[:, 1], leading.forces_N[:, 0], rtol=0, atol=1e-9)
    single = simulate_section(cat, pan, 5, SPEED, DT, reference_height_m=5.3)
    n = len(single.force_N)
    assert np.max(np.abs(trailing.forces_N[:n, 0] - single.force_N)) > 1.0


def _central_mean(force: np.ndarray, n: int, dt: float, first: int) -> np.ndarray:
    """A passage's force, 20 Hz low-passed, averaged over its 3 central spans (n samples each from `first`)."""
    from pantohil.models.metrics import lowpass

    f = lowpass(force, dt)
    return np.mean([f[j * n - 1:(j + 1) * n - 1] for j in range(first, first + 3)], axis=0)


def test_two_pantographs_on_a_fe_string_follow_the_asm2_closed_form():
    """ASM2 (the default case's string, 250 km/h) as a 12-span FE string of 0.25 m linear elements
    (tests/string_references.py), two pantographs 90 m apart, the second trailing: each one's force over
    the 3 central spans (20 Hz, mean of the spans, each at its own positions) against the closed form of
    Paper A eqs. 24-25 (pair_forces, harmonics up to 100 Hz, each pantograph's reference height set for a
    mean force F_m as in the pair's HIL).

    Measured: std +0.53 % / -0.07 % and rms 8.2 % / 9.0 % of the std (first, second);
    the std is held within 2 %, the rms within 12 %. The rms is not the single string's 1.6 % (tests/unit/
    test_fe_string.py): the 0.25 m mesh lags (4.7 % alone, there) and a 12-span section is not yet the
    endless line (per span the rms falls from 18 % in span 3 to 8 % in spans 5-7); with 0.05 m elements and
    20 spans it is 8.1 % / 5.9 % for L = 90 m (std -0.85 % / -1.87 %) and 8.3 % / 5.0 % for L = 200 m (std
    0.05 % / 0.30 %), 210 s each, too long here. The tolerance still tells the pair from one pantograph: the
    closed form of one pantograph alone is 33 % / 72 % rms away, and the pair's closed form with the
    coupling receptances H12 and H21 swapped 59 % / 82 %."""
    from pantohil.models.case import load_case
    from pantohil.models.catenary.asm.closed_form import one_sided_harmonics, pair_forces, single_pantograph
    from pantohil.models.catenary.fe.simulation import integrate_points
    from pantohil.models.catenary.receptance import harmonic_count
    from pantohil.models.hil.pair_loop import pair_profiles, pair_reference_heights_m
    from pantohil.models.metrics import lowpass_periodic
    from string_references import asm_string_tracks

    spacing, spans = 90.0, 12
    case = load_case(None, [f"second_pantograph.spacing_m={spacing}", 'second_pantograph.position="trailing"'])
    n, dt, v = case.samples_per_span, case.dt_s, case.speed_m_s
    shift = int(round(spacing / (v * dt)))
    assert abs(shift * v * dt - spacing) < 1e-9  # the second's samples fall on the first's positions
    model, tracks = asm_string_tracks(case.catenary, case.span_m, spans, 260, case.profile.heights, v, dt,
                                      (0.0, -spacing))
    res = integrate_points(model, tracks, case.pantograph, dt, pair_reference_heights_m(case))
    fe = [_central_mean(res.forces_N[e:e + spans * n, i], n, dt, (spans - 3) // 2)
          for i, e in enumerate(res.entry_steps)]
    nh = harmonic_count(100.0, n, dt)
    pair = pair_forces(case.catenary, case.pantograph, v, dt, pair_profiles(case), case.pantograph.uplift_force_N,
                       nh, spacing, False)
    # the closed form's second force at sample k is where the first is at x_k: at its own x_m, k = m + shift
    refs = [lowpass_periodic(f, dt, 20.0) for f in (pair[0], np.roll(pair[1], -(shift % n)))]
    alone = lowpass_periodic(single_pantograph(case.catenary, case.pantograph, v, case.span_m,
                                               one_sided_harmonics(case.z0_samples()),
                                               case.pantograph.uplift_force_N, nh).force_series(n), dt, 20.0)
    for f, ref in zip(fe, refs, strict=True):
        rms = np.sqrt(np.mean((f - ref) ** 2))
        assert abs(f.std() - ref.std()) < 0.02 * ref.std(), (f.std(), ref.std())
        assert rms < 0.12 * ref.std(), rms / ref.std()
        assert np.sqrt(np.mean((f - alone) ** 2)) > 0.25 * ref.std()  # the tolerance sees the coupling
