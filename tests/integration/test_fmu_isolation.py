"""Each FMU imports only its own resources, whatever else the process has loaded (fmus/own_package.py): fmpy's
simulate_fmu of the four FMUs one after the other in a process that imported pantohil, each running the
modules of its own extracted folder and leaving the host's pantohil as it was; two pantograph FMUs built by
two versions of pantohil, stepped alternately in one process, each giving its own version's forces; an FMU
whose Python class cannot be created says what failed."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description

from conftest import ROOT, pantohil
from pantohil.builder.build_fmus import DEFAULT_EXPERIMENT_STEPS
from pantohil.builder.system import FMU_NAMES

ALL_FMUS = (*FMU_NAMES, "adapter")
MODEL_CLASSES = {"catenary": "PeriodicHil", "rig": "Rig", "pantograph": "ChainPantograph", "adapter": "LinkClient"}

# Runs the FMUs given one after the other with fmpy's simulate_fmu, after `import pantohil`. At the first step
# of each it finds the live slave and prints, as JSON, the module file of each pantohil class it uses (the
# slave's classes, its attributes' and theirs: the globals their functions run in); after all, whether the
# host's pantohil modules and sys.path are as they were.
SIMULATE_IN_TURN = r"""
import gc, json, os, sys, types
import pantohil
from fmpy import read_model_description, simulate_fmu

def own(name):
    return name == "pantohil" or name.startswith(("pantohil.", "pantohil_"))

def host_modules():
    return {name: module for name, module in sys.modules.items() if own(name)}

def module_files(cls):  # the files of the modules whose namespaces the class's functions run in
    found = set()
    for member in vars(cls).values():
        member = getattr(member, "fget", None) or getattr(member, "__func__", None) or member
        if isinstance(member, types.FunctionType) and member.__globals__.get("__name__") == cls.__module__:
            found.add(member.__globals__["__file__"])
    return found

def classes_used(slave):
    classes = {cls for cls in type(slave).__mro__ if own(cls.__module__)}
    for value in vars(slave).values():
        for obj in (value, *getattr(value, "__dict__", {}).values()):
            if own(type(obj).__module__):
                classes.add(type(obj))
    return classes

def report(identifier):
    slave = next(o for o in gc.get_objects() if type(o).__name__ == identifier and hasattr(o, "resources"))
    files = {f"{cls.__module__}.{cls.__qualname__}": sorted(module_files(cls)) for cls in classes_used(slave)}
    return {"folder": os.path.realpath(slave.resources), "files": files}

def simulate(path):
    identifier = read_model_description(path).coSimulation.modelIdentifier
    seen = []
    def first_step(time, recorder):
        if not seen:
            seen.append(report(identifier))
        return True
    result = simulate_fmu(path, step_finished=first_step)
    return {"fmu": path, "steps": len(result) - 1, **seen[0]}

before, path_before = host_modules(), list(sys.path)
for path in sys.argv[1:]:
    print(json.dumps(simulate(path)), flush=True)
after = host_modules()
print(json.dumps({"host_unchanged": after.keys() == before.keys() and all(after[n] is before[n] for n in before),
                  "sys_path_unchanged": sys.path == path_before}), flush=True)
"""

# Steps pantograph FMUs alternately in one process (after importing the host's own pantograph model) from the
# same heights, printing their contact forces after each step.
STEP_IN_TURN = r"""
import math, sys
import pantohil.models.pantograph.lumped
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

slaves = []
for i, path in enumerate(sys.argv[1:]):
    md = read_model_description(path)
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName=f"pantograph{i}")
    vr = {v.name: v.valueReference for v in md.modelVariables}
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    height = slave.getReal([vr["reference_height"]])[0]
    slave.setReal([vr["height"]], [height])
    slave.exitInitializationMode()
    slaves.append((slave, vr, height))
dt = float(md.defaultExperiment.stepSize)
for k in range(200):
    forces = []
    for slave, vr, height in slaves:
        slave.setReal([vr["height"]], [height + 0.01 * math.sin(2 * math.pi * k / 50)])
        slave.doStep(k * dt, dt)
        forces.append(slave.getReal([vr["contact_force"]])[0])
    print(*(repr(f) for f in forces), flush=True)
"""

VERSION_2_OFFSET_N = 1000.0
# Appended to the second version's models/pantograph/lumped.py: its chain pantograph presses 1000 N harder
VERSION_2_CHANGE = f"""

_step_of_version_1 = ChainPantograph.step
ChainPantograph.step = lambda self, z_next: _step_of_version_1(self, z_next) + {VERSION_2_OFFSET_N!r}
"""


@pytest.fixture(scope="module")
def project_fmus(default_fmus) -> Path:
    """The default case's four FMUs, built by this pantohil."""
    return default_fmus


def _second_version(tmp_path: Path) -> Path:
    """A copy of this pantohil, laid out as the installed package, whose chain pantograph presses
    VERSION_2_OFFSET_N harder: the folder to put in front of PYTHONPATH."""
    site = tmp_path / "version2"
    package = site / "pantohil"
    ignore = shutil.ignore_patterns("__pycache__")
    for layer in ("models", "fmus", "builder", "orchestrator"):
        shutil.copytree(ROOT / layer, package / layer, ignore=ignore)
    shutil.copy2(ROOT / "orchestrator" / "public_api" / "__init__.py", package / "__init__.py")
    with open(package / "models" / "pantograph" / "lumped.py", "a") as f:
        f.write(VERSION_2_CHANGE)
    return site


def _forces(*fmus: Path) -> list[list[float]]:
    proc = subprocess.run([sys.executable, "-c", STEP_IN_TURN, *map(str, fmus)], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return [[float(word) for word in line.split()] for line in proc.stdout.splitlines()]


@pytest.mark.slow
def test_the_four_fmus_run_in_turn_in_one_process_each_on_its_own_modules(project_fmus):
    fmus = [project_fmus / f"{name}.fmu" for name in ALL_FMUS]
    proc = subprocess.run([sys.executable, "-c", SIMULATE_IN_TURN, *map(str, fmus)], capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    lines = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    assert len(lines) == len(ALL_FMUS) + 1, proc.stdout + proc.stderr
    for name, run in zip(ALL_FMUS, lines, strict=False):
        assert run["steps"] == DEFAULT_EXPERIMENT_STEPS, run  # the FMU's DefaultExperiment, which fmpy takes
        classes = {key.rpartition(".")[2] for key, files in run["files"].items() if files}
        assert {"PantohilSlave", MODEL_CLASSES[name]} <= classes, (name, sorted(classes))
        outside = {cls: files for cls, files in run["files"].items()
                   if any(not f.startswith(run["folder"] + os.sep) for f in files)}
        assert not outside, f"{name}: classes not from the FMU's own folder {run['folder']}: {outside}"
    assert lines[-1] == {"host_unchanged": True, "sys_path_unchanged": True}


@pytest.mark.slow
def test_two_versions_of_an_fmu_run_side_by_side_each_its_own(project_fmus, tmp_path):
    site = _second_version(tmp_path)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(site), os.environ.get("PYTHONPATH")])))
    proc = pantohil("build", "--out", str(tmp_path / "fmus2"), env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    version_1, version_2 = project_fmus / "pantograph.fmu", tmp_path / "fmus2" / "pantograph.fmu"
    with zipfile.ZipFile(version_2) as z:
        assert VERSION_2_CHANGE.encode() in z.read("resources/pantohil/models/pantograph/lumped.py")
    together = _forces(version_1, version_2)
    alone_1, alone_2 = _forces(version_1), _forces(version_2)
    assert len(together) == 200
    assert [row[0] for row in together] == [row[0] for row in alone_1]  # to the bit
    assert [row[1] for row in together] == [row[0] for row in alone_2]
    assert all(abs(f2 - f1 - VERSION_2_OFFSET_N) < 1e-6 for f1, f2 in together)


def test_an_fmu_whose_class_cannot_be_created_says_what_failed(project_fmus, tmp_path):
    """A module missing from the FMU's resources is named, and numpy and scipy are not blamed."""
    folder = tmp_path / "rig"
    with zipfile.ZipFile(project_fmus / "rig.fmu") as z:
        z.extractall(folder)
    (folder / "resources" / "pantohil" / "models" / "rig" / "chain.py").unlink()
    md = read_model_description(str(project_fmus / "rig.fmu"))
    script = ("import sys\nfrom fmpy.fmi2 import FMU2Slave\n"
              "slave = FMU2Slave(guid=sys.argv[2], unzipDirectory=sys.argv[1], modelIdentifier=sys.argv[3], "
              "instanceName='rig')\n"
              "try:\n    slave.instantiate()\nexcept Exception as exc:\n    print('raised', exc, flush=True)\n")
    proc = subprocess.run([sys.executable, "-c", script, str(folder), md.guid, md.coSimulation.modelIdentifier],
                          capture_output=True, text=True, timeout=600)
    assert "raised Failed to instantiate model" in proc.stdout, proc.stdout + proc.stderr
    lines = [line for line in proc.stdout.splitlines() if "could not be created" in line]
    assert len(lines) == 1 and "No module named 'pantohil.models.rig.chain'" in lines[0], proc.stdout
    assert "numpy" not in lines[0]
