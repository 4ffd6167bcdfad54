"""A co-simulation master from a package outside pantohil, installed with pip and found through the
entry-point group `pantohil.masters` (orchestrator/masters.py) with nothing in pantohil edited: it steps
the FMUs with fmpy's own FMU2Slave in its own Jacobi loop, and a virtual HIL through it equals the fmpy
master's to the bit; `--master` offers it, and what it cannot do (lockstep rig runs, checkpoints) is
refused by its declared capabilities."""
from __future__ import annotations

import json

from conftest import install_package, pantohil

PYPROJECT = """\
[build-system]
requires = ["setuptools"]
build-backend = "setuptools.build_meta"

[project]
name = "pantohil-plain-jacobi"
version = "0.1"

[project.entry-points."pantohil.masters"]
plain_jacobi = "plain_jacobi:KIND"

[tool.setuptools]
py-modules = ["plain_jacobi"]
"""

MODULE = '''\
"""A Jacobi master written on fmpy's FMU2Slave: every FMU gets the outputs of the step before."""
import shutil
import tempfile

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from pantohil.orchestrator.master import RecordingMaster
from pantohil.orchestrator.masters import MasterKind

SETTERS = {"Real": "setReal", "Integer": "setInteger", "Boolean": "setBoolean", "String": "setString"}


class PlainJacobi(RecordingMaster):
    def __init__(self, fmus, connections, parameters, dt, capacity):
        self.dt, self.names = dt, list(fmus)
        self.dirs, self.slaves, descriptions, self.vr = [], {}, {}, {}
        for n, path in fmus.items():
            md = read_model_description(str(path))
            d = extract(str(path), unzipdir=tempfile.mkdtemp())
            self.dirs.append(d)
            s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName=n)
            s.instantiate()
            s.setupExperiment(startTime=0.0)
            refs = {v.name: v for v in md.modelVariables}
            for name, value in parameters.get(n, {}).items():
                v = refs[name]
                getattr(s, SETTERS[v.type])([v.valueReference], [value])
            s.enterInitializationMode()
            s.exitInitializationMode()
            descriptions[n], self.slaves[n], self.vr[n] = md, s, refs
        self._init_records(descriptions, connections, capacity)
        self.values = {n: self._reals(n) for n in self.names}

    def _reals(self, n):
        return self.slaves[n].getReal([self.vr[n][o].valueReference for o in self.real_outputs[n]])

    def step(self):
        row, previous = self.k % self.capacity, self.values
        for n in self.names:
            s = self.slaves[n]
            if n in self.input_names:
                u = [previous[src][j] for src, j in self._in_map[n]]
                s.setReal([self.vr[n][i].valueReference for i in self.input_names[n]], u)
                self.record_in[n][row] = u
        for n in self.names:
            self.slaves[n].doStep(currentCommunicationPoint=self.k * self.dt, communicationStepSize=self.dt)
        new = {}
        for n in self.names:
            new[n] = self._reals(n)
            self.record[n][row] = new[n]
            if self.int_outputs[n]:
                self.record_int[n][row] = self.slaves[n].getInteger(
                    [self.vr[n][o].valueReference for o in self.int_outputs[n]])
        self.values, self.k = new, self.k + 1

    def close(self):
        for s in self.slaves.values():
            s.terminate()
            s.freeInstance()
        for d in self.dirs:
            shutil.rmtree(d, ignore_errors=True)


KIND = MasterKind(PlainJacobi)
'''

SHORT = ["--set", "run.max_spans=3", "--set", "run.duration_s=2.5", "--quiet"]


def test_a_master_from_another_package_runs_the_virtual_hil_as_the_fmpy_master(tmp_path):
    env = install_package(tmp_path, PYPROJECT, "plain_jacobi", MODULE)
    assert "plain_jacobi" in pantohil("run", "--help", env=env).stdout
    runs = {}
    for master in ("plain_jacobi", "fmpy"):
        out = tmp_path / master
        proc = pantohil("run", "--master", master, "--out", str(out), *SHORT, env=env, timeout=1800)
        assert proc.returncode == 0, proc.stderr
        runs[master] = (json.loads((out / "summary.json").read_text()), (out / "steady_span.csv").read_bytes())
    (plugin, plugin_span), (fmpy, fmpy_span) = runs["plain_jacobi"], runs["fmpy"]
    assert plugin["master"] == "plain_jacobi" and plugin["spans"] == fmpy["spans"] == 3
    assert plugin_span == fmpy_span  # the same FMUs in the same Jacobi order: the same doubles
    # it declares no lockstep rig runs: refused before anything is written
    out = tmp_path / "lockstep"
    proc = pantohil("run", "--master", "plain_jacobi", "--hardware", "127.0.0.1:9", "--out", str(out), "--quiet",
                    env=env)
    assert proc.returncode == 2 and "not plain_jacobi" in proc.stderr and not out.exists()
