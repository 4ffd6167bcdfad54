"""A plain `pip install .` (not editable) into a fresh virtual environment carries everything a user
needs: from a folder outside the source tree, `pantohil run` of every shipped case (a few spans each) and
`pantohil catenary` of every shipped catenary file succeed. The operator cache of the test session
(PANTOHIL_CACHE) is reused."""
from __future__ import annotations

import json
import os
import subprocess

import pytest
from conftest import CASES_DIR, CATENARIES_DIR, ROOT

CASES = sorted(p.name for p in CASES_DIR.glob("*.toml"))
CATENARIES = sorted(p.name for p in CATENARIES_DIR.glob("*.toml"))
SPANS = 3


@pytest.fixture(scope="module")
def installed(plain_installed):
    """The `pantohil` command of a fresh venv holding a non-editable install of this tree."""
    return plain_installed.parent / "pantohil"


def _run(cmd, cwd):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=3600)


@pytest.mark.slow
def test_the_installed_package_is_not_the_source_tree(installed, tmp_path):
    proc = _run([installed.parent / "python", "-c", "import pantohil.models.data as d; print(d.DATA_DIR)"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert not proc.stdout.strip().startswith(str(ROOT)), proc.stdout


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_every_shipped_case_runs_from_another_folder(installed, tmp_path, name):
    probe = _run([installed.parent / "python", "-c",
                  "from pantohil.models.data import CASES_DIR; print(CASES_DIR)"], tmp_path)
    case = probe.stdout.strip() + f"/{name}"
    # a few spans are enough to show that the installed copy finds and runs everything a case needs, in process
    # (FMUs are built from the installed copy in test_shipped_data_by_name_from_an_empty_folder) but a pair, which
    # runs as FMUs only; convergence of each case is checked where its method is (exit 1: ended at run.max_spans)
    pair = "[second_pantograph]" in (CASES_DIR / name).read_text()
    engine = [] if pair else ["--engine", "inprocess"]
    proc = _run([installed, "run", case, "--out", tmp_path / "run", "--quiet", *engine, "--no-plots",
                 "--set", f"run.max_spans={SPANS}"], tmp_path)
    assert proc.returncode in (0, 1), proc.stdout + proc.stderr
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["status"] in ("converged", "span_limit", "diverged") and summary["spans"] >= 1, summary["status"]


@pytest.mark.slow
@pytest.mark.parametrize("name", CATENARIES)
def test_every_shipped_catenary_file_builds_from_another_folder(installed, tmp_path, name):
    probe = _run([installed.parent / "python", "-c",
                  "from pantohil.models.data import CATENARIES_DIR; print(CATENARIES_DIR)"], tmp_path)
    path = probe.stdout.strip() + f"/{name}"
    proc = _run([installed, "catenary", path, "--out", tmp_path / "cat"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "cat" / "catenary.json").exists()


@pytest.mark.slow
def test_shipped_data_by_name_from_an_empty_folder(installed, tmp_path):
    pantohil = installed
    listing = _run([pantohil, "cases"], tmp_path)
    assert listing.returncode == 0 and "pfem_benchmark_250" in listing.stdout and "paper_d" in listing.stdout
    for kind in ("cases", "catenaries", "rigs", "sweeps"):
        assert f"\n{kind} (" in "\n" + listing.stdout, listing.stdout
    run = _run([pantohil, "run", "pfem_benchmark_250", "--out", tmp_path / "run", "--quiet", "--no-plots",
                "--set", f"run.max_spans={SPANS}"], tmp_path)
    assert run.returncode in (0, 1) and (tmp_path / "run" / "summary.json").exists(), run.stderr
    fem = _run([pantohil, "fem-sim", "pfem_benchmark_250", "--spans", "7", "--out", tmp_path / "fem"], tmp_path)
    assert fem.returncode == 0 and (tmp_path / "fem" / "summary.json").exists(), fem.stderr
    emu = subprocess.Popen([str(pantohil), "rig-emulator", "--case", "paper_b_mass_300", "--rig", "paper_b",
                            "--listen", "127.0.0.1:0", "--max-seconds", "60"], cwd=tmp_path, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    try:
        line = emu.stdout.readline()
        assert "rig emulator for paper_b_mass_300 with rig paper_b listening on" in line, line + emu.stderr.read()
    finally:
        emu.terminate()
        emu.wait(timeout=60)
    unknown = _run([pantohil, "run", "no_such_case", "--out", tmp_path / "none"], tmp_path)
    assert unknown.returncode == 2 and "no_such_case" in unknown.stderr and not (tmp_path / "none").exists()
