"""The public API: `import pantohil` gives load_case, Case, run_case, CaseError and __version__, in the
development (editable) install and in a plain `pip install .` into a new virtual environment."""
from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
VERSION = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
CHECK = f"""
import sys, pantohil
assert pantohil.__version__ == {VERSION!r}, pantohil.__version__
case = pantohil.load_case(None, ["hil.update=span"])
assert isinstance(case, pantohil.Case) and case.hil_update == "span" and case.samples_per_span == 936
try:
    pantohil.load_case(None, ["run.speed_kmh=nan"])
except pantohil.CaseError as exc:
    assert "run.speed_kmh" in str(exc) and "--" not in str(exc), exc
else:
    sys.exit("a NaN speed was accepted")
assert callable(pantohil.run_case)
assert sorted(pantohil.__all__) == ["Case", "CaseError", "__version__", "load_case", "run_case"]
print(pantohil.__file__)
"""


def test_public_api_in_this_install(tmp_path):
    proc = subprocess.run([sys.executable, "-c", CHECK], cwd=tmp_path, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


@pytest.mark.slow
def test_public_api_after_a_plain_pip_install(plain_installed, tmp_path):
    py, venv = plain_installed, plain_installed.parents[1]
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    proc = subprocess.run([str(py), "-c", CHECK], cwd=elsewhere, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert str(venv) in proc.stdout and str(ROOT) not in proc.stdout, proc.stdout
