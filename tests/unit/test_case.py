"""Case files: defaults, overrides and one-line errors naming the key."""
import pytest

from pantohil.models.case import CaseError, load_case


def test_default_case_derivations():
    c = load_case()
    assert c.samples_per_span == 936 and c.dt_s == pytest.approx(1e-3, rel=1e-12)
    assert c.n_harmonics == 24
    assert c.pantograph.uplift_force_N == pytest.approx(0.00097 * 250**2 + 70)  # 130.6 N (NOTES.md 3)


def test_override_parses_toml_values():
    c = load_case(None, ['hil.update="span"', "hil.max_frequency_hz=10", "run.speed_kmh=200"])
    # 200 km/h: a span lasts 1.17 s, so 10 Hz keeps harmonics 0..11 (11 x 0.855 Hz = 9.4 Hz)
    assert c.hil_update == "span" and c.n_harmonics == 12 and c.speed_kmh == pytest.approx(200)


@pytest.mark.parametrize("override,words", [
    ("pantograph.colour=1", ["pantograph.colour", "unknown key"]),
    ("bogus.key=1", ["bogus", "unknown section"]),
    ("pantograph.masses_kg=[6.6, -5.8, 5.8]", ["pantograph.masses_kg[1]", "(0, 1000]"]),
    ("run.speed_kmh=530", ["run.speed_kmh", "wave speed"]),
    ("hil.max_frequency_hz=600", ["hil.max_frequency_hz", "Nyquist"]),
    ("rig.delay_steps=936", ["rig.delay_steps", "shorter than a span"]),
    ("hil.relaxation=1.5", ["hil.relaxation", "(0, 1]"]),
    ("hil.update=\"sideways\"", ["hil.update"]),
    ("run.speed_kmh=\"fast\"", ["run.speed_kmh", "number"]),
    ("pantograph.stiffnesses_N_m=[1, 2]", ["pantograph.stiffnesses_N_m", "3 values"]),
])
def test_bad_input_names_the_key(override, words):
    with pytest.raises(CaseError) as err:
        load_case(None, [override])
    msg = str(err.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg


def test_malformed_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[run\nspeed_kmh = 250\n")
    with pytest.raises(CaseError, match="not valid TOML"):
        load_case(bad)
    with pytest.raises(CaseError, match="does not exist"):
        load_case(tmp_path / "missing.toml")
