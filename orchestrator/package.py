"""`pantohil package`: a folder for a partner lab with the FMUs, the SSP and OSP system files, a
standalone fmpy runner, the host requirements and the case's reference results."""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

from pantohil.builder import build_fmus
from pantohil.builder.fmu_parameters import fmu_parameters
from pantohil.builder.model_description import pantohil_version
from pantohil.builder.ssp import write_ssp
from pantohil.builder.system import system_components
from pantohil.models.case import Case, CaseError

from .hil_run import run_case
from .run_topology import delay_plan
from .output_paths import check_output_folder

TEMPLATES = Path(build_fmus.__file__).parent / "partner"


def case_text(case: Case) -> str:
    """The case file as written, the text an SSP file carries."""
    return Path(case.source).read_text()


def make_ssp(case: Case, fmus: dict[str, Path], path: Path, overrides: list[str]) -> Path:
    """Write the SSP 1.0 file of a case's system (FMUs, connections, start values, the case text) to `path`."""
    d = delay_plan(case)["delay_steps"]
    params = fmu_parameters(case, d)
    text = case_text(case)
    if overrides:  # an SSP carries the case as run, overrides included
        text += "\n# overrides given on the command line:\n" + "".join(f"# --set {o}\n" for o in overrides)
    n = case.samples_per_span
    pair = case.sections.second_pantograph is not None
    components, connections = system_components(fmus, pair)
    loop = "catenary -> rig -> pantograph -> rig -> catenary" + (", catenary -> pantograph_2 -> catenary" if pair
                                                                 else "")
    return write_ssp(path, case.name, components, {c: params[c] for c in components}, text,
                     case.sections.run.max_spans * n * case.dt_s, case.dt_s,
                     f"pantohil HIL system of case {case.name}: {loop}", connections)


def make_package(case: Case, out_dir: Path, overrides: list[str], progress: bool = True) -> Path:
    """Write a partner package for a case into `out_dir`, all or nothing.

    A reference run of the case, its FMUs, SSP and OSP files, a standalone fmpy runner, requirements and
    a README with the case's numbers; built in a staging folder and renamed into place.
    """
    if case.sections.profile.source == "csv":
        raise CaseError("profile.source: a package cannot yet carry a CSV profile; use a dropper profile")
    out_dir = check_output_folder(out_dir, "--out")  # new or empty; not a file, not under one
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))  # same filesystem: atomic rename
    try:
        ref = run_case(case, stage / "_run", progress=progress)
        if ref.status == "interrupted":  # the staging folder goes, nothing is written
            raise KeyboardInterrupt
        if not ref.converged:
            raise CaseError(f"case {case.name}: the reference run did not converge ({ref.message})")
        (stage / "reference").mkdir()
        for name in ("summary.json", "steady_span.csv", "contact_force.png", "convergence.png"):
            shutil.copy2(stage / "_run" / name, stage / "reference" / name)
        fmus = {}
        (stage / "fmus").mkdir()
        for p in ref.fmus:
            fmus[Path(p).stem] = Path(shutil.copy2(p, stage / "fmus" / Path(p).name))
        make_ssp(case, fmus, stage / f"{case.name}.ssp", overrides)
        steps = ref.spans * ref.samples_per_span
        (stage / "system.json").write_text(json.dumps({
            "ssp": f"{case.name}.ssp", "dt_s": ref.dt_s, "steps": steps,
            "samples_per_span": ref.samples_per_span, "tolerance_N": 1e-6}, indent=1) + "\n")
        shutil.copy2(TEMPLATES / "run_fmpy.py", stage / "run_fmpy.py")
        shutil.copy2(TEMPLATES / "requirements.txt", stage / "requirements.txt")
        readme = (TEMPLATES / "README.md").read_text()
        for key, value in {"CASE_NAME": case.name, "VERSION": pantohil_version(), "STEPS": str(steps),
                           "DT": repr(ref.dt_s), "DELAY": str(ref.hil["delay_steps"])}.items():
            readme = readme.replace(key, value)
        (stage / "README.md").write_text(readme)
        shutil.rmtree(stage / "_run")
        if out_dir.exists():
            out_dir.rmdir()
        os.replace(stage, out_dir)  # all or nothing
    finally:
        if stage.exists():
            shutil.rmtree(stage, ignore_errors=True)
    return out_dir
