"""What an FMU carries in resources/: the model package, the module that binds the FMU's script to its own
copy of it, and the case data (parameter values, the rig file, the rig's response, the catenary's files)."""
from __future__ import annotations

import importlib
import json
import shutil
from pathlib import Path

from pantohil.fmus import fmu_support, variables
from pantohil.models.case import Case
from pantohil.models.catenary.interface import catenary_model
from pantohil.models.rig.compensation import write_response_csv
from pantohil.models.rig.rig_file import rig_to_toml

FMUS_DIR = Path(fmu_support.__file__).parent
MODELS_DIR = Path(importlib.import_module("pantohil.models").__file__).parent
SUPPORT_MODULES = ("__init__.py", "fmu_support.py", "variables.py", "fmu_state.py", "fast_accessors.py",
                   "state_codec.py", "udp_protocol.py", "link_client.py")
BINDING = "own_package.py"  # beside the FMU's script in resources/: binds it to the FMU's own copy of the package


def stage_fmu_files(name: str, params: dict, case: Case, stage: Path) -> list[Path]:
    """Write the project files an FMU carries in resources/: the model package, the module that binds the FMU's
    script to it (fmus/own_package.py) and the case data."""
    pkg = stage / "pantohil"
    shutil.copytree(MODELS_DIR, pkg / "models", ignore=shutil.ignore_patterns("__pycache__", "*.toml"))
    (pkg / "fmus").mkdir()
    for f in SUPPORT_MODULES:
        shutil.copy2(FMUS_DIR / f, pkg / "fmus" / f)
    shutil.copy2(FMUS_DIR / BINDING, stage / BINDING)
    return [pkg, stage / BINDING, *stage_case_data(name, params, case, stage)]


def stage_case_data(name: str, params: dict, case: Case, stage: Path, link: bool = False) -> list[Path]:
    """Write the case data an FMU reads from resources/ into `stage`: its parameter values, the rig file,
    the rig's response and what the catenary model stages (models/catenary/interface.py). The in-process
    engine initialises the same FMU classes from such a folder; `link`: large files as symbolic links."""
    files = []
    (stage / variables.PARAMETERS_FILE).write_text(json.dumps(params, indent=1, sort_keys=True))
    files.append(stage / variables.PARAMETERS_FILE)
    (stage / variables.REQUIREMENTS_FILE).write_text("\n".join(variables.REQUIREMENTS) + "\n")
    files.append(stage / variables.REQUIREMENTS_FILE)
    if name == "rig" and case.rig_spec is not None:
        (stage / "rig.toml").write_text(rig_to_toml(case.rig_spec, f"rig of case {case.name}"))
        files.append(stage / "rig.toml")
    if name == "catenary":
        if case.compensates_rig_response:
            files.append(write_response_csv(stage, *case.rig_response()))
        files += catenary_model(case).stage(case, stage, link)
    return files
