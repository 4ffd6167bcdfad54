"""Conventional finite-section simulation (`pantohil fem-sim`, Paper C sec. 6) and `pantohil compare`."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import CASES_DIR, REFERENCE_DIR, cli_into, once_per_session, pantohil
from pantohil.orchestrator.mcap_follow import read_log

CASE = CASES_DIR / "pfem_benchmark_250.toml"
REFERENCE = REFERENCE_DIR / "fem_sim_6.json"


@pytest.fixture(scope="module")
def short_run(tmp_path_factory) -> Path:
    """A 6-span section, run once in the session (tests only read it)."""
    make = cli_into("fem-sim", str(CASE), "--spans", "6", "--central", "2", "--out", "{out}/six", "--quiet")
    return once_per_session(tmp_path_factory, "fem_six", make) / "six"


@pytest.mark.slow
def test_short_section_writes_its_run_folder(short_run):
    s = json.loads((short_run / "summary.json").read_text())
    assert s["central_spans"] == [2, 3] and s["catenary_label"] == "benchmark-like (reconstructed)"
    for key in ("mean_N", "std_N", "stat_max_N", "stat_min_N", "max_N", "min_N", "contact_loss_pct"):
        assert key in s["contact_force"]
    c = s["contact_force"]
    assert c["stat_max_N"] == pytest.approx(c["mean_N"] + 3 * c["std_N"])
    assert s["max_support_uplift_m"] > 0
    d = np.loadtxt(short_run / "central_spans.csv", delimiter=",", skiprows=1)
    assert d.shape == (2 * 792, 4) and np.allclose(d[:792, 1], np.arange(792) * 1e-3)
    for name in ("run.mcap", "force_along_section.png", "central_spans.png", "dropper_corrections.png"):
        assert (short_run / name).stat().st_size > 0


@pytest.mark.slow
def test_short_section_matches_its_reference_results(short_run):
    """Regression against the statistics recorded on main (tests/reference); tolerance 0.5 %."""
    ref = json.loads(REFERENCE.read_text())
    s = json.loads((short_run / "summary.json").read_text())
    for key in ("mean_N", "std_N", "max_N", "min_N"):
        assert s["contact_force"][key] == pytest.approx(ref[key], rel=5e-3)


@pytest.mark.slow
def test_a_lost_contact_gives_zero_force_not_negative(tmp_path):
    out = tmp_path / "loss"
    proc = pantohil("fem-sim", str(CASE), "--spans", "6", "--central", "2", "--out", str(out), "--quiet",
                    "--set", "pantograph.uplift_force_N=30", "--set", "run.speed_kmh=320")
    assert proc.returncode == 0, proc.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["contact_force"]["contact_loss_pct"] > 0
    f = np.loadtxt(out / "central_spans.csv", delimiter=",", skiprows=1)[:, 2]
    assert f.min() == 0.0 and np.all(f >= 0.0)


@pytest.mark.parametrize("args,message", [
    (["--spans", "0"], "argument --spans: 0 is outside [1, 200]"),
    (["--spans", "5"], "leave no central region"),
])
def test_bad_section_sizes_give_one_line(tmp_path, args, message):
    proc = pantohil("fem-sim", str(CASE), *args, "--out", str(tmp_path / "x"))
    assert proc.returncode == 2 and message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()


def test_a_case_without_a_catenary_file_gives_one_line(tmp_path):
    proc = pantohil("fem-sim", str(CASES_DIR / "asm_250.toml"), "--spans", "10",
                    "--out", str(tmp_path / "x"))
    assert proc.returncode == 2 and "definition_file" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_compare_overlays_two_runs(short_run, tmp_path):
    proc = pantohil("compare", str(short_run), str(short_run), "--out", str(tmp_path / "cmp"))
    assert proc.returncode == 0, proc.stderr
    r = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    assert r["rms_difference_N"] == 0.0 and r["std_difference_pct"] == 0.0
    assert (tmp_path / "cmp" / "contact_force.png").stat().st_size > 0


PAIR = ["--set", "second_pantograph.spacing_m=100", "--set", 'second_pantograph.position="trailing"']


@pytest.fixture(scope="module")
def pair_run(tmp_path_factory) -> Path:
    """An 8-span section with two pantographs, run once in the session (tests only read it)."""
    make = cli_into("fem-sim", str(CASE), "--spans", "8", "--central", "2", "--out", "{out}/pair", "--quiet", *PAIR)
    folder = once_per_session(tmp_path_factory, "fem_pair", make)
    assert "second pantograph, trailing 100 m" in (folder / "stdout.txt").read_text()
    return folder / "pair"


@pytest.mark.slow
def test_a_pair_writes_the_second_pantographs_force_summary_and_channel(pair_run):
    """Two pantographs 100 m apart over 8 spans: central_spans.csv holds both forces over the same spans,
    summary.json the second's statistics in the first's form, run.mcap a /pantograph_2 channel in the first's
    schema over its own passage."""
    from mcap.reader import make_reader

    s = json.loads((pair_run / "summary.json").read_text())
    second = s["second_pantograph"]
    assert second["spacing_m"] == 100.0 and second["position"] == "trailing"
    assert second["pantograph"]["model"] == "chain"
    assert set(second["contact_force"]) == set(s["contact_force"])
    assert second["sample_offset_m"] == pytest.approx(0.0, abs=1e-9)  # 100 m = 1440 steps of 69.4 mm
    header = (pair_run / "central_spans.csv").read_text().splitlines()[0]
    assert header == "span,t_s,f_N,f_lowpass_20hz_N,f2_N,f2_lowpass_20hz_N"
    d = np.loadtxt(pair_run / "central_spans.csv", delimiter=",", skiprows=1)
    assert d.shape == (2 * 792, 6) and list(np.unique(d[:, 0])) == [3, 4]
    assert np.all(d[:, 4] > 0) and not np.allclose(d[:, 2], d[:, 4])
    assert np.std(d[:, 5]) == pytest.approx(second["contact_force"]["std_N"], rel=1e-6)
    with open(pair_run / "run.mcap", "rb") as fh:
        summary = make_reader(fh).get_summary()
    counts = {ch.topic: summary.statistics.channel_message_counts[i] for i, ch in summary.channels.items()}
    assert counts["/pantograph"] == counts["/pantograph_2"] == 8 * 792
    fields = []
    for topic in ("/pantograph", "/pantograph_2"):
        _, _, msg = read_log(pair_run / "run.mcap", (topic,))[0]
        fields.append((topic, set(msg)))
    assert fields[0][1] == fields[1][1] == {"t", "x_m", "contact_force", "filtered_force"}, fields
    assert (pair_run / "force_along_section.png").stat().st_size > 0


@pytest.mark.slow
def test_a_pair_with_the_second_leading_swaps_the_two_forces(pair_run, tmp_path):
    """The second leading 100 m is the trailing run seen from the other pantograph: the columns swap."""
    out = tmp_path / "leading"
    proc = pantohil("fem-sim", str(CASE), "--spans", "8", "--central", "2", "--out", str(out), "--quiet",
                    "--set", "second_pantograph.spacing_m=100", "--set", 'second_pantograph.position="leading"')
    assert proc.returncode == 0, proc.stderr
    a = np.loadtxt(pair_run / "central_spans.csv", delimiter=",", skiprows=1)
    b = np.loadtxt(out / "central_spans.csv", delimiter=",", skiprows=1)
    assert np.allclose(a[:, 2:4], b[:, 4:6], rtol=1e-8) and np.allclose(a[:, 4:6], b[:, 2:4], rtol=1e-8)


@pytest.mark.parametrize("overrides,message", [
    (["second_pantograph.spacing_m=0"], "second_pantograph.spacing_m"),
    (["second_pantograph.spacing_m=-50"], "second_pantograph.spacing_m"),
    (["second_pantograph.spacing_m=400"], "not shorter than the 6-span section"),
    (["second_pantograph.spacing_m=100", 'second_pantograph.position="beside"'], "second_pantograph.position"),
])
def test_bad_pair_input_gives_one_line_and_writes_nothing(tmp_path, overrides, message):
    sets = [a for o in overrides for a in ("--set", o)]
    proc = pantohil("fem-sim", str(CASE), "--spans", "6", "--central", "2", "--out", str(tmp_path / "x"), *sets)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert not (tmp_path / "x").exists()
