"""`pantohil sweep`: a 12-point speed sweep on Dask, on a LocalCluster and on a separately started
scheduler and worker, interrupted and resumed; bad sweep input."""
import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time

import pandas as pd
import pytest

from conftest import ROOT, default_sigint, pantohil
from pantohil.models.case import load_case
from pantohil.orchestrator.direct import direct_solution

pytestmark = pytest.mark.network

SPEEDS = [200.0 + 100.0 * i / 11 for i in range(12)]


def sweep_file(tmp_path, name="speeds", grid=None, extra="", sweep_extra=""):
    grid = grid or '"run.speed_kmh" = { start = 200.0, stop = 300.0, num = 12 }'
    path = tmp_path / f"{name}.toml"
    path.write_text(f"""[sweep]
name = "{name}"
{sweep_extra}
case = "{ROOT / 'models' / 'data' / 'cases' / 'asm_250.toml'}"
[set]
"hil.relaxation" = 0.25
"run.convergence_tol" = 1e-3
{extra}
[grid]
{grid}
""")
    return path


def rows_of(folder):
    with open(folder / "results.csv") as fh:
        return list(csv.DictReader(fh))


def check_speed_results(out):
    rows = rows_of(out)
    assert len(rows) == 12 and all(r["status"] == "converged" for r in rows)
    assert len(pd.read_parquet(out / "results.parquet")) == 12
    for r in rows:  # each point against the ASM closed form at its speed (Paper A eqs. 38-41)
        case = load_case(None, [f"run.speed_kmh={r['run.speed_kmh']}", "hil.relaxation=0.25"])
        ref = direct_solution(case)["single"]["std_N"]
        assert float(r["std_N"]) == pytest.approx(ref, rel=0.01), r
    stds = [float(r["std_N"]) for r in sorted(rows, key=lambda r: float(r["run.speed_kmh"]))]
    assert stds == sorted(stds)  # Paper B Fig. 12: the std grows with the speed over 200-300 km/h
    assert (out / "std_vs_run_speed_kmh.png").stat().st_size > 10_000
    assert not list((out / "points").glob("*/*.png"))  # sweep.point_plots is false by default


def test_point_plots_put_the_run_figures_in_every_point_folder(tmp_path):
    out = tmp_path / "sweep"
    path = sweep_file(tmp_path, grid='"run.speed_kmh" = [220.0, 280.0]', extra='"run.max_spans" = 3')
    proc = pantohil("sweep", str(path), "--workers", "1", "--out", str(out), "--quiet", "--point-plots")
    assert proc.returncode == 0, proc.stderr
    folders = sorted((out / "points").iterdir())
    assert len(folders) == 2
    for folder in folders:
        assert (folder / "convergence.png").stat().st_size > 10_000
        assert (folder / "contact_force.png").stat().st_size > 10_000
        assert json.loads((folder / "summary.json").read_text())["spans"] == 3
    assert json.loads((out / "summary.json").read_text())["point_plots"] is True


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_speed_sweep_on_a_separate_scheduler_and_worker(tmp_path):
    port = free_port()
    sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                              "--port", str(port), "--no-dashboard"], stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", f"tcp://127.0.0.1:{port}",
                               "--nworkers", "2", "--nthreads", "1", "--no-dashboard"], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    try:
        from distributed import Client

        with Client(f"tcp://127.0.0.1:{port}", timeout=30) as client:
            client.wait_for_workers(2, timeout=60)
        out = tmp_path / "sweep"
        proc = pantohil("sweep", str(sweep_file(tmp_path)), "--scheduler", f"tcp://127.0.0.1:{port}",
                        "--out", str(out), "--quiet")
        assert proc.returncode == 0, proc.stderr
        check_speed_results(out)
        summary = json.loads((out / "summary.json").read_text())
        assert summary["workers"] == 2 and summary["scheduler"] == f"tcp://127.0.0.1:{port}"
    finally:
        for p in (worker, sched):
            p.terminate()
            p.wait(30)


def _start_cluster(port):
    """A scheduler and two single-thread workers, each in a process group of its own."""
    sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                              "--port", str(port), "--no-dashboard"], stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, start_new_session=True)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", f"tcp://127.0.0.1:{port}",
                               "--nworkers", "2", "--nthreads", "1", "--no-dashboard"], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, start_new_session=True)
    from distributed import Client

    with Client(f"tcp://127.0.0.1:{port}", timeout=60) as client:
        client.wait_for_workers(2, timeout=300)
    return sched, worker


@pytest.mark.slow
def test_an_interrupted_sweep_redoes_only_the_missing_points(tmp_path):
    # the interrupt comes while points are still to run: once 3 are done, the workers (and the runs
    # they started) are frozen with SIGSTOP. The points run through their FMUs (a second or more each, where a
    # compiled in-process point takes tens of ms), so that the other nine are not all done before the
    # 0.1 s poll sees the third
    path, out, port = sweep_file(tmp_path, sweep_extra='engine = "fmu"'), tmp_path / "sweep", free_port()
    sched, worker = _start_cluster(port)
    try:
        cmd = [sys.executable, "-m", "pantohil.orchestrator.cli", "sweep", str(path), "--scheduler",
               f"tcp://127.0.0.1:{port}", "--out", str(out), "--quiet"]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                preexec_fn=default_sigint)
        while not ((out / "results.csv").exists() and len(rows_of(out)) >= 3):
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.1)
        os.killpg(worker.pid, signal.SIGSTOP)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=3600)
    finally:
        for p in (worker, sched):
            os.killpg(p.pid, signal.SIGKILL)
            os.killpg(p.pid, signal.SIGCONT)
            p.wait(60)
    assert proc.returncode == 130, err
    first = {r["point"]: r for r in rows_of(out)}
    assert 3 <= len(first) < 12
    again = pantohil("sweep", str(path), "--workers", "2", "--out", str(out), "--quiet", timeout=3600)
    assert again.returncode == 0, again.stderr
    assert f"{len(first)} already done, {12 - len(first)} to run" in again.stdout
    rows = {r["point"]: r for r in rows_of(out)}
    for point, row in first.items():  # done points were not run again
        assert rows[point]["finished_utc"] == row["finished_utc"]
    check_speed_results(out)
    done = pantohil("sweep", str(path), "--workers", "2", "--out", str(out), "--quiet", timeout=3600)
    assert done.returncode == 0 and "all 12 points already done" in done.stdout, done.stdout + done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["workers"] == 0 and summary["ran"] == 0  # a finished sweep starts no cluster


@pytest.mark.parametrize("grid,needle", [
    ('"run.sped_kmh" = [200.0, 250.0]', "grid key 'run.sped_kmh' is not a case key"),
    ('"run.speed_kmh" = { start = 200.0, stop = 300.0, num = 0 }', "grid key 'run.speed_kmh' has an empty range"),
    ('"run.speed_kmh" = []', "grid key 'run.speed_kmh' has an empty range"),
    ('"run.speed_kmh" = [250.0, -5.0]', "run.speed_kmh"),
])
def test_bad_sweep_files_give_one_line(tmp_path, grid, needle):
    out = tmp_path / "bad"
    proc = pantohil("sweep", str(sweep_file(tmp_path, grid=grid)), "--out", str(out))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], proc.stderr
    assert not out.exists()


def test_an_unreachable_scheduler_gives_one_line(tmp_path):
    out = tmp_path / "bad"
    port = free_port()  # nothing listens there
    proc = pantohil("sweep", str(sweep_file(tmp_path)), "--scheduler", f"tcp://127.0.0.1:{port}", "--out", str(out))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "cannot reach the Dask scheduler" in lines[0], proc.stderr
    assert not out.exists()
