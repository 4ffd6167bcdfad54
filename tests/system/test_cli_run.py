"""`pantohil run` end to end: three FMUs stepped by the fmpy master."""
import json

import numpy as np
import pytest
from mcap.reader import make_reader

from conftest import load_run, pantohil
from pantohil.orchestrator.mcap_follow import read_log


def rel_rms(a, b, scale):
    return float(np.sqrt(np.mean(((a - a.mean()) - (b - b.mean())) ** 2)) / scale)


@pytest.mark.slow
def test_default_case_converges_to_the_closed_form(default_run):
    summary, span = load_run(default_run)
    assert summary["converged"] and not summary["diverged"]
    assert summary["samples_per_span"] == 936 and summary["dt_s"] == pytest.approx(1e-3)
    assert summary["hil"]["delay_steps"] == summary["hil"]["loop_latency_steps"] + summary["hil"]["rig_latency_steps"]
    # the dynamic part within 0.5 % (rms) of the closed form's standard deviation
    assert summary["reference"]["rms_error_rel_std"] <= 5e-3
    assert summary["contact_force"]["mean_N"] == pytest.approx(summary["pantograph"]["uplift_force_N"], rel=1e-3)
    assert span.shape == (936, 5)  # t_s, z0_m, z_m, f_N, x_m
    for name in ("run.mcap", "contact_force.png", "convergence.png", "summary.json", "steady_span.csv"):
        assert (default_run / name).stat().st_size > 0
    for key in ("wall_s", "simulated_s", "realtime_factor"):
        assert summary["timing"][key] > 0
    assert set(summary["timing"]["per_step_us"]) == {"catenary", "rig", "pantograph"}


@pytest.mark.slow
def test_mcap_log_has_every_signal_group(default_run):
    summary, _ = load_run(default_run)
    with open(default_run / "run.mcap", "rb") as fh:
        stats = make_reader(fh).get_summary()
    counts = {ch.topic: stats.statistics.channel_message_counts[i] for i, ch in stats.channels.items()}
    steps = summary["spans"] * summary["samples_per_span"]
    assert counts["/catenary"] == counts["/rig"] == counts["/pantograph"] == steps
    assert counts["/convergence"] == summary["spans"]
    _, _, msg = read_log(default_run / "run.mcap", ("/pantograph",))[0]
    assert set(msg) == {"t", "contact_force", "head_height"}
    with open(default_run / "run.mcap", "rb") as fh:  # the mcap library's indexed reader, CRCs checked
        times = [m.log_time for _, _, m in make_reader(fh, validate_crcs=True).iter_messages(log_time_order=False)]
    assert len(times) == stats.statistics.message_count and times == sorted(times)


@pytest.mark.slow
def test_span_by_span_at_10_hz(tmp_path):
    out = tmp_path / "span"
    proc = pantohil("run", "--out", str(out), "--quiet", "--set", 'hil.update="span"', "--engine", "inprocess",
                    "--set", "hil.max_frequency_hz=10", "--set", "run.max_spans=400")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary, _ = load_run(out)
    assert summary["converged"] and summary["hil"]["harmonics"] == 10
    assert summary["reference"]["rms_error_rel_std"] <= 5e-3


@pytest.mark.slow
def test_rig_delay_compensated_equals_no_delay_and_uncompensated_differs(default_run, tmp_path):
    # the default case has a 4-step rig delay, compensated
    with_delay, f_delay = load_run(default_run)
    no_delay_dir = tmp_path / "nodelay"
    assert pantohil("run", "--out", str(no_delay_dir), "--quiet", "--set", "rig.delay_steps=0",
                    "--engine", "inprocess").returncode == 0
    no_delay, f_none = load_run(no_delay_dir)
    std = no_delay["contact_force"]["std_N"]
    assert rel_rms(f_delay[:, 3], f_none[:, 3], std) <= 5e-3
    unc_dir = tmp_path / "uncompensated"
    proc = pantohil("run", "--out", str(unc_dir), "--quiet", "--set", "hil.delay_compensation=false",
                    "--engine", "inprocess")
    unc, f_unc = load_run(unc_dir)
    assert unc["hil"]["delay_steps"] == unc["hil"]["loop_latency_steps"]
    if unc["converged"]:
        assert rel_rms(f_unc[:, 3], f_none[:, 3], std) > 0.05
    else:
        assert proc.returncode == 1


@pytest.mark.parametrize("override,key", [
    ("pantograph.colour=3", "pantograph.colour"),
    ("pantograph.masses_kg=[-6.6, 5.8, 5.8]", "pantograph.masses_kg"),
    ("run.speed_kmh=527", "run.speed_kmh"),
    ("hil.max_frequency_hz=501", "hil.max_frequency_hz"),
    ("rig.delay_steps=936", "rig.delay_steps"),
    ("rig.delay_steps=933", "rig.delay_steps"),  # 933 + the master's 4 steps reach a span
])
def test_bad_input_exits_2_with_one_line_and_no_run_folder(tmp_path, override, key):
    out = tmp_path / "never"
    proc = pantohil("run", "--out", str(out), "--quiet", "--set", override)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and "Traceback" not in proc.stderr
    assert not out.exists()


def test_malformed_case_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[catenary]\nspan_m = 65.0\ntension_N = \n")
    proc = pantohil("run", str(bad), "--out", str(tmp_path / "x"))
    assert proc.returncode == 2 and "not valid TOML" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.slow
def test_divergence_stops_at_once_and_says_so(tmp_path):
    # step-by-step at 25 Hz with 12 steps of loop delay is unstable (Paper D sec. 4)
    out = tmp_path / "div"
    proc = pantohil("run", "--out", str(out), "--quiet", "--set", "rig.delay_steps=8",
                    "--set", "run.force_limit_N=400", "--set", "run.max_spans=150")
    summary, _ = load_run(out)
    assert proc.returncode == 1 and summary["diverged"] and not summary["converged"]
    assert "diverged" in proc.stdout and summary["spans"] < 150
    with open(out / "run.mcap", "rb") as fh:  # the log up to the stop is readable
        assert sum(1 for _ in make_reader(fh).iter_messages(topics=["/rig"])) >= summary["spans"] * 936


def test_direct_closed_form(tmp_path):
    out = tmp_path / "direct.json"
    proc = pantohil("direct", "--second-pantograph-at", "200", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    res = json.loads(out.read_text())
    assert res["single"]["std_N"] == pytest.approx(17.95, abs=0.01)
    assert res["two_pantographs"]["trailing_std_N"] > 0
    assert all(h["L_min_m"] for h in res["two_pantographs"]["optimal_spacings_m"])
