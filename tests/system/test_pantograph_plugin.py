"""A pantograph model from a package outside pantohil, installed with pip, found through the entry-point
group `pantohil.pantographs` (models/pantograph/interface.py) with nothing in pantohil edited: a virtual
HIL with it runs through the FMU path (fmpy master) and the in-process path with the same result to the
bit, and equals an independent run of the same physics with pantohil's own chain; so does its stability
map."""
from __future__ import annotations

import csv
import json

from conftest import install_package, pantohil

PYPROJECT = """\
[build-system]
requires = ["setuptools"]
build-backend = "setuptools.build_meta"

[project]
name = "pantohil-stiff-head"
version = "0.1"

[project.entry-points."pantohil.pantographs"]
stiff_head = "stiff_head:StiffHead"

[tool.setuptools]
py-modules = ["stiff_head"]
"""

MODULE = '''\
"""A pantograph whose contact spring is twice the case's: the chain of pantohil with 2 k_c."""
import dataclasses

from pantohil.models.pantograph.linear import chain_linear
from pantohil.models.pantograph.lumped import ChainPantograph, chain_receptance


def _stiff(params):
    return dataclasses.replace(params, contact_stiffness_N_m=2.0 * params.contact_stiffness_N_m)


class StiffHead:
    fixed_to_actuator = False

    def build(self, params, dt_s, reference_height_m):
        return ChainPantograph(_stiff(params), dt_s, reference_height_m)

    def receptance(self, params, omega_rad_s):
        return chain_receptance(_stiff(params), omega_rad_s)

    def linear(self, params, dt_s):
        return chain_linear(_stiff(params), dt_s)
'''

SHORT = ["--set", "run.max_spans=3", "--set", "run.duration_s=2.5", "--quiet"]


def _run(env, out, *args):
    proc = pantohil("run", "--out", str(out), *args, *SHORT, env=env, timeout=1800)
    assert proc.returncode == 0, proc.stderr
    return json.loads((out / "summary.json").read_text()), (out / "steady_span.csv").read_bytes()


def test_a_pantograph_model_from_another_package_runs_on_both_paths_to_the_bit(tmp_path):
    env = install_package(tmp_path, PYPROJECT, "stiff_head", MODULE)
    fmu = _run(env, tmp_path / "fmu", "--set", "pantograph.model=stiff_head")
    inprocess = _run(env, tmp_path / "inprocess", "--set", "pantograph.model=stiff_head", "--engine", "inprocess")
    chain = _run(env, tmp_path / "chain", "--set", "pantograph.contact_stiffness_N_m=100000", "--engine", "inprocess")
    assert fmu[0]["pantograph"]["model"] == "stiff_head"
    assert fmu[0]["convergence"] == inprocess[0]["convergence"] and fmu[1] == inprocess[1]
    assert inprocess[0]["convergence"] == chain[0]["convergence"] and inprocess[1] == chain[1]


def test_an_unregistered_model_is_one_line_naming_the_key(tmp_path):
    proc = pantohil("run", "--out", str(tmp_path / "x"), "--set", "pantograph.model=stiff_head", "--quiet")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "pantograph.model" in lines[0], proc.stderr
    assert not (tmp_path / "x").exists()


def _spectral_radius(env, out, *args):
    proc = pantohil("stability", "--update", "step", "--fmax", "25", "--delay", "8", "--relaxation", "0.1",
                    "--workers", "1", "--out", str(out), "--quiet", *args, env=env, timeout=1800)
    assert proc.returncode == 0, proc.stderr
    with open(out / "stability.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 1
    return float(rows[0]["spectral_radius"])


def test_the_stability_map_of_a_plugin_model_is_its_physics(tmp_path):
    """`pantohil stability` on the plugin at k_c equals pantohil's chain at 2 k_c (the same linear map)."""
    env = install_package(tmp_path, PYPROJECT, "stiff_head", MODULE)
    plugin = _spectral_radius(env, tmp_path / "plugin", "--contact-stiffness", "5e4", "--set",
                              "pantograph.model=stiff_head")
    chain = _spectral_radius(env, tmp_path / "chain", "--contact-stiffness", "1e5")
    assert plugin == chain and plugin > 0
