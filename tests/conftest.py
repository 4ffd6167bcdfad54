"""Shared fixtures: a run of the default case (made once per session) and helpers."""
from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
REFERENCE_DIR = Path(__file__).resolve().parent / "reference"
CASES_DIR = ROOT / "models" / "data" / "cases"
CATENARIES_DIR = ROOT / "models" / "data" / "catenaries"
# runs over the rig link wait up to 1 s for each answer: far above any scheduling stall of a loaded machine,
# so that every answer is used (a lockstep run is then deterministic) and a lost one means a fault of the link
PATIENT_LINK = "link.receive_timeout_s=1.0"


def pantohil(*args: str, cwd: Path | None = None, timeout: float = 600,
             env: dict | None = None) -> subprocess.CompletedProcess:
    """Run the installed CLI as a user would (in `env`, e.g. one that sees a plugin package)."""
    return subprocess.run([sys.executable, "-m", "pantohil.orchestrator.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=timeout, env=env)


def install_package(tmp_path: Path, pyproject: str, module: str, text: str) -> dict:
    """A package of one module (`module`.py holding `text`) outside pantohil, pip-installed into a folder of
    its own; the environment in which Python sees it."""
    src, site = tmp_path / "src", tmp_path / "site"
    src.mkdir()
    (src / "pyproject.toml").write_text(pyproject)
    (src / f"{module}.py").write_text(text)
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(site), str(src)],
                   check=True, capture_output=True, timeout=600)
    return dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(site), os.environ.get("PYTHONPATH")])))


def package_lines_matching(pattern, outside: Path) -> list[str]:
    """Every line of the package's modules (models, fmus, builder, orchestrator) that `pattern` (a compiled
    regular expression) finds, as "path:line: text", but in the module `outside` (relative to the root)."""
    found = []
    for layer in ("models", "fmus", "builder", "orchestrator"):
        for path in sorted((ROOT / layer).rglob("*.py")):
            if path.relative_to(ROOT) == outside:
                continue
            for no, line in enumerate(path.read_text().splitlines(), 1):
                if pattern.search(line):
                    found.append(f"{path.relative_to(ROOT)}:{no}: {line.strip()}")
    return found


def plain_install(venv: Path) -> Path:
    """A new virtual environment at `venv` with a plain (not editable) `pip install --no-deps` of this tree;
    its Python. The dependencies are lent by the environment running the tests (its site-packages
    folders, named in a .pth file, whose own .pth files are not run: an editable install of pantohil there
    stays out), whether that is the machine's Python or a virtual environment of its own."""
    import site
    import sysconfig

    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    python = venv / "bin" / "python"
    purelib = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                             capture_output=True, text=True, check=True).stdout.strip()
    lent = [*site.getsitepackages(), sysconfig.get_path("purelib"), sysconfig.get_path("platlib")]
    if site.ENABLE_USER_SITE:
        lent.append(site.getusersitepackages())
    lent = [p for p in dict.fromkeys(lent) if Path(p).is_dir() and Path(p) != Path(purelib)]
    (Path(purelib) / "_pantohil_test_dependencies.pth").write_text("\n".join(lent) + "\n")
    proc = subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", str(ROOT)],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return python


def run_main(argv: list[str]) -> tuple[int, str]:
    """The CLI's main in this process (faster than a child for many refusals): its exit code and stderr."""
    import io

    from pantohil.orchestrator.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse leaves through exit
            code = exc.code
    return code, err.getvalue()


def default_sigint() -> None:
    """`preexec_fn` of a child the test will Ctrl-C: SIGINT's default disposition, as a terminal gives it, also
    when the suite itself runs with SIGINT ignored (a background job of a shell without job control)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def load_run(folder: Path) -> tuple[dict, np.ndarray]:
    """A HIL run folder's summary and its converged span (t_s, z0_m, z_m, f_N)."""
    from pantohil.orchestrator.run_folder import STEADY_SPAN, read_summary, read_table

    return read_summary(folder), read_table(folder, STEADY_SPAN)


def pair_rate(result, window: int = 20) -> float:
    """A pair loop's rate per span over its last `window` spans: the decay of the larger of the two points'
    changes (the pair converges when both do: orchestrator/run_stepping.py)."""
    change = np.max([[h["change"] for h in history] for history in result.history], axis=0)
    return float((change[-1] / change[-1 - window]) ** (1 / window))


def closed_form_error_25hz(case, force: np.ndarray) -> float:
    """RMS difference of a converged span from the rig-free closed form (Paper A eqs. 38-41), both low-passed
    at 25 Hz (Paper B sec. 5.1), over the closed form's std."""
    from pantohil.models.catenary.asm.closed_form import one_sided_harmonics, single_pantograph
    from pantohil.models.metrics import lowpass_periodic

    ss = single_pantograph(case.catenary, case.pantograph, case.speed_m_s, case.span_m,
                           one_sided_harmonics(case.z0_samples()), case.pantograph.uplift_force_N, case.n_harmonics)
    ref = ss.force_series(case.samples_per_span)
    f25, r25 = lowpass_periodic(force, case.dt_s, 25.0), lowpass_periodic(ref, case.dt_s, 25.0)
    return float(np.sqrt(np.mean(((f25 - f25.mean()) - (r25 - r25.mean())) ** 2)) / np.std(r25))


@contextlib.contextmanager
def _machine_share(item):
    """A test marked `realtime` runs with the machine to itself: the suite runs on several workers
    (`-n 2`), and a rig-paced run whose master shares the cores with another test's long run falls behind
    the rig's clock (its forces are then held out and the run ends link_lost), which says nothing of the
    link. Every other test holds a shared lock while it runs (its fixtures' set-up and tear-down
    included), a realtime test the exclusive one; a turnstile held by a waiting realtime test stops new
    shared holders, so that it is not starved. Waiting is on the locks (events), never on a time."""
    shared = _shared_temp(item.session.config._tmp_path_factory)
    if shared is None:  # one process: nothing runs beside the test
        yield
        return
    base = shared / "machine-share"
    exclusive = item.get_closest_marker("realtime") is not None
    with open(f"{base}.turnstile", "a") as gate, open(f"{base}.lock", "a") as lock:
        fcntl.flock(gate, fcntl.LOCK_EX)
        if not exclusive:
            fcntl.flock(gate, fcntl.LOCK_UN)
        fcntl.flock(lock, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        if exclusive:
            fcntl.flock(gate, fcntl.LOCK_UN)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def pytest_collection_modifyitems(items):
    """The realtime tests first, then the slow ones, then the rest, each group in its order. The workers run
    the realtime tests one after the other at the start, each waiting on the other's realtime test only,
    not on a long test that holds the machine; the long tests then start early, so that the suite does not
    end with one worker on a long test and the other idle."""
    items.sort(key=lambda item: (item.get_closest_marker("realtime") is None, item.get_closest_marker("slow") is None))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Each test under the machine share (`_machine_share`)."""
    with _machine_share(item):
        yield


def _shared_temp(tmp_path_factory) -> Path | None:
    """The folder the workers of this test session share (the parent of each worker's basetemp), or None
    when the session runs in one process."""
    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        return None
    return tmp_path_factory.getbasetemp().parent


@pytest.fixture(scope="session", autouse=True)
def isolated_cache(tmp_path_factory):
    """Build FMUs and operators into a cache of the test session's own, so tests also exercise a cold cache.
    The workers share it, as two pantohil processes of a user share theirs (every entry is written
    atomically), so that no operator is built twice in one session."""
    shared = _shared_temp(tmp_path_factory)
    cache = shared / "cache" if shared is not None else tmp_path_factory.mktemp("cache")
    cache.mkdir(exist_ok=True)
    os.environ["PANTOHIL_CACHE"] = str(cache)


def once_per_session(tmp_path_factory, name: str, make) -> Path:
    """The folder `name` that `make(folder)` fills once in the whole test session; tests only read it. The
    workers share it: the first to ask makes it under a lock, the others wait on the lock (an event) and
    read it. A `make` that fails leaves nothing marked done, so the next test to ask makes it again."""
    base = (_shared_temp(tmp_path_factory) or tmp_path_factory.getbasetemp()) / "once"
    base.mkdir(exist_ok=True)
    folder, done = base / name, base / f"{name}.done"
    with open(base / f"{name}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            make(folder)
            done.touch()
    return folder


def cli_into(*args: str, timeout: float = 600):
    """A `make` for once_per_session: `pantohil *args` with "{out}" in them replaced by the folder, which must
    succeed; its stdout is kept in the folder's stdout.txt."""
    def make(folder: Path) -> None:
        proc = pantohil(*[a.replace("{out}", str(folder)) for a in args], timeout=timeout)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        (folder / "stdout.txt").write_text(proc.stdout)
    return make


@pytest.fixture(scope="session")
def default_fmus(tmp_path_factory) -> Path:
    """The folder of the default case's four FMUs (`pantohil build`), built once; tests only read them."""
    return once_per_session(tmp_path_factory, "default_fmus", cli_into("build", "--out", "{out}/fmus")) / "fmus"


@pytest.fixture(scope="session")
def default_run(tmp_path_factory) -> Path:
    """The run folder of the default case (`pantohil run`), run once; tests only read it."""
    return once_per_session(tmp_path_factory, "default_run", cli_into("run", "--out", "{out}/default", "--quiet")) \
        / "default"


@pytest.fixture(scope="session")
def plain_installed(tmp_path_factory) -> Path:
    """The Python of a fresh venv holding a plain (not editable) install of this tree (plain_install), made once."""
    return once_per_session(tmp_path_factory, "install", lambda folder: plain_install(folder / "venv")) \
        / "venv" / "bin" / "python"
