"""A case with a [second_pantograph] on the command line: `pantohil run` runs the pair as a virtual HIL of FMUs
(the catenary's second contact point, a second instance of the pantograph FMU) and writes both pantographs'
results; the commands and options that run one pantograph refuse it in one line and write nothing (a result
without the second is not the case's); `pantohil direct` gives the pair's closed form at the section's spacing."""
import json

import numpy as np
import pytest
from mcap.reader import make_reader

from conftest import cli_into, once_per_session, pantohil
from pantohil.models.case import load_case
from pair_references import closed_form_pair
from pantohil.orchestrator.live_layout import layout_json, layout_topics

PAIR = ("--set", "second_pantograph.spacing_m=200")
# below the contact frequency (14.8 Hz) the pair's iteration is stable (tests/unit/test_two_pantographs.py)
# a change of 2e-5 per span leaves the slow pair about 0.15 % of the std from its fixed point (1e-4: 0.5 %)
PAIR_RUN = ["second_pantograph.spacing_m=90", 'second_pantograph.position="leading"', "hil.max_frequency_hz=10",
            "run.convergence_tol=2e-5"]


@pytest.fixture(scope="module")
def pair_run(tmp_path_factory):
    """The pair's run (PAIR_RUN), run once in the session: its folder and stdout (tests only read them)."""
    make = cli_into("run", *[a for s in PAIR_RUN for a in ("--set", s)], "--out", "{out}/run", "--quiet")
    folder = once_per_session(tmp_path_factory, "pair_run", make)
    return folder / "run", (folder / "stdout.txt").read_text()


@pytest.mark.slow
def test_pantohil_run_of_a_pair_converges_to_the_pairs_closed_form(pair_run):
    out, stdout = pair_run
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "converged" and summary["topology"] == "pair"
    second = summary["second_pantograph"]
    assert (second["spacing_m"], second["position"], second["pantograph"]["model"]) == (90.0, "leading", "chain")
    table = np.genfromtxt(out / "steady_span.csv", delimiter=",", names=True)
    assert table.dtype.names == ("t_s", "z0_m", "z_m", "f_N", "x_m", "z2_m", "f2_N")
    # the closed form written apart from pantohil's (tests/pair_references.py), within issue 33's 0.5 % of the std
    want = closed_form_pair(load_case(None, PAIR_RUN))
    for got, ref in ((table["f_N"], want[0]), (table["f2_N"], want[1])):
        assert np.sqrt(np.mean((got - ref) ** 2)) < 0.005 * np.std(ref)
    assert second["contact_force"]["std_N"] == pytest.approx(np.std(table["f2_N"]), rel=1e-9)
    assert summary["reference"]["rms_error_rel_std"] < 0.005 and second["reference"]["rms_error_rel_std"] < 0.005
    assert f"second pantograph (leading, 90 m): mean {second['contact_force']['mean_N']:.2f} N" in stdout
    assert (out / "contact_force_2.png").stat().st_size > 0
    with open(out / "run.mcap", "rb") as fh:
        topics = {c.topic for c in make_reader(fh).get_summary().channels.values()}
    assert {"/pantograph", "/pantograph_2"} <= topics
    layout = json.loads(layout_json("pair"))  # the shipped layout of a pair names only what its log holds
    assert layout_topics(layout) <= topics and "/pantograph_2" in layout_topics(layout)


@pytest.mark.parametrize("command", [("stability", "--fmax", "5:10:2"), ("run", "--engine", "inprocess")])
def test_a_command_for_one_pantograph_refuses_a_case_with_two(command, tmp_path):
    out = tmp_path / "out"
    done = pantohil(*command, *PAIR, "--out", str(out))
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and ("runs one pantograph" in lines[0] or "--fmax: a two-pantograph case" in lines[0])
    assert not out.exists()


@pytest.mark.slow
def test_stability_of_a_pair_names_the_update_that_converges(tmp_path):
    """At L = 70 m (250 km/h, 10 Hz) the step-by-step pair diverges even with the coupling compensation and the
    span-by-span one converges (tests/unit/test_pair_stability.py runs both); `pantohil stability` of the pair
    maps both strategies and says so before a run."""
    out = tmp_path / "stab"
    done = pantohil("stability", "--set", "second_pantograph.spacing_m=70", "--set", "hil.max_frequency_hz=10",
                    "--relaxation", "0.3", "--out", str(out), "--quiet")
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["pair"]["step"]["spectral_radius"] > 1.2
    assert summary["pair"]["span"]["spectral_radius"] == pytest.approx(0.9535, abs=2e-3)
    assert summary["stable_points"] == 1 and "converges with span-by-span updating" in summary["verdict"]
    assert "two pantographs, L = 70 m trailing: converges with span-by-span" in done.stdout
    table = np.genfromtxt(out / "stability.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert list(table["update"]) == ["step", "span"]


def test_direct_takes_the_spacing_of_the_case(tmp_path):
    done = pantohil("direct", *PAIR)
    assert done.returncode == 0, done.stderr
    assert "two pantographs 200 m apart: leading std 18.915 N, trailing std 20.051 N" in done.stdout


SWEEP = """[sweep]
name = "pair_spacing"
description = "the second pantograph's std against the spacing"
case = "{case}"
kind = "run"
{engine}
[set]
"hil.max_frequency_hz" = 10
"run.max_spans" = 3

[grid]
"second_pantograph.spacing_m" = [90.0, 200.0]
"""


@pytest.mark.slow
def test_a_sweep_of_the_spacing_reports_the_second_pantograph(tmp_path):
    from conftest import ROOT

    case = ROOT / "models/data/cases/asm_250.toml"
    (tmp_path / "fmu.toml").write_text(SWEEP.format(case=case, engine='engine = "fmu"'))
    done = pantohil("sweep", str(tmp_path / "fmu.toml"), "--out", str(tmp_path / "out"), "--quiet")
    assert done.returncode == 0, done.stdout + done.stderr
    rows = np.genfromtxt(tmp_path / "out/results.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert len(rows) == 2 and all(rows["second_std_20hz_N"] > 1.0)
    assert (tmp_path / "out/std_vs_second_pantograph_spacing_m.png").stat().st_size > 0
    # the in-process engine runs one pantograph: the sweep says so before it starts
    (tmp_path / "inprocess.toml").write_text(SWEEP.format(case=case, engine=""))
    refused = pantohil("sweep", str(tmp_path / "inprocess.toml"), "--out", str(tmp_path / "no"))
    assert refused.returncode == 2 and 'set engine = "fmu"' in refused.stderr
    assert not (tmp_path / "no").exists()
