"""The FMUs in hosts other than pantohil's master: a C host with no Python of its own (tests/hosts/
jacobi_host.c, compiled here with cc) steps the virtual HIL as a Jacobi system and must reproduce the
fmpy master's converged span; wrong communication steps are refused in fmpy and in the C host; fmpy's
simulate_fmu takes step and stop time from the model descriptions."""
from __future__ import annotations

import os
import shutil
import subprocess
import urllib.parse
import sys
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy import read_model_description

from conftest import CASES_DIR, load_run, pantohil
from pantohil.builder.system import CONNECTIONS, FMU_NAMES

HOST_SOURCE = Path(__file__).parent / "hosts" / "jacobi_host.c"
CASES = CASES_DIR
# what a host that never heard of Python has in its environment: none of Python's own variables
PYTHON_VARIABLES = ("LD_PRELOAD", "PYTHONHOME", "PYTHONPATH", "PANTOHIL_LIBPYTHON", "VIRTUAL_ENV")


@pytest.fixture(scope="module")
def host(tmp_path_factory) -> Path:
    cc = shutil.which(os.environ.get("CC", "cc"))
    if cc is None:
        pytest.skip("no C compiler")
    exe = tmp_path_factory.mktemp("host") / "jacobi_host"
    headers = Path(fmpy.__file__).parent / "c-code"
    subprocess.run([cc, "-O2", "-std=c99", "-Wall", "-Wno-format-truncation", f"-I{headers}", "-o", str(exe),
                    str(HOST_SOURCE), "-ldl"], check=True)
    return exe


def _plan(fmus: dict[str, Path], into: Path, steps: int, last: int,
          wrong_step: tuple[str, float] | None = None) -> Path:
    lines, index = [], {}
    for i, name in enumerate(FMU_NAMES):
        folder = into / name
        with zipfile.ZipFile(fmus[name]) as z:
            z.extractall(folder)
        md = read_model_description(str(fmus[name]))
        index[name] = (i, {v.name: v.valueReference for v in md.modelVariables})
        lines.append(f"fmu {folder} {md.coSimulation.modelIdentifier} {md.guid}")
    for src, out, dst, inp in CONNECTIONS:
        lines.append(f"connect {index[src][0]} {index[src][1][out]} {index[dst][0]} {index[dst][1][inp]}")
    dt = read_model_description(str(fmus["catenary"])).defaultExperiment.stepSize
    lines += [f"record 0 {index['catenary'][1]['force_at_sample']}", f"steps {steps}", f"step {dt}", f"last {last}"]
    if wrong_step is not None:
        lines.append(f"wrong_step {index[wrong_step[0]][0]} {wrong_step[1]!r}")
    plan = into / "plan.txt"
    plan.write_text("\n".join(lines) + "\n")
    return plan


def _run_host(host: Path, plan: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in PYTHON_VARIABLES}
    proc = subprocess.run([str(host), str(plan)], env=env, capture_output=True, text=True, timeout=3600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr
    assert "python-loaded-before: 0" in proc.stdout  # the process had no interpreter when it loaded the FMUs
    return proc


def _host_matches_fmpy(host: Path, run_folder: Path, tmp_path: Path) -> float:
    summary, span = load_run(run_folder)
    n = summary["samples_per_span"]
    fmus = {name: run_folder / "fmus" / f"{name}.fmu" for name in FMU_NAMES}
    proc = _run_host(host, _plan(fmus, tmp_path, summary["spans"] * n, n))
    values = np.array([float(line.split()[1]) for line in proc.stdout.splitlines() if line.startswith("value:")])
    assert len(values) == n
    return float(np.max(np.abs(values - span[:, 3])))


@pytest.mark.slow
def test_c_host_without_python_reproduces_the_default_case(host, default_run, tmp_path):
    # steady_span.csv holds 13 significant digits: 1e-10 N at 130 N, below the 1e-9 N asked for
    assert _host_matches_fmpy(host, default_run, tmp_path) <= 1e-9


@pytest.mark.slow
def test_c_host_without_python_reproduces_the_pfem_case(host, tmp_path):
    run = tmp_path / "pfem"
    proc = pantohil("run", str(CASES / "pfem_benchmark_250.toml"), "--out", str(run), "--quiet", timeout=3600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert _host_matches_fmpy(host, run, tmp_path / "host") <= 1e-9


@pytest.mark.slow
def test_c_host_gets_an_error_and_a_message_for_a_wrong_step(host, default_run, tmp_path):
    fmus = {name: default_run / "fmus" / f"{name}.fmu" for name in FMU_NAMES}
    proc = _run_host(host, _plan(fmus, tmp_path, 0, 0, ("pantograph", 0.002)))
    assert "wrong-step-status: 3" in proc.stdout  # fmi2Error
    assert "communication step of 0.002 s" in proc.stdout and "fixed step of 0.001 s" in proc.stdout


@pytest.mark.slow
def test_c_host_names_a_missing_libpython(host, default_run, tmp_path):
    fmus = {name: default_run / "fmus" / f"{name}.fmu" for name in FMU_NAMES}
    plan = _plan(fmus, tmp_path, 1, 1)
    env = {k: v for k, v in os.environ.items() if k not in PYTHON_VARIABLES}
    env["PANTOHIL_LIBPYTHON"] = str(tmp_path / "no" / "libpython3.so")
    proc = subprocess.run([str(host), str(plan)], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode != 0
    logged = [line for line in proc.stdout.splitlines() if line.startswith("log ")]
    assert len(logged) == 1 and "needs libpython" in logged[0] and "PANTOHIL_LIBPYTHON" in logged[0]


SYSTEM_LIBPYTHON = Path("/usr/lib/x86_64-linux-gnu/libpython3.11.so.1.0")  # Debian's, without numpy here


@pytest.mark.slow
def test_c_host_names_numpy_when_the_python_lacks_it(host, default_run, tmp_path):
    has_numpy = subprocess.run(["/usr/bin/python3.11", "-c", "import numpy"], capture_output=True).returncode == 0 \
        if Path("/usr/bin/python3.11").exists() else True
    if not SYSTEM_LIBPYTHON.exists() or has_numpy:
        pytest.skip("needs a shared libpython 3.11 without numpy (Debian's python3.11)")
    fmus = {name: default_run / "fmus" / f"{name}.fmu" for name in FMU_NAMES}
    plan = _plan(fmus, tmp_path, 1, 1)
    env = {k: v for k, v in os.environ.items() if k not in PYTHON_VARIABLES}
    # PATH without the test's own environment: an embedded Python that finds a virtual environment's
    # python3 on PATH takes that environment's site-packages (its pyvenv.cfg), numpy included
    env.update(PANTOHIL_LIBPYTHON=str(SYSTEM_LIBPYTHON), PYTHONHOME="/usr", PYTHONPATH=str(tmp_path / "empty"),
               PATH=os.defpath)
    proc = subprocess.run([str(host), str(plan)], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode != 0
    assert "No module named 'numpy'" in proc.stdout
    assert "the embedded Python needs numpy and scipy" in proc.stdout


WRONG_STEP_IN_FMPY = """
import sys
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
path = sys.argv[1]
md = read_model_description(path)
slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="x")
slave.instantiate()
slave.setupExperiment(startTime=0.0)
slave.enterInitializationMode()
slave.exitInitializationMode()
dt = float(md.defaultExperiment.stepSize)
do_step = slave._functions["fmi2DoStep"]
rounded = [do_step(slave.component, k * dt, dt * (1 + 5.3e-7), 1) for k in range(3)]  # a master's rounding
remainder = do_step(slave.component, 3 * dt, 1.5e-11, 1)  # to a stop time between two steps
print("rounded", *rounded, "remainder", remainder, flush=True)
status = do_step(slave.component, 3 * dt, 2 * dt, 1)
print("status", status, flush=True)
"""


@pytest.mark.slow
def test_fmpy_gets_an_error_for_a_wrong_step_and_ok_for_rounding_and_a_last_remainder(default_run):
    for name in FMU_NAMES:
        proc = subprocess.run([sys.executable, "-c", WRONG_STEP_IN_FMPY, str(default_run / "fmus" / f"{name}.fmu")],
                              capture_output=True, text=True, timeout=600)
        assert "status 3" in proc.stdout and proc.returncode == 0, proc.stdout + proc.stderr  # fmi2Error, clean exit
        assert "this FMU takes only its fixed step of 0.001 s" in proc.stdout
        assert "rounded 0 0 0 remainder 0" in proc.stdout, proc.stdout  # fmi2OK: taken as dt, and with no step


SIMULATE_ALONE = """
import sys
from fmpy import simulate_fmu
result = simulate_fmu(sys.argv[1])
t = result["time"]
print("steps", len(t) - 1, "first", float(t[1] - t[0]), "stop", float(t[-1]), flush=True)
"""


@pytest.mark.slow
def test_simulate_fmu_takes_step_and_stop_time_from_the_model_description(tmp_path):
    out = tmp_path / "fmus"
    proc = pantohil("build", "--out", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for name in (*FMU_NAMES, "adapter"):  # the adapter alone: no rig answers, its counters run
        md = read_model_description(str(out / f"{name}.fmu"))
        assert float(md.defaultExperiment.stepSize) == 0.001 and float(md.defaultExperiment.stopTime) == pytest.approx(
            0.5
        )
        assert md.coSimulation.canHandleVariableCommunicationStepSize is False
        run = subprocess.run([sys.executable, "-c", SIMULATE_ALONE, str(out / f"{name}.fmu")], capture_output=True,
                             text=True, timeout=600)
        words = run.stdout.split()
        assert words[:2] == ["steps", "500"] and run.returncode == 0, run.stdout + run.stderr
        assert float(words[3]) == pytest.approx(0.001, rel=1e-9) and float(words[5]) == pytest.approx(0.5, rel=1e-9)


@pytest.mark.slow
def test_c_host_instantiates_with_every_form_of_a_local_file_uri(host, default_run, tmp_path):
    """RFC 8089's forms of a local folder's URI (file:/p, file:///p, file://localhost/p) and paths with
    spaces and non-ASCII characters, raw or percent-encoded, all reach the FMU's resources; another
    host's URI is refused with a message (builder/loader/fmu_loader.c, local_file_uri)."""
    folder = tmp_path / "pantograph"
    with zipfile.ZipFile(default_run / "fmus" / "pantograph.fmu") as z:
        z.extractall(folder)
    md = read_model_description(str(default_run / "fmus" / "pantograph.fmu"))
    odd = tmp_path / "a folder with spaces" / "r\u00e9sum\u00e9 \u00fc"
    odd.mkdir(parents=True)
    (odd / "resources").symlink_to(folder / "resources", target_is_directory=True)
    res = f"{folder}/resources"
    encoded = urllib.parse.quote(f"{odd}/resources")
    forms = [f"file:{res}", f"file://{res}", f"file://localhost{res}", f"FILE://LOCALHOST{res}",
             f"file://{odd}/resources", f"file://{encoded}", Path(f"{odd}/resources").as_uri()]
    lines = [f"fmu {folder} {md.coSimulation.modelIdentifier} {md.guid}" for _ in forms]
    lines += [f"uri {i} {uri}" for i, uri in enumerate(forms)]
    plan = tmp_path / "plan.txt"
    plan.write_text("\n".join(lines) + "\n", encoding="utf-8")
    _run_host(host, plan)  # every instance made and initialised: exit 0
    plan.write_text(f"fmu {folder} {md.coSimulation.modelIdentifier} {md.guid}\nuri 0 file://elsewhere{res}\n")
    env = {k: v for k, v in os.environ.items() if k not in PYTHON_VARIABLES}
    proc = subprocess.run([str(host), str(plan)], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 3 and "a file URI of another host" in proc.stdout + proc.stderr
