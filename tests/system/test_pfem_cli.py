"""PFEM (Paper C sec. 3-5, Paper D sec. 3) end to end: the appendix example command and the benchmark-like
case (slack droppers, reference results, stability map, libcosim, conventional FE sections)."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import CASES_DIR as CASES
from conftest import REFERENCE_DIR, cli_into, load_run, once_per_session, pantohil
from pantohil.models.case import mean_force_en50367

REFERENCE = REFERENCE_DIR / "pfem_benchmark_250.json"



def test_example_command_writes_the_summary(tmp_path):
    proc = pantohil("example", "paper-c-appendix", "--out", str(tmp_path / "ex"))
    assert proc.returncode == 0, proc.stderr
    s = json.loads((tmp_path / "ex" / "summary.json").read_text())
    assert np.array(s["operator_m_per_N"]).shape == (6, 6)
    assert s["first_forces_N"][:2] == pytest.approx([50.0, 25.7351], abs=0.5e-4)
    assert (tmp_path / "ex" / "contact_force.png").stat().st_size > 0


@pytest.fixture(scope="module")
def pfem_runs(tmp_path_factory):
    """The benchmark case with slackening droppers and linear, run once in the session (tests only read them)."""
    out = {}
    for name, extra in (("nonlinear", []), ("linear", ["--set", "pfem.droppers=false"])):
        # the model under test in process; the FMU path: test_inprocess.py
        make = cli_into("run", str(CASES / "pfem_benchmark_250.toml"), "--out", "{out}/run", "--quiet", *extra,
                        "--engine", "inprocess", timeout=1200)
        out[name] = once_per_session(tmp_path_factory, f"pfem_{name}", make) / "run"
    return out


@pytest.mark.slow
def test_pfem_benchmark_converges_with_slack_droppers(pfem_runs):
    s, span = load_run(pfem_runs["nonlinear"])
    assert s["converged"] and s["catenary"]["model"] == "pfem"
    last = s["convergence"][-1]
    assert last["change"] <= 1e-3
    assert sum(s["droppers"]["slack_steps"]) > 0
    # Paper C sec. 6: the end droppers (larger static tension) do not slacken; here the last one does, for
    # 6 steps, as it does in the conventional simulation (7 steps of 792)
    assert s["droppers"]["slack_steps"][0] == 0 and s["droppers"]["slack_steps"][-1] <= 10
    assert s["contact_force"]["mean_N"] == pytest.approx(mean_force_en50367(250.0), rel=5e-3)
    assert set(s["operators"]) >= {"build_s", "cached", "n_frequencies", "bytes"}
    assert s["operators"]["bytes"] < 100e6
    assert (pfem_runs["nonlinear"] / "dropper_corrections.png").stat().st_size > 0


@pytest.mark.slow
def test_pfem_benchmark_matches_its_reference_results(pfem_runs):
    """Regression against the statistics recorded on main (tests/reference): a change of the method or of
    the catenary shows up here. Tolerance 1 %: the run stops at a span-to-span change of 1e-3."""
    ref = json.loads(REFERENCE.read_text())
    s, _ = load_run(pfem_runs["nonlinear"])
    for key in ("std_N", "max_N", "min_N"):
        assert s["contact_force"]["filtered_20hz"][key] == pytest.approx(ref["nonlinear"][key], rel=0.01)
    s, _ = load_run(pfem_runs["linear"])
    assert s["contact_force"]["filtered_20hz"]["std_N"] == pytest.approx(ref["linear"]["std_N"], rel=0.01)


@pytest.mark.slow
def test_the_stability_map_predicts_the_linear_pfem_run(pfem_runs, tmp_path):
    """The stability map with a PFEM operator (not circulant: the dense span map): the linear run's rate per span."""
    out = tmp_path / "map"
    proc = pantohil("stability", str(CASES / "pfem_benchmark_250.toml"), "--set", "pfem.droppers=false",
                    "--fmax", "40", "--relaxation", "0.1", "--workers", "1", "--out", str(out), "--quiet")
    assert proc.returncode == 0, proc.stderr
    rho = float((out / "stability.csv").read_text().splitlines()[1].split(",")[-1])
    s, _ = load_run(pfem_runs["linear"])
    change = [h["change"] for h in s["convergence"]]
    rate = (change[-1] / change[-11]) ** (1 / 10)
    assert rho < 0.95 and rate == pytest.approx(rho, rel=0.05)


@pytest.mark.slow
def test_slackening_changes_the_force_where_droppers_slacken(pfem_runs):
    s_nl, span_nl = load_run(pfem_runs["nonlinear"])
    s_l, span_l = load_run(pfem_runs["linear"])
    assert s_l["operators"]["cached"]  # the second run reuses the operators
    assert "droppers" not in s_l
    diff = np.abs(span_nl[:, 3] - span_l[:, 3])
    assert diff.max() > 5.0  # N
    assert abs(s_nl["contact_force"]["std_N"] - s_l["contact_force"]["std_N"]) > 1.0


@pytest.mark.slow
def test_a_corrupt_cached_operator_file_gives_one_line(pfem_runs, tmp_path):
    cache = Path(os.environ["PANTOHIL_CACHE"])
    copy = tmp_path / "cache"
    # not the hidden files another worker is writing into the shared cache (they vanish as it finishes)
    shutil.copytree(cache / "operators", copy / "operators", ignore=shutil.ignore_patterns(".*"))
    for f in (copy / "operators").glob("*.npz"):
        f.write_bytes(f.read_bytes()[:1000])
    env = dict(os.environ, PANTOHIL_CACHE=str(copy))
    import subprocess
    import sys

    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pantohil.orchestrator.cli",
            "run",
            str(CASES / "pfem_benchmark_250.toml"),
            "--out",
            str(tmp_path / "run"),
            "--quiet",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "corrupt or truncated" in lines[0], proc.stderr


@pytest.mark.slow
def test_libcosim_runs_the_pfem_case_like_fmpy(pfem_runs, tmp_path):
    """The PFEM catenary FMU under OSP's C++ master gives the fmpy master's span to the last bit."""
    spans = []
    for master in ("fmpy", "libcosim"):
        out = tmp_path / master
        proc = pantohil("run", str(CASES / "pfem_benchmark_250.toml"), "--out", str(out), "--quiet",
                        "--master", master, "--set", "run.max_spans=3")
        assert proc.returncode == 1, proc.stderr  # 3 spans: not converged, by design
        spans.append(load_run(out)[1][:, 3])
    assert np.max(np.abs(spans[0] - spans[1])) <= 1e-6


@pytest.mark.slow
def test_pfem_agrees_with_conventional_sections_of_15_and_30_spans(pfem_runs, tmp_path):
    """Paper C Figs. 9-10: the converged PFEM span against the mean of the central
    spans of finite sections, both at 20 Hz. The std holds to the issue's 3 %. The RMS difference is 6.7 %
    against 30 spans (measured; the issue asks 5 %, met against 60 spans, 3.5 %, too slow for CI): the
    30-span model's central spans are themselves 4.7 % RMS from a 60-span model's (docs/method.md), so 8 % here.
    The longer section is the closer (Fig. 9). Droppers: the same slack intervals within 15 steps (measured
    <= 10 of 31-77) and the same largest correction within 10 % (measured <= 5.3 %) (Fig. 10)."""
    rms, std = {}, {}
    for spans in (15, 30):
        fe, cmp = tmp_path / f"fe{spans}", tmp_path / f"cmp{spans}"
        proc = pantohil("fem-sim", str(CASES / "pfem_benchmark_250.toml"), "--spans", str(spans), "--out", str(fe),
                        "--quiet", timeout=600)
        assert proc.returncode == 0, proc.stderr
        proc = pantohil("compare", str(pfem_runs["nonlinear"]), str(fe), "--out", str(cmp))
        assert proc.returncode == 0, proc.stderr
        c = json.loads((cmp / "compare.json").read_text())
        rms[spans], std[spans] = c["rms_difference_pct_of_std_b"], abs(c["std_difference_pct"])
    assert std[30] <= 3.0 and rms[30] <= 8.0
    assert rms[15] > rms[30] and std[15] > std[30]
    s_fe = json.loads((tmp_path / "fe30" / "summary.json").read_text())["droppers"]
    s_pf, _ = load_run(pfem_runs["nonlinear"])
    slack_fe, slack_pf = np.array(s_fe["slack_steps"]), np.array(s_pf["droppers"]["slack_steps"])
    assert np.all(slack_pf[1:8] > 0) and np.max(np.abs(slack_pf - slack_fe)) <= 15
    top_fe, top_pf = np.array(s_fe["max_correction_N"][1:8]), np.array(s_pf["droppers"]["max_correction_N"][1:8])
    assert np.allclose(top_pf, top_fe, rtol=0.10)
