"""Every command block of README.md and docs/user-guide.md, run as a user types it (in a bash of its own,
from an empty folder), with its exit code and what it writes checked. A documented command that breaks,
or a new block that this test does not know, fails the suite.

Small changes keep the suite short, and each is listed below: long runs get `--set run.max_spans=N`,
the fixed ports of the docs are swapped for free ones, background processes (`&`) are waited for until
they listen and stopped at the end of their block, and the Ctrl-C of the resume example is sent by the
test once the run has saved a span. The install blocks are what CI itself runs."""
from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from conftest import ROOT

PAGES = ("README.md", "docs/user-guide.md")
INSTALL = re.compile(r"^python3 -m pip install")  # what CI runs: the suite would install itself into itself
SHORT = {  # a command's first words -> overrides that keep it short (the command stays as written otherwise)
    "pantohil run pfem_benchmark_250": "--set run.max_spans=3",
    "pantohil run --hardware": "--set run.max_spans=3",
    "pantohil run paper_b_mass_300 --hardware": "--set run.max_spans=3",
    "pantohil run --master libcosim": "--set run.max_spans=3",
    "pantohil run --set second_pantograph.spacing_m=200": "--set run.max_spans=3",
    "pantohil optimise": "--max-designs 3 --explore 0 --no-confirm",
    "pantohil run --set hil.update=span": "--set run.max_spans=3",
    "pantohil run system.ssp": "--set run.max_spans=3",
    "pantohil stability --set second_pantograph.spacing_m=70": "--update step",  # both: test_two_pantographs_cli.py
}
READY = {"pantohil rig-emulator": ("stdout", "listening on"), "dask scheduler": ("stderr", "Scheduler at"),
         "dask worker": ("stderr", "Registered to")}


@dataclass(frozen=True)
class Expect:
    """What a documented command must do: its exit codes and the files it leaves (relative to its folder)."""

    codes: tuple = (0,)
    files: tuple = ()
    setup: str = ""  # shell run before the block (a file the block names but does not make)


EXPECT = {
    "pantohil run --out runs/default": Expect(files=("runs/default/summary.json", "runs/default/run.mcap")),
    "pantohil run --set hil.update=span --set hil.max_frequency_hz=10 --out runs/span":
        Expect((1,), ("runs/span/summary.json",)),
    "pantohil run pfem_benchmark_250 --out runs/pfem": Expect((1,), ("runs/pfem/summary.json",)),
    "pantohil compare runs/default runs/span --out runs/compare": Expect(files=("runs/compare/compare.json",)),
    "pantohil stability --fmax 2:40:10 --contact-stiffness 1e4:1e6:10:log --out runs/stab":
        Expect(files=("runs/stab/stability.csv", "runs/stab/summary.json")),
    "pantohil run": Expect(),
    "pantohil stability --set second_pantograph.spacing_m=70 --set hil.max_frequency_hz=10 --relaxation 0.3 "
    "--out runs/pair_stab": Expect(files=("runs/pair_stab/stability.csv", "runs/pair_stab/summary.json")),
    "pantohil optimise paper_a_stitched --case pfem_stitched_250 --set run.speed_kmh=300 --vary heights "
    "--out runs/oc1": Expect(files=("runs/oc1/optimised_catenary.toml", "runs/oc1/optimised_case.toml",
                                    "runs/oc1/summary.json")),
    "pantohil run --master libcosim --out runs/libcosim": Expect((1,), ("runs/libcosim/summary.json",)),
    "pantohil run system.ssp --out runs/ssp": Expect((1,), ("runs/ssp/summary.json",),
                                                     setup="pantohil build --ssp system.ssp --out fmus"),
    "pantohil run --engine inprocess --out runs/fast": Expect(files=("runs/fast/summary.json",)),
    "pantohil run --out runs/long": Expect((130,), ("runs/long/state/checkpoint.json",)),
    "pantohil run --resume runs/long": Expect(files=("runs/long/summary.json",)),
    "pantohil run --hardware 127.0.0.1:47800 --realtime --out runs/rig": Expect((1,), ("runs/rig/summary.json",)),
    "pantohil run --hardware 127.0.0.1:47800 --paced-by rig --out runs/rig-paced":
        Expect((1,), ("runs/rig-paced/summary.json",)),
    "pantohil run paper_b_mass_300 --hardware 127.0.0.1:47800 --out runs/b-rig":
        Expect((1,), ("runs/b-rig/summary.json",)),
    "pantohil rig-identify --hardware 127.0.0.1:47800 --case paper_b_mass_300 --out paper_b_identified.toml":
        Expect(files=("paper_b_identified.toml",)),
    'pantohil run paper_b_mass_300 --set "rig.file=\\"$PWD/paper_b_identified.toml\\""': Expect(),
    "pantohil run --set second_pantograph.spacing_m=200 --set hil.max_frequency_hz=10 --out runs/pair":
        Expect((1,), ("runs/pair/summary.json", "runs/pair/contact_force_2.png")),
    "pantohil build --set second_pantograph.spacing_m=200 --ssp pair.ssp": Expect(files=("pair.ssp",)),
    "pantohil direct --set second_pantograph.spacing_m=200": Expect(),
    "pantohil sweep speed_200_300 --scheduler tcp://127.0.0.1:8786 --out sweeps/speed":
        Expect(files=("sweeps/speed/results.csv", "sweeps/speed/summary.json")),
}
INTERRUPT = "pantohil run --out runs/long"  # the docs say: Ctrl-C at span 30; the test does it after span 1


def _blocks(page: str) -> list[list[str]]:
    """The bash blocks of a page as logical command lines (continuations joined, comments and indents gone)."""
    text = (ROOT / page).read_text(encoding="utf-8")
    out = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        joined = re.sub(r"\\\n\s*", "", block)
        lines = [_strip_comment(ln).strip() for ln in joined.splitlines()]
        out.append([ln for ln in lines if ln])
    return out


def _strip_comment(line: str) -> str:
    quoted = False
    for i, ch in enumerate(line):
        quoted = quoted ^ (ch in "\"'")
        if ch == "#" and not quoted and (i == 0 or line[i - 1] == " "):
            return line[:i]
    return line


BLOCKS = [(page, i, block) for page in PAGES for i, block in enumerate(_blocks(page))
          if not all(INSTALL.match(ln) for ln in block)]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _shell(line: str, ports: dict) -> str:
    """The line as run: its fixed ports swapped, its short-run overrides added."""
    for fixed, free in ports.items():
        line = line.replace(f":{fixed}", f":{free}").replace(f"--port {fixed}", f"--port {free}")
    for head, extra in SHORT.items():
        if line.startswith(head + " ") and "--resume" not in line:
            line = f"{line} {extra}"
    return line


class _Block:
    """One block's processes in one folder: foreground commands in turn, background ones until the end."""

    def __init__(self, cwd: Path):
        self.cwd = cwd
        self.env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}",
                    "PYTHONUNBUFFERED": "1"}
        self.background: list[subprocess.Popen] = []

    def start(self, line: str) -> None:
        proc = subprocess.Popen(["bash", "-c", f"exec {line}"], cwd=self.cwd, env=self.env, text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
        self.background.append(proc)
        ready = next((r for head, r in READY.items() if line.startswith(head)), None)
        if ready is not None:
            stream = proc.stdout if ready[0] == "stdout" else proc.stderr
            for text in stream:  # waits on the process's own words, not on a time
                if ready[1] in text:
                    break
            else:
                raise AssertionError(f"{line!r} ended before it was ready: {proc.wait()}")
        for stream in (proc.stdout, proc.stderr):  # read on, so that a full pipe never blocks it
            threading.Thread(target=stream.read, daemon=True).start()

    def run(self, line: str) -> subprocess.CompletedProcess:
        if line == INTERRUPT:
            return self._interrupted(line)
        return subprocess.run(["bash", "-c", line], cwd=self.cwd, env=self.env, capture_output=True, text=True,
                              timeout=1800)

    def _interrupted(self, line: str) -> subprocess.CompletedProcess:
        proc = subprocess.Popen(["bash", "-c", f"exec {line} --quiet"], cwd=self.cwd, env=self.env, text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        meta = self.cwd / "runs" / "long" / "state" / "checkpoint.json"
        while proc.poll() is None:
            try:
                if json.loads(meta.read_text())["span"] >= 1:
                    break
            except (FileNotFoundError, ValueError):
                pass
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=600)
        return subprocess.CompletedProcess(line, proc.returncode, out, err)

    def stop(self) -> None:
        for proc in self.background:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(timeout=60)


@pytest.mark.slow
@pytest.mark.network
@pytest.mark.parametrize("page,index,block", BLOCKS, ids=[f"{p}:{i}" for p, i, _ in BLOCKS])
def test_a_documented_block_runs_as_written(tmp_path, page, index, block):
    unknown = [ln.rstrip(" &") for ln in block if not ln.endswith("&") and ln not in EXPECT]
    assert not unknown, f"{page} block {index}: no expectation for {unknown} (add it to EXPECT)"
    ports = {47800: _free_port(), 8786: _free_port()}
    shell = _Block(tmp_path)
    try:
        if page == "README.md" and "runs/compare" in " ".join(block):  # the tour's step 1 made runs/default
            assert shell.run("pantohil run --out runs/default").returncode == 0
        for line in block:
            setup = EXPECT[line].setup if line in EXPECT else ""
            if setup:
                assert shell.run(setup).returncode == 0
            if line.endswith("&"):
                shell.start(_shell(line.rstrip(" &"), ports))
                continue
            proc = shell.run(_shell(line, ports))
            expect = EXPECT[line]
            assert proc.returncode in expect.codes, f"{line}: exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}"
            assert "Traceback" not in proc.stderr, proc.stderr
            missing = [f for f in expect.files if not (tmp_path / f).exists()]
            assert not missing, f"{line}: did not write {missing}"
    finally:
        shell.stop()
