"""A catenary model from a package outside pantohil, installed with pip, found through the entry-point group
`pantohil.catenaries` (models/catenary/interface.py) with nothing in pantohil edited: a virtual HIL with it
runs through the FMU path (fmpy master) and the in-process path with the same result to the bit, and
equals an independent run of the same physics with pantohil's own ASM2; so does its stability map."""
from __future__ import annotations

import csv
import json

from conftest import install_package, pantohil

PYPROJECT = """\
[build-system]
requires = ["setuptools"]
build-backend = "setuptools.build_meta"

[project]
name = "pantohil-stiff-support"
version = "0.1"

[project.entry-points."pantohil.catenaries"]
stiff_support = "stiff_support:StiffSupport"

[tool.setuptools]
py-modules = ["stiff_support"]
"""

MODULE = '''\
"""A periodic catenary: the analytical string on a support twice as stiff as the case's, its static height
staged as a file of its own."""
import dataclasses
from pathlib import Path

import numpy as np

from pantohil.models.catenary.asm.string import AsmParameters, receptance_direct
from pantohil.models.catenary.profile import read_profile_csv, write_profile_csv
from pantohil.models.catenary.receptance import CirculantOperator, asm_operator, reduce_harmonics
from pantohil.models.hil.loop import PeriodicHil

FIELDS = [f.name for f in dataclasses.fields(AsmParameters)]
HEIGHTS = "static_height.csv"


def _string(values):
    given = {name: float(values[name]) for name in FIELDS}
    return AsmParameters(**{**given, "support_stiffness_N_m2": 2.0 * given["support_stiffness_N_m2"]})


class StiffSupport:
    structural_keys = ()

    def check(self, case):
        pass

    def prepare(self, case, progress):
        return None

    def stage(self, case, folder, link=False):
        write_profile_csv(Path(folder) / HEIGHTS, case.profile)
        return [Path(folder) / HEIGHTS]

    def iteration(self, grid, parameters, resources, settings, compensation):
        z0 = read_profile_csv(Path(resources) / HEIGHTS, grid.span_m).heights(grid.positions_m())
        op = asm_operator(_string(parameters), grid.speed_m_s, grid.samples_per_span, grid.dt_s, grid.n_harmonics)
        if compensation is not None:
            op = CirculantOperator(compensation.compensate_kernel(op.kernel))
        return PeriodicHil(op, reduce_harmonics(z0, grid.n_harmonics), settings, compensation), z0

    def static_compliance_m_N(self, case):
        return float(np.real(receptance_direct(_string(dataclasses.asdict(case.catenary)), 0.0, case.speed_m_s)))

    def stability_operator(self, case, n_harmonics):
        string = _string(dataclasses.asdict(case.catenary))
        return asm_operator(string, case.speed_m_s, case.samples_per_span, case.dt_s, n_harmonics).kernel, None

    def summary(self, case):
        return {"model": case.model, "span_m": case.span_m, "support": "twice the case's"}

    def dropper_positions_m(self, case):
        return []

    def reference_force(self, case):
        return None
'''

SHORT = ["--set", "run.max_spans=3", "--set", "run.duration_s=2.5", "--quiet"]
PLUGIN = ["--set", 'catenary.model="stiff_support"']
STIFFER = ["--set", "catenary.support_stiffness_N_m2=102.3"]  # twice asm_250's 51.15 (exact in binary)


def _run(env, out, *args):
    proc = pantohil("run", "--out", str(out), *args, *SHORT, env=env, timeout=1800)
    assert proc.returncode == 0, proc.stderr
    return json.loads((out / "summary.json").read_text()), (out / "steady_span.csv").read_bytes()


def test_a_catenary_model_from_another_package_runs_on_both_paths_to_the_bit(tmp_path):
    env = install_package(tmp_path, PYPROJECT, "stiff_support", MODULE)
    fmu = _run(env, tmp_path / "fmu", *PLUGIN)
    inprocess = _run(env, tmp_path / "inprocess", *PLUGIN, "--engine", "inprocess")
    string = _run(env, tmp_path / "string", *STIFFER, "--engine", "inprocess")
    assert fmu[0]["catenary"]["model"] == "stiff_support" and "reference" not in fmu[0]
    assert fmu[0]["convergence"] == inprocess[0]["convergence"] and fmu[1] == inprocess[1]
    assert inprocess[0]["convergence"] == string[0]["convergence"] and inprocess[1] == string[1]


def _spectral_radius(env, out, *args):
    proc = pantohil("stability", "--update", "step", "--fmax", "25", "--delay", "8", "--relaxation", "0.1",
                    "--workers", "1", "--out", str(out), "--quiet", *args, env=env, timeout=1800)
    assert proc.returncode == 0, proc.stderr
    with open(out / "stability.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 1
    return float(rows[0]["spectral_radius"])


def test_the_stability_map_of_a_plugin_catenary_is_its_physics(tmp_path):
    """`pantohil stability` on the plugin equals pantohil's ASM2 on the twice stiffer support."""
    env = install_package(tmp_path, PYPROJECT, "stiff_support", MODULE)
    plugin = _spectral_radius(env, tmp_path / "plugin", *PLUGIN)
    string = _spectral_radius(env, tmp_path / "string", *STIFFER)
    assert plugin == string and plugin > 0
