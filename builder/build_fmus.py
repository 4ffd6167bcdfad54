"""Package the three FMUs of a case with pythonfmu, decorate their model descriptions, cache them.

A built FMU is cached under a key hashed from everything it depends on (its script, the model
sources, the case parameters and data files, the pythonfmu version), so a repeated run reuses it.
"""
from __future__ import annotations

import contextlib
import hashlib
import html
import importlib
import io
import json
import shutil
import sys
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pythonfmu

from pantohil.fmus import fmu_support
from pantohil.models.case import Case
from pantohil.models.catenary.interface import catenary_model
from pantohil.models.parameters import fmu_values
from pantohil.models.rig.compensation import write_response_csv
from pantohil.models.rig.rig_file import rig_to_toml
from pantohil.models.input_files import InputFileError, read_input_bytes
from pantohil.models.storage import atomic_path, cache_folder, cache_root, write_text_atomic

from . import loader
from .system import FMU_NAMES, loop_latency_steps

BUILDER_VERSION = "15"
MAX_FMU_BYTES = 256 * 1024 * 1024  # a cache entry read to check its digest (a built FMU is about 4 MB)
FMUS_DIR = Path(fmu_support.__file__).parent
MODELS_DIR = Path(importlib.import_module("pantohil.models").__file__).parent
SCRIPTS = {name: FMUS_DIR / f"pantohil_{name}.py" for name in (*FMU_NAMES, "adapter")}
CLASS_NAMES = {"catenary": "PantohilCatenary", "rig": "PantohilRig", "pantograph": "PantohilPantograph",
               "adapter": "PantohilAdapter"}
SUPPORT_MODULES = ("__init__.py", "fmu_support.py", "state_codec.py", "udp_protocol.py", "link_client.py")
BINDING = "own_package.py"  # beside the FMU's script in resources/: binds it to the FMU's own copy of the package


def fmu_parameters(case: Case, delay_steps: int,
                   rig_address: tuple[str, int] = ("127.0.0.1", 47800)) -> dict[str, dict]:
    """The case as FMU parameter values, by FMU: every case key that reaches an FMU under its declared
    name (models/parameters.py), and the quantities the FMUs take derived from the case."""
    pan = case.pantograph
    resolved = {"hil.delay_steps": delay_steps, "pantograph.uplift_force_N": pan.uplift_force_N,
                "pantograph.masses_kg": pan.masses_kg, "pantograph.stiffnesses_N_m": pan.stiffnesses_N_m,
                "pantograph.dampings_Ns_m": pan.dampings_Ns_m}
    derived = {
        "catenary": {"speed": case.speed_m_s, "time_step": case.dt_s, "samples_per_span": case.samples_per_span,
                     "rig_compensation": int(case.compensates_rig_response), "horizon_steps": case.horizon_steps},
        "pantograph": {"n_masses": pan.n, "reference_height": case.reference_height_m(), "time_step": case.dt_s},
        "rig": {"time_step": case.dt_s, "rig_chain": int(case.rig_spec is not None)},
        "adapter": {"rig_host": rig_address[0], "rig_port": rig_address[1], "time_step": case.dt_s,
                    "local_host": case.sections.link.local_host, "key_file": case.sections.link.key_file,
                    "horizon_steps": case.horizon_steps},
    }
    return {name: {**fmu_values(name, case.values, resolved), **extra} for name, extra in derived.items()}


def default_delay_steps(case: Case) -> int:
    """D for the standard topology: its loop latency plus the rig's (Paper D sec. 3.4)."""
    return case.delay_steps(loop_latency_steps())


def _stage(name: str, params: dict, case: Case, stage: Path) -> list[Path]:
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
    (stage / fmu_support.PARAMETERS_FILE).write_text(json.dumps(params, indent=1, sort_keys=True))
    files.append(stage / fmu_support.PARAMETERS_FILE)
    (stage / fmu_support.REQUIREMENTS_FILE).write_text("\n".join(fmu_support.REQUIREMENTS) + "\n")
    files.append(stage / fmu_support.REQUIREMENTS_FILE)
    if name == "rig" and case.rig_spec is not None:
        (stage / "rig.toml").write_text(rig_to_toml(case.rig_spec, f"rig of case {case.name}"))
        files.append(stage / "rig.toml")
    if name == "catenary":
        if case.compensates_rig_response:
            files.append(write_response_csv(stage, *case.rig_response()))
        files += catenary_model(case).stage(case, stage, link)
    return files


def _digest(name: str, files: list[Path], experiment: tuple[float, float], runtime: loader.PythonRuntime) -> str:
    h = hashlib.sha256()
    h.update(f"{BUILDER_VERSION} {pythonfmu.__version__} {name} {experiment!r} {runtime.key()}".encode())
    h.update(SCRIPTS[name].read_bytes())
    h.update(loader.SOURCE.read_bytes())
    for root in files:
        paths = sorted(p for p in ([root] if root.is_file() else root.rglob("*")) if p.is_file())
        for p in paths:
            h.update(p.name.encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:20]


def _variables(name: str):
    module = importlib.import_module(f"pantohil.fmus.pantohil_{name}")
    return module.VARIABLES


# What the loader library and the state hooks make true of every pantohil FMU
CAPABILITIES = {"canHandleVariableCommunicationStepSize": "false", "canGetAndSetFMUstate": "true",
                "canSerializeFMUstate": "true"}


def _declare_behaviour(root: ET.Element, experiment: tuple[float, float]) -> None:
    """Capabilities, DefaultExperiment and ModelStructure as they are. Outputs: computed in doStep from
    the inputs of the step before (dependencies=""), and computed during initialisation (the pantograph
    settles on its input height, the catenary commands its first height), hence initial="calculated",
    listed in InitialUnknowns (depending on everything set before: no dependencies attribute)."""
    for key, value in CAPABILITIES.items():
        root.find("CoSimulation").set(key, value)
    step_s, stop_s = experiment
    for old in root.findall("DefaultExperiment"):
        root.remove(old)
    root.insert(list(root).index(root.find("ModelVariables")), ET.Element(
        "DefaultExperiment", {"startTime": "0.0", "stopTime": repr(float(stop_s)), "stepSize": repr(float(step_s))}))
    for sv in root.iter("ScalarVariable"):
        if sv.get("causality") == "output":
            sv.set("initial", "calculated")
            sv[0].attrib.pop("start", None)
    structure = root.find("ModelStructure")
    outputs = structure.find("Outputs")
    for unknown in outputs.iter("Unknown"):
        unknown.set("dependencies", "")
    for old in structure.findall("InitialUnknowns"):
        structure.remove(old)
    initial = ET.SubElement(structure, "InitialUnknowns")
    for unknown in outputs.iter("Unknown"):
        ET.SubElement(initial, "Unknown", {"index": unknown.get("index")})


def decorate_model_description(xml_bytes: bytes, variables, experiment: tuple[float, float], identity: str) -> bytes:
    """Add unit and display-unit definitions, units, ranges and the generation tool to pythonfmu's
    modelDescription.xml; state the fixed step, the default experiment (step, stop time), the state
    capabilities and the output dependencies (FMI 2.0 sec. 2.2.8: no output depends directly on an
    input: every output is computed in doStep or read from the state it leaves). The GUID is derived
    from `identity` (the digest of the build's inputs) and the build time is left out, so that the same
    inputs give the same FMU, byte for byte."""
    root = ET.fromstring(xml_bytes)
    root.set("generationTool", f"pantohil {_version()} with {root.get('generationTool')}")
    root.set("guid", str(uuid.uuid5(uuid.NAMESPACE_URL, f"pantohil-fmu:{identity}")))
    root.attrib.pop("generationDateAndTime", None)
    _declare_behaviour(root, experiment)
    by_name = {v.name: v for v in variables}
    used = sorted({v.unit for v in variables if v.kind == "real"})
    units = ET.Element("UnitDefinitions")
    for u in used:
        unit = ET.SubElement(units, "Unit", name=u)
        ET.SubElement(unit, "BaseUnit", {k: str(e) for k, e in fmu_support.UNITS[u].items()})
        if u in fmu_support.DISPLAY_UNITS:
            name, factor = fmu_support.DISPLAY_UNITS[u]
            ET.SubElement(unit, "DisplayUnit", {"name": name, "factor": repr(factor)})
    cosim = root.find("CoSimulation")
    root.insert(list(root).index(cosim) + 1, units)
    for sv in root.iter("ScalarVariable"):
        var = by_name[sv.get("name")]
        typ = sv[0]
        if typ.tag in ("Real", "Integer"):
            if typ.tag == "Real":
                typ.set("unit", var.unit)
            if var.min is not None:
                typ.set("min", repr(var.min) if typ.tag == "Real" else str(int(var.min)))
            if var.max is not None:
                typ.set("max", repr(var.max) if typ.tag == "Real" else str(int(var.max)))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("pantohil")
    except PackageNotFoundError:
        return "unknown"


LIMITS = ("The periodic method gives the steady state of a pantograph running along an endless line of equal "
          "spans: no overlaps, section ends, local irregularities or curves. The HIL iteration converges only "
          "where it is stable: keep the highest harmonic below the pantograph's contact frequency, or the loop "
          "delay short (Gil et al., Paper D sec. 4).")


def _documentation(name: str, variables, description: str, method: str) -> str:
    rows = "".join(f"<tr><td>{html.escape(v.name)}</td><td>{v.causality}</td><td>{html.escape(v.unit)}</td>"
                   f"<td>{html.escape(v.description)}</td></tr>" for v in variables)
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>pantohil {name}</title></head><body>"
            f"<h1>pantohil {name} FMU</h1><p>{html.escape(description)}</p>"
            f"<h2>Method</h2><p>{html.escape(method)}</p><h2>Limits</h2><p>{html.escape(LIMITS)}</p>"
            "<h2>Running it</h2><p>FMI 2.0 co-simulation, built with pythonfmu: the host needs Python 3.11 with "
            "numpy and scipy (resources/requirements.txt). Case data are the start values, also in "
            "resources/parameters.json. Connect catenary.height_command to rig.height_command, "
            "rig.actuator_height to pantograph.height, pantograph.contact_force to rig.true_force and "
            "rig.measured_force to catenary.contact_force; set catenary.delay_steps to the loop latency of "
            "the master plus rig.latency_steps.</p><h2>Variables</h2>"
            f"<table border='1'><tr><th>variable</th><th>causality</th><th>unit</th><th>description</th></tr>{rows}"
            "</table></body></html>")


ZIP_TIME = (1980, 1, 1, 0, 0, 0)  # every member's time: the zip's bytes depend on its contents only


def _rewrite_zip(path: Path, replace: dict[str, bytes]) -> None:
    """The FMU with members replaced or added, written reproducibly: members in name order, one fixed
    time, each keeping its permission bits."""
    members, modes = {}, {}
    with zipfile.ZipFile(path) as src:
        for item in src.infolist():
            members[item.filename], modes[item.filename] = src.read(item.filename), item.external_attr
    members.update(replace)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as dst:
        for name in sorted(members):
            info = zipfile.ZipInfo(name, ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = modes.get(name, 0o644 << 16)
            info.create_system = 3  # Unix: the permission bits are in external_attr
            dst.writestr(info, members[name])
    path.write_bytes(buf.getvalue())


SIMULATE_FMU_MAX_STEPS = 1000  # fmpy's simulate_fmu doubles its step until the run has at most this many


def default_experiment(case: Case) -> tuple[float, float]:
    """(step, stop time) of an FMU run alone: the case's step, for one span but at most 1000 steps, so that
    a tool that caps the number of steps (fmpy's simulate_fmu) still takes the FMU's fixed step. A HIL
    run's length is the master's (run.max_spans)."""
    return case.dt_s, min(case.samples_per_span, SIMULATE_FMU_MAX_STEPS) * case.dt_s


def _add_loader(fmu: Path, xml: bytes, runtime: loader.PythonRuntime, tmp: Path) -> dict[str, bytes]:
    """The zip entries that put the loader library in front of pythonfmu's (see builder/loader.py)."""
    root = ET.fromstring(xml)
    identifier = root.find("CoSimulation").get("modelIdentifier")
    vr = next(int(sv.get("valueReference")) for sv in root.iter("ScalarVariable") if sv.get("name") == "time_step")
    binary = f"binaries/{loader.PLATFORM}/{identifier}.so"
    with zipfile.ZipFile(fmu) as z:
        inner = z.read(binary)
    built = loader.compile_loader(identifier, vr, runtime, tmp / "loader" / f"{identifier}.so")
    return {binary: built.read_bytes(), f"binaries/{loader.PLATFORM}/{identifier}{loader.INNER_SUFFIX}.so": inner}


def _digest_path(cached: Path) -> Path:
    return cached.with_name(cached.name + ".sha256")


def _sha256(path: Path) -> str:
    return hashlib.sha256(read_input_bytes(path, "FMU cache entry", MAX_FMU_BYTES)).hexdigest()


def _entry_is_whole(cached: Path) -> bool:
    """Whether an FMU cache entry is there and whole: its bytes hash to the digest stored beside it when it was
    made. A damaged entry (truncated, a bit flipped, no digest) is reported in one line and rebuilt."""
    if not cached.exists() and not cached.is_symlink():
        return False
    try:
        whole = _digest_path(cached).read_text().strip() == _sha256(cached)
    except (OSError, UnicodeDecodeError, InputFileError):
        whole = False
    if not whole:
        print(f"pantohil: the FMU cache entry {cached} does not match its digest (damaged or incomplete): "
              "rebuilding it", file=sys.stderr, flush=True)
    return whole


def build_fmu(name: str, params: dict, case: Case, dest_dir: Path) -> tuple[Path, bool]:
    """Build (or fetch from the cache) one FMU and copy it to dest_dir. Returns (path, cached)."""
    experiment = default_experiment(case)
    runtime = loader.python_runtime()
    with tempfile.TemporaryDirectory(prefix=f"pantohil_{name}_") as tmp:
        stage = Path(tmp) / "stage"
        stage.mkdir()
        files = _stage(name, params, case, stage)
        key = _digest(name, files, experiment, runtime)
        cached = cache_root() / "fmus" / key / f"{CLASS_NAMES[name]}.fmu"
        hit = _entry_is_whole(cached)
        if not hit:
            variables = _variables(name)
            doc = Path(tmp) / "doc"
            doc.mkdir()
            module = importlib.import_module(f"pantohil.fmus.pantohil_{name}")
            description = getattr(module, CLASS_NAMES[name]).description
            method = " ".join((module.__doc__ or "").split())
            (doc / "index.html").write_text(_documentation(name, variables, description, method))
            out = Path(tmp) / "out"
            with contextlib.redirect_stdout(io.StringIO()):
                fmu = pythonfmu.FmuBuilder.build_FMU(SCRIPTS[name], dest=out, project_files=files,
                                                     documentation_folder=doc)
            with zipfile.ZipFile(fmu) as z:
                xml = z.read("modelDescription.xml")
            _rewrite_zip(fmu, {"modelDescription.xml": decorate_model_description(xml, variables, experiment, key),
                               **_add_loader(fmu, xml, runtime, Path(tmp))})
            cache_folder(cached.parent)
            with atomic_path(cached) as part:  # no half-written cache entry
                shutil.copy2(fmu, part)
            write_text_atomic(_digest_path(cached), _sha256(cached) + "\n")  # after the FMU: a check at use
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
