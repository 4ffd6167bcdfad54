"""Package the FMUs of a case with pythonfmu, decorate their model descriptions, cache them.

A built FMU is cached (builder/fmu_cache.py) under a key hashed from everything it depends on, so a
repeated run reuses it.
"""
from __future__ import annotations

import contextlib
import importlib
import io
import shutil
import tempfile
import zipfile
from pathlib import Path

import pythonfmu

from pantohil.models.case import Case

from . import loader
from .fmu_archive import loader_members, rewrite_zip
from .fmu_cache import cache_entry, cache_key, entry_is_whole, store
from .fmu_documentation import documentation_page
from .fmu_parameters import default_delay_steps, fmu_parameters
from .model_description import decorate_model_description
from .staging import FMUS_DIR, stage_case_data, stage_fmu_files
from .system import FMU_NAMES

__all__ = ["CLASS_NAMES", "build_case_fmus", "build_fmu", "default_delay_steps", "default_experiment",
           "fmu_parameters", "stage_case_data"]

SCRIPTS = {name: FMUS_DIR / f"pantohil_{name}.py" for name in (*FMU_NAMES, "adapter")}
CLASS_NAMES = {"catenary": "PantohilCatenary", "rig": "PantohilRig", "pantograph": "PantohilPantograph",
               "adapter": "PantohilAdapter"}


def _variables(name: str):
    module = importlib.import_module(f"pantohil.fmus.pantohil_{name}")
    return module.VARIABLES


DEFAULT_EXPERIMENT_STEPS = 500  # the FMU Compliance Checker's default run: stopTime / 500 per step


def default_experiment(case: Case) -> tuple[float, float]:
    """(step, stop time) of an FMU run alone: 500 of the case's steps, so that a tool that divides the stop
    time into a number of steps takes the FMU's fixed step (the FMU Compliance Checker, 500 by default), and
    one that caps their number (fmpy's simulate_fmu, at 1000) needs not double it. A HIL run's length is the
    master's (run.max_spans)."""
    return case.dt_s, DEFAULT_EXPERIMENT_STEPS * case.dt_s


def build_fmu(name: str, params: dict, case: Case, dest_dir: Path) -> tuple[Path, bool]:
    """Build (or fetch from the cache) one FMU and copy it to dest_dir. Returns (path, cached)."""
    experiment = default_experiment(case)
    runtime = loader.python_runtime()
    with tempfile.TemporaryDirectory(prefix=f"pantohil_{name}_") as tmp:
        stage = Path(tmp) / "stage"
        stage.mkdir()
        files = stage_fmu_files(name, params, case, stage)
        key = cache_key(name, SCRIPTS[name], files, experiment, runtime)
        cached = cache_entry(key, CLASS_NAMES[name])
        hit = entry_is_whole(cached)
        if not hit:
            variables = _variables(name)
            doc = Path(tmp) / "doc"
            doc.mkdir()
            module = importlib.import_module(f"pantohil.fmus.pantohil_{name}")
            description = getattr(module, CLASS_NAMES[name]).description
            method = " ".join((module.__doc__ or "").split())
            (doc / "index.html").write_text(documentation_page(name, variables, description, method))
            out = Path(tmp) / "out"
            with contextlib.redirect_stdout(io.StringIO()):
                fmu = pythonfmu.FmuBuilder.build_FMU(SCRIPTS[name], dest=out, project_files=files,
                                                     documentation_folder=doc)
            with zipfile.ZipFile(fmu) as z:
                xml = z.read("modelDescription.xml")
            rewrite_zip(fmu, {"modelDescription.xml": decorate_model_description(xml, variables, experiment, key),
                              **loader_members(fmu, xml, runtime, Path(tmp))})
            store(fmu, cached)
    dest_dir.mkdir(parents=True, exist_ok=True)
    target = dest_dir / f"{name}.fmu"
    shutil.copy2(cached, target)
    return target, hit


def build_case_fmus(case: Case, dest_dir: Path, delay_steps: int | None = None, names=FMU_NAMES,
                    rig_address: tuple[str, int] = ("127.0.0.1", 47800)) -> dict[str, Path]:
    """The FMUs of a case in dest_dir, with the case's values as their start values."""
    d = default_delay_steps(case) if delay_steps is None else delay_steps
    params = fmu_parameters(case, d, rig_address)
    return {name: build_fmu(name, params[name], case, Path(dest_dir))[0] for name in names}
