"""One error hierarchy and one exit-code table (models/errors.py): every error pantohil raises on purpose
carries its exit code, a missing tool is one line and exit 2 with nothing written, and every exit code
the documentation names comes from the table."""
from __future__ import annotations

import importlib
import inspect
import os
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

from pantohil.models.errors import EXIT_CODE_MEANINGS, ExitCode, InputError, PantohilError, exit_code_table

ROOT = Path(__file__).resolve().parents[2]
SIGNAL_CODES = {129, 130, 143}  # 128 + SIGHUP, SIGINT, SIGTERM
# control flow inside one module, never seen by a caller of the library or the command line
INTERNAL = {"RunInterrupted", "_Stop", "RunGone", "_ParentGone", "BudgetSpent"}


def test_a_run_with_no_c_compiler_on_path_is_one_line_exit_2_and_writes_nothing(tmp_path):
    empty_path = tmp_path / "bin"
    empty_path.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "CC"}
    env.update(PATH=str(empty_path), PANTOHIL_CACHE=str(tmp_path / "cache"))  # an empty cache: the FMUs are built
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--out", str(out), "--quiet"],
                          capture_output=True, text=True, timeout=600, env=env, cwd=tmp_path)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "no C compiler" in lines[0] and "Traceback" not in proc.stderr
    assert not out.exists()


def _pantohil_modules():
    for layer in ("models", "fmus", "builder", "orchestrator"):
        package = importlib.import_module(f"pantohil.{layer}")
        for info in pkgutil.walk_packages(package.__path__, f"pantohil.{layer}."):
            if info.name.endswith("__main__"):
                continue
            try:
                yield importlib.import_module(info.name)
            except ImportError:  # an optional extra that is not installed (libcosimpy, foxglove)
                continue


def test_every_error_pantohil_raises_derives_from_the_one_base_and_keeps_its_builtin_base():
    strays, errors = [], []
    for module in _pantohil_modules():
        for name, cls in inspect.getmembers(module, inspect.isclass):
            if cls.__module__ != module.__name__ or not issubclass(cls, Exception) or name in INTERNAL:
                continue
            (errors if issubclass(cls, PantohilError) else strays).append(f"{module.__name__}.{name}")
    assert not strays, f"errors outside pantohil.models.errors' hierarchy: {strays}"
    assert len(errors) >= 15
    from pantohil.models.case import CaseError

    assert issubclass(CaseError, ValueError) and CaseError("x").exit_code == ExitCode.BAD_INPUT
    assert InputError("bad", key="run.dt_s").key == "run.dt_s"


def test_the_exit_code_table_of_the_user_guide_is_generated_from_the_one_table():
    doc = (ROOT / "docs" / "user-guide.md").read_text()
    section = doc[doc.index("## Exit codes\n"):]
    table = section[section.index("| code |"):]
    assert table[:table.index("\n\n") + 1] == exit_code_table()


def test_every_exit_code_the_documentation_names_is_in_the_table():
    allowed = {int(c) for c in ExitCode} | SIGNAL_CODES
    assert {int(c) for key in EXIT_CODE_MEANINGS for c in re.findall(r"\d+", key)} == allowed
    named = {}
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for m in re.finditer(r"\bexit(?: code)?s? (\d+)\b", path.read_text()):
            named.setdefault(int(m.group(1)), path.name)
    assert named and set(named) <= allowed, {c: f for c, f in named.items() if c not in allowed}


def test_output_to_a_reader_that_went_away_ends_quietly():
    """`pantohil cases | head -1`: the pipe's reader is gone before the listing is written; the command
    ends with exit 0 and no traceback (a closed read end makes every write fail, whatever the timing)."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        proc = subprocess.run([sys.executable, "-m", "pantohil.orchestrator.cli", "cases"], stdout=write_end,
                              stderr=subprocess.PIPE, text=True, timeout=300)
    finally:
        os.close(write_end)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
