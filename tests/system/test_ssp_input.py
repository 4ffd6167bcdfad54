"""SSP input: members from inside the archive only, garbage FMUs refused in one line, and no
temporary folder left behind on any exit path."""
from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from conftest import pantohil


@pytest.fixture(scope="module")
def ssp(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("ssp_input") / "asm_250.ssp"
    proc = pantohil("build", "--ssp", str(path))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return path


def _rewrite(src: Path, dst: Path, replace: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            zout.writestr(item.filename, replace.get(item.filename, zin.read(item.filename)))
    return dst


def _run(args: list[str], tmp: Path) -> subprocess.CompletedProcess:
    """`pantohil run` with a temporary folder of its own, to see what it leaves there."""
    tmp.mkdir(exist_ok=True)
    env = dict(os.environ, TMPDIR=str(tmp))
    return subprocess.run([sys.executable, "-m", "pantohil.orchestrator.cli", "run", *args, "--quiet"],
                          capture_output=True, text=True, env=env)


def _ssd_with_source(ssp: Path, component: str, source: str) -> bytes:
    with zipfile.ZipFile(ssp) as z:
        ssd = z.read("SystemStructure.ssd").decode()
    old = f'source="resources/{component}.fmu"'
    assert old in ssd
    return ssd.replace(old, f'source="{source}"').encode()


@pytest.mark.parametrize("what,replace,needle", [
    ("garbage", {"resources/rig.fmu": b"\x00garbage" * 100}, "component 'rig': resources/rig.fmu: not a readable FMU"),
    ("no binary", None, "component 'pantograph': resources/pantograph.fmu: no binary for"),
    ("escaping", "../../../outside.fmu", "is not a member of the archive"),
    ("absolute", "/etc/hostname", "is not a member of the archive"),
])
def test_a_bad_member_is_refused_in_one_line(ssp, tmp_path, what, replace, needle):
    if what == "no binary":
        with zipfile.ZipFile(ssp) as z:
            fmu = z.read("resources/pantograph.fmu")
        stripped = tmp_path / "stripped.fmu"
        (tmp_path / "full.fmu").write_bytes(fmu)
        with zipfile.ZipFile(tmp_path / "full.fmu") as zin, zipfile.ZipFile(stripped, "w") as zout:
            for item in zin.infolist():
                if not item.filename.startswith("binaries/"):
                    zout.writestr(item.filename, zin.read(item.filename))
        replace = {"resources/pantograph.fmu": stripped.read_bytes()}
    elif isinstance(replace, str):
        (tmp_path / "outside.fmu").write_bytes(b"")
        replace = {"SystemStructure.ssd": _ssd_with_source(ssp, "rig", replace)}
    bad = _rewrite(ssp, tmp_path / "bad.ssp", replace)
    out = tmp_path / "run"
    proc = _run([str(bad), "--out", str(out)], tmp_path / "tmp")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and needle in lines[0], proc.stderr
    assert not out.exists()
    assert list((tmp_path / "tmp").iterdir()) == []


@pytest.mark.slow
def test_a_run_of_an_ssp_leaves_no_temporary_folder(ssp, tmp_path):
    proc = _run([str(ssp), "--set", "run.max_spans=1", "--out", str(tmp_path / "run")], tmp_path / "tmp")
    assert proc.returncode == 1 and "span_limit" in proc.stdout, proc.stderr
    assert (tmp_path / "run" / "summary.json").exists()
    assert list((tmp_path / "tmp").iterdir()) == []


@pytest.mark.slow
def test_code_in_an_ssp_is_never_run(ssp, tmp_path):
    # the catenary FMU of the archive gets a slave script that would leave a marker when imported
    marker = tmp_path / "PWNED"
    with zipfile.ZipFile(ssp) as z:
        inner = z.read("resources/catenary.fmu")
    inner_path = tmp_path / "catenary.fmu"
    inner_path.write_bytes(inner)
    with zipfile.ZipFile(inner_path) as z:
        script = next(n for n in z.namelist() if n.endswith("pantohil_catenary.py"))
        code = z.read(script).decode()
    crafted = _rewrite(inner_path, tmp_path / "crafted.fmu",
                       {script: f"open({str(marker)!r}, 'w').close()\n{code}".encode()})
    bad = _rewrite(ssp, tmp_path / "crafted.ssp", {"resources/catenary.fmu": crafted.read_bytes()})
    proc = _run([str(bad), "--set", "run.max_spans=1", "--out", str(tmp_path / "run")], tmp_path / "tmp")
    assert proc.returncode == 1, proc.stderr
    assert not marker.exists()
    summary = __import__("json").loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["ssp"] == {"archive_fmus_run": False, "archive_fmus_same_contents": False}
