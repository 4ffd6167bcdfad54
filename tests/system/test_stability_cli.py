"""`pantohil stability`: maps on Dask, and its predictions against virtual HIL runs of the FMUs' models
(in process: the same result as the FMU path, tests/integration/test_inprocess.py)."""
import csv
import json
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from conftest import pantohil
from pantohil.models.case import load_case
from pantohil.models.catenary.receptance import asm_operator, harmonic_count
from pantohil.models.stability.map_point import problem_for, with_contact_stiffness

MASTER_LATENCY = 4  # one step per connection of the virtual loop (docs/user-guide.md: the system)

# (update, f_max [Hz], k_c [N/m], loop latency [steps], mu_c): both strategies, several delays
POINTS = [("step", 25, 5e4, 8, 0.1), ("step", 25, 5e4, 12, 0.1), ("step", 25, 5e4, 4, 0.3),
          ("step", 25, 2e5, 8, 0.1), ("span", 25, 5e4, 8, 0.1), ("span", 5, 1e4, 8, 0.27),
          ("span", 10, 1e4, 12, 0.16)]


def _predict(tmp_path, i, update, fmax, kc, latency, mu):
    out = tmp_path / f"map{i}"
    proc = pantohil("stability", "--update", update, "--fmax", str(fmax), "--contact-stiffness", str(kc),
                    "--delay", str(latency), "--relaxation", str(mu), "--workers", "1", "--out", str(out), "--quiet")
    assert proc.returncode == 0, proc.stderr
    with open(out / "stability.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 1
    return float(rows[0]["spectral_radius"])


def _simulate(tmp_path, i, update, fmax, kc, latency, mu):
    out = tmp_path / f"run{i}"
    proc = pantohil("run", "--set", f'hil.update="{update}"', "--set", f"hil.max_frequency_hz={fmax}",
                    "--set", f"pantograph.contact_stiffness_N_m={kc}", "--set", f"hil.relaxation={mu}",
                    "--set", f"rig.delay_steps={latency - MASTER_LATENCY}", "--set", "run.max_spans=150",
                    "--out", str(out), "--quiet", "--engine", "inprocess")  # the FMUs' models, same result
    assert proc.returncode in (0, 1), proc.stderr
    return json.loads((out / "summary.json").read_text())


@pytest.mark.slow
def test_predictions_meet_the_virtual_hil_runs(tmp_path):
    """Predicted stable (rho < 0.95) converge, predicted unstable (rho > 1.05) diverge and stop
    early; the measured rate per span equals rho; more spans where rho is larger."""
    with ThreadPoolExecutor(2) as pool:
        rho = list(pool.map(lambda a: _predict(tmp_path, a[0], *a[1]), enumerate(POINTS)))
        runs = list(pool.map(lambda a: _simulate(tmp_path, a[0], *a[1]), enumerate(POINTS)))
    table = []
    for p, r, s in zip(POINTS, rho, runs, strict=False):
        table.append((p, round(r, 4), s["status"], s["spans"]))
        assert r < 0.95 or r > 1.05, p
        if r < 0.95:
            assert s["converged"], (p, r, s["message"])
            change = np.array([h["change"] for h in s["convergence"] if h["change"] is not None])
            rate = (change[-1] / change[-11]) ** (1 / 10)  # asymptotic rate over the last 10 spans
            assert rate == pytest.approx(r, rel=0.05), (p, r, rate)
        else:
            assert s["diverged"] and s["spans"] < 150, (p, r, s["message"])
    for p, r, s in zip(POINTS, rho, runs, strict=False):
        if r < 0.95:  # spans to converge: from the first span whose change is below 0.01, shrinking by rho per span
            change = [h["change"] for h in s["convergence"]]
            first = next(i for i, c in enumerate(change) if c is not None and c < 0.01)
            predicted = first + np.log(1e-4 / change[first]) / np.log(r) + 1
            assert s["spans"] == pytest.approx(predicted, rel=0.1, abs=3), (p, r, s["spans"], predicted)
    print(table)


@pytest.mark.slow
def test_a_small_map_matches_the_library_and_is_plotted(tmp_path):
    out = tmp_path / "map"
    proc = pantohil("stability", "--update", "span", "--fmax", "5:25:3", "--contact-stiffness", "1e4:1e5:3:log",
                    "--workers", "1", "--out", str(out), "--quiet")
    assert proc.returncode == 0, proc.stderr
    with open(out / "stability.csv") as fh:
        reader = csv.DictReader(fh)
        assert reader.fieldnames == ["update", "f_max_hz", "contact_stiffness_N_m", "delay_steps", "relaxation",
                                     "spectral_radius"]
        rows = list(reader)
    assert len(rows) == 9 and {r["delay_steps"] for r in rows} == {"8"}
    case = load_case(None, [])
    for r in rows[::4]:
        nh = harmonic_count(float(r["f_max_hz"]), case.samples_per_span, case.dt_s)
        op = asm_operator(case.catenary, case.speed_m_s, case.samples_per_span, case.dt_s, nh)
        pb = problem_for("span", with_contact_stiffness(case.pantograph, float(r["contact_stiffness_N_m"])),
                         case.dt_s, 8, 8, kernel=op.kernel)
        assert float(r["spectral_radius"]) == pytest.approx(pb.spectral_radius(float(r["relaxation"])), rel=1e-6)
    assert (out / "stability_span_D8.png").stat().st_size > 10_000
    summary = json.loads((out / "summary.json").read_text())
    assert summary["points"] == 9 and summary["workers"] == 1


@pytest.mark.parametrize("args,needle", [
    (["--fmax", "5:1:0"], "--fmax: empty range"),
    (["--delay", "1.5"], "--delay: delays are whole steps"),
    (["--contact-stiffness", "-1"], "--contact-stiffness: must be > 0"),
    (["--fmax", "abc"], "--fmax: expected"),
])
def test_bad_map_input_gives_one_line(tmp_path, args, needle):
    out = tmp_path / "bad"
    proc = pantohil("stability", *args, "--out", str(out))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], proc.stderr
    assert not out.exists()
