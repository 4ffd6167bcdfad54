"""A master whose optional package is not installed (`--master libcosim` without libcosimpy): one line
naming the extra to install, exit 2, nothing written, so that a retry into the same --out works."""
from __future__ import annotations

import subprocess
import sys

BLOCKED = """
import sys

class Missing:  # libcosimpy as if it were not installed
    def find_spec(self, name, path=None, target=None):
        if name == "libcosimpy" or name.startswith("libcosimpy."):
            raise ModuleNotFoundError(f"No module named {name!r}")
        return None

sys.meta_path.insert(0, Missing())
from pantohil.orchestrator.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_libcosim_without_its_package_is_one_line_and_writes_nothing(tmp_path):
    script = tmp_path / "blocked.py"
    script.write_text(BLOCKED)
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, str(script), "run", "--master", "libcosim", "--out", str(out), "--quiet"],
                          capture_output=True, text=True, timeout=600)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert 'pip install "pantohil[libcosim]"' in lines[0] and not out.exists()
