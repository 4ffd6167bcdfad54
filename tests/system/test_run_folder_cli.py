"""`pantohil run --out`: used folders and files refused in one line, default folders under runs/,
the summary read back by attribute."""
from __future__ import annotations

import json

import pytest
from conftest import CASES_DIR, pantohil
from pantohil.orchestrator.run_summary import RunSummary


def test_the_cli_refuses_a_used_folder_or_a_file_in_one_line(tmp_path):
    used = tmp_path / "used"
    used.mkdir()
    (used / "steady_span.csv").write_text("old")
    (tmp_path / "file").write_text("")
    for out, needle in ((used, "exists and is not empty"), (tmp_path / "file", "exists and is not a folder")):
        proc = pantohil("run", "--out", str(out), "--quiet")
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and needle in lines[0], proc.stderr
    assert (used / "steady_span.csv").read_text() == "old"
    assert sorted(p.name for p in used.iterdir()) == ["steady_span.csv"]


@pytest.mark.slow
def test_a_case_name_with_a_path_runs_under_runs(tmp_path):
    case = tmp_path / "case.toml"
    text = (CASES_DIR / "asm_250.toml").read_text()
    case.write_text(text.replace('name = "asm_250"', 'name = "../../escape"', 1))
    assert 'name = "../../escape"' in case.read_text()
    work = tmp_path / "work"
    work.mkdir()
    proc = pantohil("run", str(case), "--set", "run.max_spans=1", "--quiet", cwd=work)
    assert proc.returncode == 1, proc.stderr
    (folder,) = (work / "runs").iterdir()
    assert folder.name.startswith("escape-")
    assert not (tmp_path / "escape").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["case.toml", "work"]


@pytest.mark.slow
def test_the_summary_reads_back_by_attribute(default_run):
    raw = json.loads((default_run / "summary.json").read_text())
    s = RunSummary.read(default_run)
    assert s.to_dict() == raw
    assert s.converged and s.exit_code == 0 and s.contact_force.std_N == raw["contact_force"]["std_N"]
    assert s.timing.realtime_factor == raw["timing"]["realtime_factor"]
