"""The in-process engine (`pantohil run --engine inprocess`) steps the FMUs' own models in the fmpy
master's Jacobi order: its converged span, its convergence history and every signal the master records
are the same to the bit as the FMU path's, and its run folder has the same files and channels."""
from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.reader import make_reader

from conftest import CASES_DIR, load_run, pantohil
from pantohil.models.case import load_case
from pantohil.orchestrator.hil_run import RunObserver, run_case
from pantohil.orchestrator.run_folder import STEADY_SPAN


class KeepRecords(RunObserver):
    """Copies of the master's records (every output and input of the steps still held) at the end."""

    def on_end(self, run) -> None:
        master = run.master
        rows = master.rows(max(0, master.k - master.capacity), master.k)
        self.k = master.k
        self.outputs = {n: (master.real_outputs[n], master.record[n][rows].copy()) for n in master.names}
        self.ints = {n: (master.int_outputs[n], a[rows].copy()) for n, a in master.record_int.items()}
        self.inputs = {n: (master.input_names[n], a[rows].copy()) for n, a in master.record_in.items()}
        self.values = {n: list(v) for n, v in master.values.items()}
        self.compiled = getattr(master, "compiled_blocks", None)


class KeepCorrections(KeepRecords):
    """KeepRecords, and the most droppers with a correction force at one phase at the end."""

    def on_end(self, run) -> None:
        super().on_end(run)
        hil = run.master.slaves["catenary"].stepped_iteration
        self.most_slack_at_once = int((hil.correction_at != 0.0).sum(axis=1).max())


def _both(case, tmp_path):
    out = {}
    for engine in ("fmu", "inprocess"):
        keep = KeepRecords()
        summary = run_case(case, tmp_path / engine, progress=False, engine=engine, observers=(keep,))
        out[engine] = (summary, keep)
    return out


def _assert_identical(runs, tmp_path):
    (s_fmu, r_fmu), (s_in, r_in) = runs["fmu"], runs["inprocess"]
    assert s_in.engine == "inprocess" and s_fmu.engine == "fmu"
    assert (s_in.status, s_in.spans) == (s_fmu.status, s_fmu.spans)
    assert s_in.convergence == s_fmu.convergence  # every span's change, mean, std, max, min: exactly
    _, span_fmu = load_run(tmp_path / "fmu")
    _, span_in = load_run(tmp_path / "inprocess")
    assert np.array_equal(span_fmu, span_in)
    assert (tmp_path / "fmu" / STEADY_SPAN).read_bytes() == (tmp_path / "inprocess" / STEADY_SPAN).read_bytes()
    assert r_in.k == r_fmu.k and r_in.values == r_fmu.values
    for kept in ("outputs", "ints", "inputs"):
        a, b = getattr(r_fmu, kept), getattr(r_in, kept)
        assert a.keys() == b.keys()
        for name in a:
            assert a[name][0] == b[name][0]
            assert np.array_equal(a[name][1], b[name][1], equal_nan=True), (kept, name)


def test_the_default_case_is_the_same_to_the_bit_in_process(tmp_path):
    case = load_case(None, [])
    runs = _both(case, tmp_path)
    _assert_identical(runs, tmp_path)
    assert runs["inprocess"][0].converged and runs["inprocess"][1].compiled
    assert runs["inprocess"][0].fmus == []


def test_a_rig_with_a_drive_ramp_a_servo_and_a_load_cell_is_the_same_to_the_bit_in_compiled_blocks(tmp_path):
    case = load_case(None, ["rig.comm_decimation=4", "rig.servo_bandwidth_hz=40", "rig.loadcell_cutoff_hz=30",
                            "rig.force_offset_N=2.5", "run.max_spans=4"])
    runs = _both(case, tmp_path)
    assert runs["inprocess"][1].compiled
    _assert_identical(runs, tmp_path)


def test_the_compiled_blocks_and_their_numpy_path_are_the_same_to_the_bit(tmp_path, monkeypatch):
    """PANTOHIL_JIT=0 steps the models one call at a time in Python (the path where numba is missing), also when
    the iteration diverges (a rig delay the advance does not cover, relaxation 0.9: stopped at the force limit)."""
    for overrides in ([], ["rig.delay_steps=40", "hil.delay_compensation=false", "hil.relaxation=0.9",
                           "run.max_spans=40"]):
        case = load_case(None, overrides)
        runs = {}
        for jit in ("1", "0"):
            monkeypatch.setenv("PANTOHIL_JIT", jit)
            keep = KeepRecords()
            runs[jit] = run_case(case, tmp_path / f"{len(overrides)}_{jit}", progress=False, engine="inprocess",
                                 observers=(keep,)), keep
        (s_jit, r_jit), (s_py, r_py) = runs["1"], runs["0"]
        assert r_jit.compiled and not r_py.compiled
        assert (s_jit.status, s_jit.spans, r_jit.k) == (s_py.status, s_py.spans, r_py.k)
        assert s_jit.status == ("diverged" if overrides else "converged"), s_jit.status
        assert s_jit.convergence == s_py.convergence and r_jit.values == r_py.values
        for name, (_, block) in r_py.outputs.items():
            assert np.array_equal(r_jit.outputs[name][1], block, equal_nan=True), name


@pytest.mark.slow
def test_a_pfem_case_with_droppers_is_the_same_to_the_bit_in_process(tmp_path):
    case = load_case(CASES_DIR / "pfem_benchmark_250.toml", [])
    runs = _both(case, tmp_path)
    assert runs["inprocess"][1].compiled
    _assert_identical(runs, tmp_path)
    assert runs["inprocess"][0].droppers == runs["fmu"][0].droppers


@pytest.mark.slow
def test_pfem_span_by_span_with_slack_droppers_is_the_same_compiled_and_in_python(tmp_path, monkeypatch):
    """The PFEM block with span-by-span updating and several droppers slack at once (the small system of Paper C
    eq. 40) steps as the models do one call at a time (PANTOHIL_JIT=0)."""
    case = load_case(CASES_DIR / "pfem_benchmark_250.toml", ["hil.update=span", "hil.relaxation=0.3",
                                                             "run.max_spans=12"])
    runs = {}
    for jit in ("1", "0"):
        monkeypatch.setenv("PANTOHIL_JIT", jit)
        keep = KeepCorrections()
        runs[jit] = run_case(case, tmp_path / jit, progress=False, engine="inprocess", observers=(keep,)), keep
    (s_jit, r_jit), (s_py, r_py) = runs["1"], runs["0"]
    assert r_jit.compiled and not r_py.compiled
    assert r_py.most_slack_at_once >= 2, "the case must exercise the several-dropper system"
    assert (s_jit.status, s_jit.spans, r_jit.k) == (s_py.status, s_py.spans, r_py.k)
    assert s_jit.convergence == s_py.convergence and r_jit.values == r_py.values
    for name, (_, block) in r_py.outputs.items():
        assert np.array_equal(r_jit.outputs[name][1], block, equal_nan=True), name


def _channels(path) -> dict[str, int]:
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    return {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}


def test_the_in_process_run_folder_has_the_fmu_runs_files_and_channels(tmp_path):
    args = ("--set", "run.max_spans=3", "--set", "run.duration_s=2.5", "--quiet")
    for engine in ("fmu", "inprocess"):
        proc = pantohil("run", "--out", str(tmp_path / engine), "--engine", engine, *args)
        assert proc.returncode in (0, 1), proc.stderr
    files = {p.name for p in (tmp_path / "inprocess").iterdir()}
    assert {"summary.json", "run.mcap", STEADY_SPAN, "contact_force.png", "convergence.png"} <= files
    assert files == {p.name for p in (tmp_path / "fmu").iterdir()} - {"fmus", "state"}
    assert _channels(tmp_path / "inprocess" / "run.mcap") == _channels(tmp_path / "fmu" / "run.mcap")
    summary = json.loads((tmp_path / "inprocess" / "summary.json").read_text())
    assert summary["engine"] == "inprocess" and summary["spans"] == 3


@pytest.mark.parametrize("args,clash", [
    (["--hardware", "127.0.0.1:47999"], "--hardware"),
    (["--master", "libcosim"], "--master libcosim"),
])
def test_the_in_process_engine_refuses_what_it_does_not_run(tmp_path, args, clash):
    out = tmp_path / "refused"
    proc = pantohil("run", "--engine", "inprocess", *args, "--out", str(out), "--quiet")
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "--engine inprocess" in lines[0] and clash in lines[0], proc.stderr
    assert not out.exists()


class StopAfterSpan(RunObserver):
    """Asks for a stop (as SIGINT would) once a given span has closed."""

    def __init__(self, stop, span: int):
        self.stop, self.span = stop, span

    def on_span(self, run, span: int, record: dict) -> None:
        if span == self.span:
            self.stop.request()


def test_a_stop_ends_an_in_process_run_at_a_step_boundary(tmp_path):
    from pantohil.orchestrator.stopping import StopRequest

    stop = StopRequest()
    summary = run_case(load_case(None, []), tmp_path / "run", progress=False, engine="inprocess", stop=stop,
                       observers=(StopAfterSpan(stop, 1),))
    assert summary.status == "interrupted" and summary.spans == 2 and summary.exit_code == 130
    assert (tmp_path / "run" / STEADY_SPAN).exists()
