"""Rig files, the rig chains of Papers B and D, their frequency response, and the compensation of the
rig's dynamics at the kept harmonics (Paper D sec. 3.4 generalised)."""
from pathlib import Path

import numpy as np
import pytest
from conftest import closed_form_error_25hz

from pantohil.models.case import CaseError, load_case
from pantohil.models.rig.drive_chain import (RigChain, analytic_response, frequency_response, group_delay_s,
                                       latency_steps, pattern_spans)
from pantohil.models.rig.compensation import HarmonicCompensation
from pantohil.models.rig.rig_file import RigFileError, load_rig_file, rig_from_dict, rig_to_toml
from pantohil.models.hil.rig_loop import run_loop

DATA = Path(__file__).resolve().parents[2] / "models" / "data"
RIGS = DATA / "rigs"
CASES = DATA / "cases"


def _kept(n, dt, f_max=25.0):
    n_h = int(np.floor(f_max * n * dt + 1e-9)) + 1
    return n_h, np.arange(n_h) / (n * dt)


def test_paper_rigs_total_delay():
    """Paper B: about 19 ms from the force's measurement to the height reached, the model's own 1 ms step
    included; Paper D: 4 ms + 10 ms ramp (read at the 2 ms step's end) + the 30 Hz filter's 7.5 ms."""
    b = load_rig_file(RIGS / "paper_b.toml")
    total_b = group_delay_s(b, b.model_step_s)["total_s"] + b.model_step_s
    assert total_b == pytest.approx(0.019, abs=0.0006)
    assert latency_steps(b, 0.001) == 18
    d = load_rig_file(RIGS / "paper_d.toml")
    g = group_delay_s(d, d.model_step_s)
    assert g["height_s"] == pytest.approx(0.004 + 0.010 - 0.002 + 0.0003125 / 2, abs=2e-5)
    assert g["force_s"] == pytest.approx(np.sqrt(2) / (2 * np.pi * 30.0), rel=0.01)  # 2nd-order Butterworth


@pytest.mark.parametrize("rig,n,tol_gain,tol_deg", [("paper_b", 780, 2e-4, 0.01), ("paper_d", 330, 1e-2, 0.3)])
def test_simulated_response_matches_closed_form(rig, n, tol_gain, tol_deg):
    """The chain run with a multisine (exact, time-varying) against the closed form of its LTI
    approximation; the difference is the cost of that approximation (sub-reference staircase)."""
    spec = load_rig_file(RIGS / f"{rig}.toml")
    dt = spec.model_step_s
    n_h, freqs = _kept(n, dt)
    gz, gf = frequency_response(spec, dt, n, n_h)
    az, af = analytic_response(spec, dt, freqs)
    assert np.max(np.abs(np.abs(gz[1:]) / np.abs(az[1:]) - 1)) < tol_gain
    assert np.max(np.abs(np.degrees(np.angle(gz[1:] / az[1:])))) < tol_deg
    np.testing.assert_allclose(gf[1:], af[1:], rtol=1e-9)  # the force path is LTI: exact
    assert abs(gz[-1]) < 0.95  # the ramp's droop at 25 Hz is real and must be compensated


def test_chain_reaches_a_held_command_and_respects_limits():
    spec = load_rig_file(RIGS / "paper_b.toml")
    chain = RigChain(spec, 0.001)
    heights = [chain.step(1e-4, 0.0)[0] for _ in range(200)]  # a ramp within the acceleration limit
    assert heights[-1] == pytest.approx(1e-4, abs=1e-12)
    assert max(heights) < 1e-4 * 1.05  # damping 0.7 on a ramp: less than 5 % overshoot
    chain = RigChain(spec, 0.001)
    far = [chain.step(1.0, 0.0)[0] for _ in range(400)]
    assert max(far) <= spec.limits.stroke_max_m + 1e-3  # the motion profile stops at the stroke
    v = np.diff(far) / 0.001
    assert np.max(np.abs(v)) <= spec.limits.max_velocity_m_s * 1.2  # the position loop lags the profile


def test_pattern_period():
    """780 samples at N_com = 8: the drive's phase repeats every 2 spans; 936 (250 km/h): every 2."""
    spec = load_rig_file(RIGS / "paper_b.toml")
    assert pattern_spans(spec, 0.001, 780) == 2
    assert pattern_spans(spec, 0.001, 1170) == 4


def test_pure_delay_is_the_special_case():
    n, n_h, d = 780, 20, 7
    w = 2 * np.pi * np.arange(n_h) / n
    comp = HarmonicCompensation(n, np.exp(-1j * w * d), np.ones(n_h))
    z = np.fft.irfft(np.r_[np.random.default_rng(1).normal(size=n_h) + 0j, np.zeros(n // 2 + 1 - n_h)], n=n)
    for t in (0, 5, n - 3):
        assert comp.command(z, t) == pytest.approx(z[(t + d) % n], abs=1e-12)
    np.testing.assert_allclose(comp.force_column(3), np.eye(n)[3], atol=1e-12)


def test_compensation_inverts_the_gains():
    n, n_h = 400, 15
    rng = np.random.default_rng(2)
    gz = (0.5 + rng.random(n_h)) * np.exp(1j * rng.normal(size=n_h))
    gf = (0.5 + rng.random(n_h)) * np.exp(1j * rng.normal(size=n_h))
    gz[0], gf[0] = 1.0, 1.0
    comp = HarmonicCompensation(n, gz, gf)
    f = rng.normal(size=n)
    bf = comp.force_matrix() @ f
    spec_f, spec_bf = np.fft.rfft(f), np.fft.rfft(bf)
    np.testing.assert_allclose(spec_bf[:n_h], spec_f[:n_h] / gf, atol=1e-9)
    np.testing.assert_allclose(spec_bf[n_h:], spec_f[n_h:], atol=1e-9)  # above the kept band: unchanged
    z = np.fft.irfft(np.r_[rng.normal(size=n_h) + 1j * rng.normal(size=n_h), np.zeros(n // 2 + 1 - n_h)], n=n)
    c = np.array([comp.command(z, t) for t in range(n)])
    np.testing.assert_allclose(np.fft.rfft(c)[1:n_h] * gz[1:], np.fft.rfft(z)[1:n_h], atol=1e-9)


@pytest.mark.parametrize("patch,message", [
    ({"height": {"decimation": 0}}, "height.decimation: 0 is outside its range [1, 10000]"),
    ({"height": {"ramp": 1.0}}, "height.ramp: unknown key"),
    ({"force": {"filter_hz": 600.0}}, "force.filter_hz: 600 Hz is at or above the Nyquist"),
    ({"height": {"ramp_s": 0.02}}, "height.ramp_s: 0.02 s is longer than a reference period"),
    ({"limits": {"stroke_min_m": 0.2}}, "limits.stroke_max_m: must be above"),
    ({"response": {"frequencies_hz": [1.0]}}, "response.height_gain: missing"),
    ({"wiring": {}}, "wiring: unknown section"),
    # sizes that set a run's work and memory (issue 28, D09)
    ({"height": {"sub_step_s": 1e-9}}, "height.sub_step_s: 1e-09 s gives 1e+06 sub-steps per model step"),
    ({"height": {"delay_steps": 2_000_000_000}}, "height.delay_steps: 2000000000 is outside its range [0, 100000]"),
    ({"force": {"delay_steps": 100_001}}, "force.delay_steps: 100001 is outside its range [0, 100000]"),
    ({"height": {"decimation": 10_001}}, "height.decimation: 10001 is outside its range [1, 10000]"),
    ({"rig": {"model_step_s": 1e-9}}, "rig.model_step_s: 1e-09 s is outside its range [1e-05, 1]"),
])
def test_bad_rig_files(patch, message):
    raw = {"rig": {"name": "x", "model_step_s": 0.001}, "height": {"decimation": 8}}
    for section, keys in patch.items():
        raw.setdefault(section, {}).update(keys)
    with pytest.raises(RigFileError) as err:
        rig_from_dict(raw)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_rig_file_round_trip(tmp_path):
    spec = load_rig_file(RIGS / "paper_b.toml")
    path = tmp_path / "copy.toml"
    path.write_text(rig_to_toml(spec, "copy"))
    assert load_rig_file(path) == spec


def test_case_rig_file_errors(tmp_path):
    with pytest.raises(CaseError, match="rig.delay_steps: not with rig.file"):
        load_case(CASES / "paper_b_mass_300.toml", ["rig.delay_steps=3"])
    with pytest.raises(CaseError, match="rig.file: the rig runs at dt = 0.001 s"):
        load_case(CASES / "paper_b_mass_300.toml", ["run.dt_s=0.002"])
    with pytest.raises(CaseError, match="rig.file: rig file .* does not exist"):
        load_case(CASES / "paper_b_mass_300.toml", ["rig.file=\"nowhere.toml\""])
    with pytest.raises(CaseError, match="hil.rig_compensation: must be"):
        load_case(CASES / "paper_b_mass_300.toml", ["hil.rig_compensation=\"exact\""])



@pytest.mark.slow
def test_paper_b_mass_converges_to_the_closed_form_through_the_rig():
    """Paper B sec. 5.1 through the full Paper B chain (in process, the FMU master's semantics): with the
    rig's response compensated the converged force is within 3 % RMS of the std of the rig-free closed
    form after a 25 Hz low-pass (0.26 % measured); with only its whole-step latency it is not (6.8 %)."""
    case = load_case(CASES / "paper_b_mass_300.toml")
    result = run_loop(case)
    assert result.status == "converged"
    assert closed_form_error_25hz(case, result.force_N) < 0.01
    delay_only = load_case(CASES / "paper_b_mass_300.toml", ["hil.rig_compensation=\"delay\""])
    result = run_loop(delay_only)
    assert result.status == "converged"
    assert closed_form_error_25hz(delay_only, result.force_N) > 0.03


# --- identification with a rigid mass (pantohil rig-identify, issue 16 acceptance 3) ---

from pantohil.models.rig.identification import excitation, identify_chain, response_errors  # noqa: E402
from pantohil.models.rig.drive_chain import MeasuredResponse  # noqa: E402
from pantohil.models.rig.rig_file import with_measured  # noqa: E402


@pytest.mark.parametrize("rig,case_name", [("paper_b", "paper_b_mass_300"), ("paper_d", "paper_d_mass_300")])
def test_identification_of_a_chain_with_the_mass_reproduces_its_model(rig, case_name):
    """The multisine with the case's 5.29 kg mass through the chain in process: within 2 % and 2 deg of
    the chain's own frequency_response at every kept harmonic (measured: 1e-12 %, the same estimator)."""
    case = load_case(CASES / f"{case_name}.toml")
    spec = load_rig_file(RIGS / f"{rig}.toml")
    exc = excitation(spec, case.dt_s, case.samples_per_span, case.n_harmonics)
    measured = identify_chain(spec, exc, case.pantograph)
    gz, gf = frequency_response(spec, case.dt_s, case.samples_per_span, case.n_harmonics)
    err = response_errors(measured, gz[1:], gf[1:])
    for path in ("height", "force"):
        assert err[path]["max_magnitude_error"] < 0.02 and err[path]["max_phase_error_deg"] < 2.0, err[path]
    assert len(measured.frequencies_hz) == case.n_harmonics - 1


def test_a_measured_response_round_trips_through_a_rig_file(tmp_path):
    spec = load_rig_file(RIGS / "paper_b.toml")
    m = MeasuredResponse((1.0, 2.5), (0.9 * np.exp(-0.3j), 0.8 * np.exp(-2.9j)), (1.0 + 0j, 0.7 * np.exp(-1j)))
    path = tmp_path / "identified.toml"
    path.write_text(rig_to_toml(with_measured(spec, m), "identified"))
    back = load_rig_file(path).measured
    assert back.frequencies_hz == m.frequencies_hz
    np.testing.assert_allclose(back.height, m.height, rtol=1e-12)
    np.testing.assert_allclose(back.force, m.force, rtol=1e-12)


@pytest.mark.parametrize("response,message", [
    ({"frequencies_hz": [2.0, 1.0]}, "response.frequencies_hz: one or more frequencies > 0, increasing"),
    ({"frequencies_hz": [0.0, 1.0]}, "response.frequencies_hz[0]: 0.0 Hz is outside its range (0, inf)"),
    ({"height_gain": [1.0, 0.0]}, "response.height_gain[1]: 0.0 is outside its range (0, inf)"),
    ({"force_phase_deg": [0.0, float("nan")]}, "response.force_phase_deg[1]: must be a finite number"),
    ({"height_gain": [1.0]}, "response.height_gain: 1 values for 2 frequencies"),
    ({"force_gain": "1.0"}, "response.force_gain: expected a list of numbers"),
])
def test_bad_response_tables(response, message):
    table = {"frequencies_hz": [1.0, 2.0], "height_gain": [1.0, 0.9], "height_phase_deg": [-5.0, -10.0],
             "force_gain": [1.0, 0.9], "force_phase_deg": [-3.0, -6.0]}
    raw = {"rig": {"name": "x", "model_step_s": 0.001}, "response": {**table, **response}}
    with pytest.raises(RigFileError) as err:
        rig_from_dict(raw)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_case_refuses_a_measured_response_without_its_harmonics(tmp_path):
    spec = load_rig_file(RIGS / "paper_b.toml")
    m = MeasuredResponse((1.0, 2.0), (1.0 + 0j, 1.0 + 0j), (1.0 + 0j, 1.0 + 0j))
    (tmp_path / "rig.toml").write_text(rig_to_toml(with_measured(spec, m)))
    with pytest.raises(CaseError, match=r"rig.file: the measured response has no point at 1.28205 Hz"):
        load_case(CASES / "paper_b_mass_300.toml", [f"rig.file=\"{tmp_path / 'rig.toml'}\""])
    # only a case that compensates with the table needs it
    load_case(CASES / "paper_b_mass_300.toml", [f"rig.file=\"{tmp_path / 'rig.toml'}\"",
                                                "hil.rig_compensation=\"delay\""])


def _rms_of_std(a, b):
    return float(np.sqrt(np.mean(((a - a.mean()) - (b - b.mean())) ** 2)) / np.std(b))


@pytest.mark.slow
def test_a_run_compensated_with_the_identified_rig_equals_one_with_the_model(tmp_path):
    """paper_b_mass_300 in process, compensated with the response identified in process (rig file written
    as rig-identify writes it) against the chain's own frequency_response: within 0.5 % RMS of the std."""
    case = load_case(CASES / "paper_b_mass_300.toml")
    exc = excitation(case.rig_spec, case.dt_s, case.samples_per_span, case.n_harmonics)
    measured = identify_chain(case.rig_spec, exc, case.pantograph)
    path = tmp_path / "identified.toml"
    path.write_text(rig_to_toml(with_measured(case.rig_spec, measured), "identified"))
    exact = run_loop(case)
    identified = run_loop(load_case(CASES / "paper_b_mass_300.toml", [f"rig.file=\"{path}\""]))
    assert exact.status == identified.status == "converged"
    diff = _rms_of_std(identified.force_N, exact.force_N)
    print(f"\nidentified vs model compensation: {100 * diff:.3g} % RMS of the std")
    assert diff < 0.005
