"""Model exchange: the same run under libcosim, from an SSP file, from the OSP system
structure, and from a partner package in a fresh virtual environment with no repository on the path."""
import os
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from fmpy.ssp.ssd import read_ssd

from conftest import load_run, pantohil
from pantohil.orchestrator.mcap_follow import read_log


@pytest.fixture(scope="module")
def ssp(tmp_path_factory):
    path = tmp_path_factory.mktemp("ssp") / "asm_250.ssp"
    proc = pantohil("build", "--ssp", str(path))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return path


@pytest.mark.slow
def test_ssp_has_the_fmus_connections_and_parameters(ssp):
    ssd = read_ssd(str(ssp))  # validates against the SSP 1.0 schema
    system = ssd.system
    assert {e.name for e in system.elements} == {"catenary", "rig", "pantograph"}
    assert {(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in system.connections} == {
        ("catenary", "height_command", "rig", "height_command"), ("rig", "actuator_height", "pantograph", "height"),
        ("pantograph", "contact_force", "rig", "true_force"), ("rig", "measured_force", "catenary", "contact_force")}
    names = {p.name for b in system.parameterBindings for s in b.parameterValues for p in s.parameters}
    assert {"catenary.delay_steps", "pantograph.uplift_force_N", "rig.delay_steps"} <= names
    with zipfile.ZipFile(ssp) as z:
        assert {"resources/catenary.fmu", "resources/rig.fmu", "resources/pantograph.fmu",
                "resources/case.toml"} <= set(z.namelist())
    assert (ssp.parent / "asm_250_osp" / "OspSystemStructure.xml").exists()


@pytest.mark.slow
def test_running_the_ssp_equals_running_the_case(ssp, default_run, tmp_path):
    out = tmp_path / "from_ssp"
    proc = pantohil("run", str(ssp), "--out", str(out), "--quiet")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    _, a = load_run(default_run)
    _, b = load_run(out)
    assert np.max(np.abs(a[:, 3] - b[:, 3])) <= 1e-6


@pytest.mark.slow
def test_libcosim_master_equals_the_fmpy_master(default_run, tmp_path):
    out = tmp_path / "libcosim"
    proc = pantohil("run", "--master", "libcosim", "--out", str(out), "--quiet")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary, b = load_run(out)
    ref, a = load_run(default_run)
    assert summary["master"] == "libcosim" and summary["spans"] == ref["spans"]
    assert np.max(np.abs(a[:, 3] - b[:, 3])) <= 1e-6


@pytest.mark.slow
def test_osp_system_structure_runs_in_libcosim(ssp, default_run):
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver

    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel.WARNING)
    ex = CosimExecution.from_osp_config_file(str(ssp.parent / "asm_250_osp"))
    obs = CosimObserver.create_last_value()
    ex.add_observer(obs)
    index = ex.slave_index_from_instance_name("catenary")
    vr = next(v.reference for v in ex.slave_variables(index) if v.name.decode() == "contact_force")
    got = []
    for _ in range(1500):
        assert ex.step()
        got.append(obs.last_real_values(index, [vr])[0])
    want = [m["contact_force"] for _, _, m in read_log(default_run / "run.mcap", ("/catenary",))][:1500]
    assert np.max(np.abs(np.array(got) - np.array(want))) <= 1e-6


@pytest.mark.slow
def test_partner_package_runs_by_its_own_readme_in_a_fresh_venv(tmp_path):
    pkg = tmp_path / "pkg"
    proc = pantohil("package", "--out", str(pkg), "--zip", "--quiet")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    empty = tmp_path / "partner"
    empty.mkdir()
    with zipfile.ZipFile(tmp_path / "pkg.zip") as z:
        z.extractall(empty)
    folder = empty / "pkg"
    readme = (folder / "README.md").read_text()
    block = readme.split("## Run it in fmpy", 1)[1].split("```bash", 1)[1].split("```", 1)[0].strip()
    env = {"PATH": os.path.dirname(sys.executable) + ":/usr/bin:/bin", "HOME": os.environ.get("HOME", "/root")}
    run = subprocess.run(["bash", "-c", block], cwd=folder, env=env, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert "OK" in run.stdout
    # the venv holds only the declared requirements: no pantohil, no repository on the path
    python = str(folder / ".venv/bin/python")
    check = subprocess.run([python, "-c", "import pantohil"], cwd=folder, env=env, capture_output=True, text=True)
    assert check.returncode != 0
    # each FMU file alone, in a fresh process, from an otherwise empty folder
    for fmu in sorted((folder / "fmus").glob("*.fmu")):
        alone = tmp_path / f"alone_{fmu.stem}"
        alone.mkdir()
        (alone / fmu.name).write_bytes(fmu.read_bytes())
        code = ("from fmpy import simulate_fmu; import numpy as np; "
                f"r = simulate_fmu('{fmu.name}', stop_time=0.05, step_size=0.001, output_interval=0.001); "
                "print(len(r), all(np.isfinite(r[n]).all() for n in r.dtype.names))")
        out = subprocess.run([python, "-c", code], cwd=alone, env=env, capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr[-2000:]
        assert out.stdout.split()[-1] == "True"


def test_bad_ssp_gives_one_line(tmp_path):
    bad = tmp_path / "bad.ssp"
    bad.write_bytes(b"not a zip")
    proc = pantohil("run", str(bad), "--out", str(tmp_path / "x"))
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_ssp_carries_omsimulators_annotation_and_parameter_units(tmp_path):
    import xml.etree.ElementTree as ET

    from pantohil.builder.ssp import OMS, SSC, SSV

    path = tmp_path / "hil.ssp"
    proc = pantohil("build", "--ssp", str(path))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "SSP of 3 FMUs (catenary, rig, pantograph)" in proc.stdout
    with zipfile.ZipFile(path) as z:
        ssd = ET.fromstring(z.read("SystemStructure.ssd"))
        ssv = ET.fromstring(z.read("resources/parameters.ssv"))
    master = ssd.find(f".//{{{OMS}}}SimulationInformation/{{{OMS}}}FixedStepMaster")
    assert master is not None and master.get("description") == "oms-ma" and float(master.get("stepSize")) == 0.001
    values = {p.get("name"): p[0] for p in ssv.iter(f"{{{SSV}}}Parameter")}
    assert values["catenary.speed"].get("unit") == "m/s" and values["pantograph.uplift_force_N"].get("unit") == "N"
    delay = values["catenary.delay_steps"]
    assert delay.tag == f"{{{SSV}}}Integer" and delay.get("unit") is None
    used = {v.get("unit") for v in values.values() if v.get("unit")}
    assert used == {u.get("name") for u in ssv.iter(f"{{{SSC}}}Unit")}
