"""Paper D sec. 5's HIL tests as the thesis ran them (Table 1 harmonics, dt = 2 ms, span-by-span updating,
mu_c = 0.1, mu_d = 1, 120 s with a 40 s ramp, D = 8), run virtually on the stitched and the simple
catenary's PFEM. Each case reports the statistics Paper D tabulates (std, max and min of the force
low-passed at 25 Hz) and the spans it took, and does what the spectral radius of its linear iteration
(Paper D eq. 13) predicts: below 1 its span-to-span change falls at that rate per span (converged within
its 120 s, or the spans it needs are reported), above 1 it stops as diverged."""
from __future__ import annotations

import csv

import numpy as np
import pytest
from conftest import CASES_DIR, load_run, pantohil
from pantohil.models.metrics import lowpass_periodic
from pantohil.orchestrator.fem_sim import correction_measures

CASES = [f"paper_d_{kind}_{v}" for kind in ("stitched", "simple", "mass_stitched") for v in (250, 300)]
CASES.append("paper_d_mass_stitched_300_plus160")


def _radius(case: str, out) -> float:
    proc = pantohil("stability", str(CASES_DIR / f"{case}.toml"), "--relaxation", "0.1", "--workers", "1",
                    "--out", str(out), "--quiet", timeout=3600)
    assert proc.returncode == 0, proc.stderr
    with open(out / "stability.csv") as fh:
        return float(next(csv.DictReader(fh))["spectral_radius"])


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES)
def test_paper_d_case_reports_its_statistics_and_does_what_its_spectral_radius_predicts(case, tmp_path, capsys):
    proc = pantohil("run", str(CASES_DIR / f"{case}.toml"), "--out", str(tmp_path / "run"), "--quiet",
                    "--engine", "inprocess", timeout=3600)  # the models, not the FMU path, are under test
    assert proc.returncode in (0, 1), proc.stderr
    s, span = load_run(tmp_path / "run")
    rho = _radius(case, tmp_path / "stability")
    f25 = lowpass_periodic(span[:, 3], s["dt_s"], 25.0)
    seconds = s["spans"] * s["samples_per_span"] * s["dt_s"]
    with capsys.disabled():
        print(f"\n{case}: {s['status']} after {s['spans']} spans ({seconds:.0f} s), spectral radius {rho:.4f}; "
              f"25 Hz: std {np.std(f25):.2f} N, max {np.max(f25):.1f} N, min {np.min(f25):.1f} N; "
              f"slack steps per dropper {s.get('droppers', {}).get('slack_steps')}")
    changes = np.array([c["change"] for c in s["convergence"]])
    if rho < 1.0:  # converging at the predicted rate per span (measured over its last 10 spans)
        rate = (changes[-1] / changes[-11]) ** 0.1
        assert rate == pytest.approx(rho, rel=0.03), (rate, rho)
        needed = s["spans"] if s["converged"] else s["spans"] + np.log(1e-3 / changes[-1]) / np.log(rate)
        with capsys.disabled():
            print(f"  rate per span {rate:.4f}; spans to a change of 1e-3 of the std: {needed:.0f} "
                  f"({needed * s['samples_per_span'] * s['dt_s']:.0f} s)")
    else:
        assert s["diverged"], s["message"]
    if "mass" in case:  # the validation set-up of sec. 5.1 is stable as the thesis ran it
        assert rho < 1.0
    if case.endswith("plus160"):  # Fig. 11: droppers slacken and get correction forces
        assert sum(s["droppers"]["slack_steps"]) > 0 and max(s["droppers"]["max_correction_N"]) > 0
        assert np.mean(f25) == pytest.approx(160.0, abs=0.5)
        # like for like with fem-sim (docs/validation.md): droppers 3-6 slacken, and their correction
        # impulses lie within the span-to-span range of a 60-span fem-sim section (spans 20-40, measured
        # 2026-12-02), whose largest values scatter by up to +-18 % from span to span
        d = np.loadtxt(tmp_path / "run" / "dropper_corrections.csv", delimiter=",", skiprows=1)
        m = correction_measures(d[:, 1:], s["dt_s"])
        assert [i for i, n in enumerate(m["slack_steps"]) if n] == [2, 3, 4, 5]
        fe_range = [(6.54, 8.63), (8.34, 10.48), (10.10, 11.52), (25.34, 43.90)]  # N s, droppers 3-6
        for impulse, (lo, hi) in zip(m["correction_impulse_Ns"][2:6], fe_range, strict=True):
            assert lo <= impulse <= hi, (m["correction_impulse_Ns"], fe_range)
