"""What an engineer reads in a run folder: EN 50367's statistics in summary.json (the same definition
for HIL runs and fem-sim), the pantograph's position in steady_span.csv, and a run on a rig file
written by `pantohil rig-identify` (its complex response) summarised without error."""
from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import CASES_DIR, ROOT, load_run, pantohil
from pantohil.models.metrics import lowpass_periodic


def test_en50367_statistics_and_position_of_a_run(tmp_path):
    out = tmp_path / "run"
    proc = pantohil("run", "--engine", "inprocess", "--out", str(out), "--quiet", "--no-plots")
    assert proc.returncode == 0, proc.stderr
    summary, span = load_run(out)
    t, f, x = span[:, 0], span[:, 3], span[:, 4]
    speed = summary["speed_kmh"] / 3.6
    assert np.allclose(x, speed * t, atol=1e-6) and x[0] == 0.0
    cf = summary["contact_force"]
    # an independent computation from the CSV's 13 digits
    assert cf["std_N"] == pytest.approx(np.std(f), rel=1e-9) and cf["max_N"] == pytest.approx(f.max(), rel=1e-9)
    assert cf["stat_max_N"] == pytest.approx(cf["mean_N"] + 3 * cf["std_N"], rel=1e-12)
    assert cf["stat_min_N"] == pytest.approx(cf["mean_N"] - 3 * cf["std_N"], rel=1e-12)
    assert cf["contact_loss_pct"] == 0.0 and f.min() > 0
    low = lowpass_periodic(f, summary["dt_s"], 20.0)
    assert cf["filtered_20hz"]["std_N"] == pytest.approx(np.std(low), rel=1e-9)
    assert cf["filtered_20hz"]["stat_min_N"] == pytest.approx(np.mean(low) - 3 * np.std(low), rel=1e-9)


@pytest.mark.slow
def test_a_run_on_an_identified_rig_file_writes_its_summary(tmp_path):
    rig = tmp_path / "identified.toml"
    case = CASES_DIR / "paper_b_mass_300.toml"
    proc = pantohil("rig-identify", "--rig", str(ROOT / "models" / "data" / "rigs" / "paper_b.toml"),
                    "--case", str(case), "--out", str(rig))
    assert proc.returncode == 0, proc.stderr
    out = tmp_path / "run"
    proc = pantohil("run", str(case), "--set", f'rig.file="{rig}"', "--set", "run.max_spans=4", "--engine",
                    "inprocess", "--out", str(out), "--quiet", "--no-plots")
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr  # 4 spans: not yet converged
    summary = json.loads((out / "summary.json").read_text())
    response = summary["rig"]["chain"]["response"]
    assert len(response["frequencies_hz"]) == len(response["height_gain"]) == len(response["force_phase_deg"]) > 1
    assert "contact_loss_pct" not in summary["contact_force"]  # a rigid mass on the actuator: not defined


def test_a_fixed_length_test_that_ran_its_duration_is_completed(tmp_path):
    out = tmp_path / "fixed"
    proc = pantohil("run", "--engine", "inprocess", "--out", str(out), "--quiet", "--no-plots",
                    "--set", "run.duration_s=2.8", "--set", "run.max_spans=5")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and not summary["converged"] and summary["spans"] == 3
    assert "completed the planned run.duration_s = 2.8 s" in proc.stdout and "not converged" in proc.stdout


@pytest.mark.slow
def test_compare_of_two_runs_of_one_case_keeps_both(tmp_path):
    # the README's tour: the default run and a span-by-span one of the same case
    for name, extra in (("default", ()), ("span", ("--set", "hil.update=span", "--set", "hil.max_frequency_hz=10"))):
        proc = pantohil("run", "--engine", "inprocess", "--out", str(tmp_path / name), "--quiet", "--no-plots", *extra)
        assert proc.returncode == 0, proc.stderr
    proc = pantohil("compare", str(tmp_path / "default"), str(tmp_path / "span"), "--out", str(tmp_path / "cmp"))
    assert proc.returncode == 0, proc.stderr
    res = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    assert res["a"]["label"] != res["b"]["label"] and res["a"]["label"].endswith("default")
    assert res["rms_difference_N"] > 0 and (tmp_path / "cmp" / "contact_force.png").stat().st_size > 10_000


def test_a_run_logs_its_progress_in_lines(tmp_path):
    # stderr is a pipe here, as in a log: lines, no carriage returns (a terminal gets a bar)
    proc = pantohil("run", "--engine", "inprocess", "--out", str(tmp_path / "run"), "--no-plots",
                    "--set", "run.max_spans=3")
    assert proc.returncode == 1, proc.stderr
    assert "\r" not in proc.stderr and "asm_250: 3/3 span (100 %)" in proc.stderr


def test_plot_titles_name_the_overrides():
    from pantohil.models.case import load_case

    assert load_case(None).title == "asm_250"
    assert load_case(None, ["hil.max_frequency_hz=20", "run.max_spans=3"]).title == \
        "asm_250 [hil.max_frequency_hz=20, run.max_spans=3]"


def test_the_per_step_history_exports_as_a_table(tmp_path):
    import pandas as pd

    out = tmp_path / "run"
    proc = pantohil("run", "--engine", "inprocess", "--out", str(out), "--quiet", "--no-plots",
                    "--set", "run.max_spans=3")
    assert proc.returncode == 1, proc.stderr
    proc = pantohil("export", str(out), "--csv")
    assert proc.returncode == 0, proc.stderr
    steps = pd.read_parquet(out / "steps.parquet")
    summary, span = load_run(out)
    n = summary["samples_per_span"]
    assert len(steps) == 3 * n and np.allclose(steps["t_s"], np.arange(3 * n) * summary["dt_s"])
    assert {"catenary.contact_force", "rig.actuator_height", "pantograph.head_height"} <= set(steps.columns)
    # the log keeps the doubles (orchestrator/channels.py), the CSV 13 significant digits
    assert np.allclose(steps["catenary.force_at_sample"].to_numpy()[-n:], span[:, 3], rtol=1e-12, atol=0)
    assert pd.read_csv(out / "steps.csv").shape == steps.shape
    bad = pantohil("export", str(tmp_path))  # no run.mcap
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "no run.mcap" in bad.stderr
