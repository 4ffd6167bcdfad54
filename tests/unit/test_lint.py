"""The code base passes the project's ruff configuration ([tool.ruff] in pyproject.toml)."""
import subprocess
import sys

import pytest
from conftest import ROOT

pytest.importorskip("ruff")


def test_ruff_finds_nothing():
    proc = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", str(ROOT)], cwd=ROOT,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
