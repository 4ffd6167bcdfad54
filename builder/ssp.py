"""System files for exchange: an SSP 1.0 package (SystemStructure.ssd + FMUs + parameter values in an
.ssv + the case file) and an OspSystemStructure.xml for libcosim, both of a case's topology (builder/system.py:
one pantograph, or two as two instances of the pantograph FMU)."""
from __future__ import annotations

import math
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from fmpy import read_model_description

from pantohil.fmus.variables import UNITS
from pantohil.models.case import CaseError, apply_overrides, build_case, load_case_dict
from pantohil.models.errors import InputError
from pantohil.models.input_files import InputFileError, open_regular
from pantohil.models.parameters import fmu_keys, fmu_variable_names
from pantohil.models.storage import atomic_path

from .system import CONNECTIONS

SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
OSP = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
OMS = "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"
CASE_RESOURCE = "resources/case.toml"
PARAMETERS_RESOURCE = "resources/parameters.ssv"
FMU_TYPE = "application/x-fmu-sharedlibrary"
# An SSP of pantohil holds 3 FMUs of about 4 MB, an .ssd, an .ssv and the case: far below these bounds,
# which are checked from the archive's directory before anything is extracted.
MAX_SSP_MEMBERS = 64
MAX_SSP_MEMBER_BYTES = 256 * 1024 * 1024
MAX_SSP_BYTES = 512 * 1024 * 1024

ET.register_namespace("ssc", SSC)
ET.register_namespace("ssd", SSD)
ET.register_namespace("ssv", SSV)
ET.register_namespace("oms", OMS)


def _q(ns: str, tag: str) -> str:
    return f"{{{ns}}}{tag}"


def _variables(fmu: Path):
    return [
        v for v in read_model_description(str(fmu)).modelVariables if v.causality in ("parameter", "input", "output")
    ]


def _fmt(kind: str, value) -> str:
    if kind == "Real":
        return repr(float(value))
    if kind == "Boolean":
        return "true" if value else "false"
    return str(int(value))


def _oms_annotation(parent: ET.Element, **simulation_information) -> ET.Element:
    """OMSimulator's annotation (org.openmodelica): its standalone program loads an SSP only with
    oms:SimulationInformation/oms:FixedStepMaster on the system."""
    annotations = ET.SubElement(parent, _q(SSD, "Annotations"))
    annotation = ET.SubElement(annotations, _q(SSC, "Annotation"), {"type": "org.openmodelica"})
    info = ET.SubElement(ET.SubElement(annotation, _q(OMS, "Annotations")), _q(OMS, "SimulationInformation"),
                         simulation_information)
    return info


def _parameter_set(name: str, fmus: dict[str, Path], parameters: dict[str, dict]) -> ET.Element:
    """parameters.ssv: every parameter value, Real ones with their unit (defined in ssv:Units)."""
    pset = ET.Element(_q(SSV, "ParameterSet"), {"version": "1.0", "name": name})
    params = ET.SubElement(pset, _q(SSV, "Parameters"))
    units = set()
    for comp, path in fmus.items():
        by_name = {v.name: v for v in _variables(path)}
        for var, value in parameters.get(comp, {}).items():
            v = by_name[var]
            p = ET.SubElement(params, _q(SSV, "Parameter"), {"name": f"{comp}.{var}"})
            attrs = {"value": _fmt(v.type, value)}
            if v.type == "Real" and v.unit:
                attrs["unit"] = v.unit
                units.add(v.unit)
            ET.SubElement(p, _q(SSV, v.type), attrs)
    _units(ET.SubElement(pset, _q(SSV, "Units")), units)
    return pset


def _units(parent: ET.Element, units: set[str]) -> None:
    for u in sorted(units):
        unit = ET.SubElement(parent, _q(SSC, "Unit"), {"name": u})
        ET.SubElement(unit, _q(SSC, "BaseUnit"), {k: str(e) for k, e in UNITS[u].items()})


def system_structure(name: str, fmus: dict[str, Path], parameters: dict[str, dict], stop_time_s: float,
                     description: str, dt: float, connections=CONNECTIONS) -> tuple[bytes, bytes]:
    """SystemStructure.ssd and parameters.ssv (bytes): the components (`fmus`: component -> FMU file; two
    components may instantiate one FMU) and their connections."""
    root = ET.Element(_q(SSD, "SystemStructureDescription"), {"version": "1.0", "name": name,
                                                              "generationTool": "pantohil"})
    system = ET.SubElement(root, _q(SSD, "System"), {"name": "hil", "description": description})
    bindings = ET.SubElement(system, _q(SSD, "ParameterBindings"))
    ET.SubElement(bindings, _q(SSD, "ParameterBinding"), {"source": PARAMETERS_RESOURCE})
    elements = ET.SubElement(system, _q(SSD, "Elements"))
    units = set()
    for comp, path in fmus.items():
        c = ET.SubElement(elements, _q(SSD, "Component"), {"name": comp, "type": FMU_TYPE,
                                                           "source": f"resources/{path.name}"})
        conns = ET.SubElement(c, _q(SSD, "Connectors"))
        for v in _variables(path):
            con = ET.SubElement(conns, _q(SSD, "Connector"), {"name": v.name, "kind": v.causality})
            attrs = {"unit": v.unit} if v.type == "Real" and v.unit else {}
            units.update(attrs.values())
            ET.SubElement(con, _q(SSC, v.type), attrs)
    wires = ET.SubElement(system, _q(SSD, "Connections"))
    for src, out, dst, inp in connections:
        ET.SubElement(wires, _q(SSD, "Connection"), {"startElement": src, "startConnector": out,
                                                          "endElement": dst, "endConnector": inp})
    _oms_annotation(system).append(ET.Element(_q(OMS, "FixedStepMaster"), {  # Jacobi, as pantohil's masters
        "description": "oms-ma", "stepSize": repr(float(dt)), "absoluteTolerance": "0.0001",
        "relativeTolerance": "0.0001"}))
    _units(ET.SubElement(root, _q(SSD, "Units")), units)
    experiment = ET.SubElement(root, _q(SSD, "DefaultExperiment"), {"startTime": "0.0",
                                                                     "stopTime": repr(float(stop_time_s))})
    # bufferSize and signalFilter: without them OMSimulator looks up an empty resource node (a logged error)
    # and its Python API crashes at exit
    _oms_annotation(experiment, resultFile=f"{name}_res.csv", loggingInterval=repr(float(dt)), bufferSize="1",
                    signalFilter=".*")
    ET.indent(root)
    pset = _parameter_set(name, fmus, parameters)
    ET.indent(pset)
    def decl(el):
        return ET.tostring(el, encoding="UTF-8", xml_declaration=True)
    return decl(root), decl(pset)


def osp_system_structure(fmus: dict[str, Path], parameters: dict[str, dict], dt: float, fmu_dir: str = "",
                         connections=CONNECTIONS) -> bytes:
    """OspSystemStructure.xml: the same system for libcosim (Simulators, InitialValues, Connections)."""
    ET.register_namespace("", OSP)
    root = ET.Element(_q(OSP, "OspSystemStructure"), {"version": "0.1"})
    ET.SubElement(root, _q(OSP, "StartTime")).text = "0.0"
    ET.SubElement(root, _q(OSP, "BaseStepSize")).text = repr(float(dt))
    ET.SubElement(root, _q(OSP, "Algorithm")).text = "fixedStep"
    sims = ET.SubElement(root, _q(OSP, "Simulators"))
    for comp, path in fmus.items():
        sim = ET.SubElement(sims, _q(OSP, "Simulator"), {"name": comp, "source": f"{fmu_dir}{path.name}",
                                                         "stepSize": repr(float(dt))})
        values = parameters.get(comp, {})
        if values:
            kinds = {v.name: v.type for v in _variables(path)}
            init = ET.SubElement(sim, _q(OSP, "InitialValues"))
            for var, value in values.items():
                iv = ET.SubElement(init, _q(OSP, "InitialValue"), {"variable": var})
                ET.SubElement(iv, _q(OSP, kinds[var]), {"value": _fmt(kinds[var], value)})
    conns = ET.SubElement(root, _q(OSP, "Connections"))
    for src, out, dst, inp in connections:
        vc = ET.SubElement(conns, _q(OSP, "VariableConnection"))
        ET.SubElement(vc, _q(OSP, "Variable"), {"simulator": src, "name": out})
        ET.SubElement(vc, _q(OSP, "Variable"), {"simulator": dst, "name": inp})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def write_ssp(path: Path, name: str, fmus: dict[str, Path], parameters: dict[str, dict], case_text: str,
              stop_time_s: float, dt: float, description: str, connections=CONNECTIONS) -> Path:
    """Write FILE.ssp atomically, and OspSystemStructure.xml with the FMUs in a folder next to it; each FMU file
    once, whatever the number of components that instantiate it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ssd, ssv = system_structure(name, fmus, parameters, stop_time_s, description, dt, connections)
    files = {Path(fmu).name: fmu for fmu in fmus.values()}
    with atomic_path(path) as part, zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", ssd)
        z.writestr(PARAMETERS_RESOURCE, ssv)
        z.writestr(CASE_RESOURCE, case_text)
        for file_name, fmu in files.items():
            z.write(fmu, f"resources/{file_name}")
    osp_dir = path.parent / f"{path.stem}_osp"
    osp_dir.mkdir(exist_ok=True)
    for file_name, fmu in files.items():
        shutil.copy2(fmu, osp_dir / file_name)
    (osp_dir / "OspSystemStructure.xml").write_bytes(osp_system_structure(fmus, parameters, dt,
                                                                          connections=connections))
    return path


class SspError(InputError):
    """An SSP file that cannot be run; one line."""


def _check_archive(z: zipfile.ZipFile, ssp: Path) -> None:
    """Refuse, before anything is extracted, an archive whose members are too many or too large (by their
    uncompressed sizes, which the extraction cannot exceed), or whose names leave the folder."""
    members = z.infolist()
    if len(members) > MAX_SSP_MEMBERS:
        raise SspError(f"{ssp}: {len(members)} members, above the limit of {MAX_SSP_MEMBERS}")
    total = 0
    for m in members:
        name = m.filename
        parts = Path(name).parts
        if name.startswith(("/", "\\")) or ".." in parts or "\0" in name or ":" in (parts[0] if parts else ""):
            raise SspError(f"{ssp}: member {name!r} leaves the archive's folder")
        if (m.external_attr >> 16) & 0o170000 == 0o120000:
            raise SspError(f"{ssp}: member {name!r} is a symbolic link")
        if m.file_size > MAX_SSP_MEMBER_BYTES:
            raise SspError(f"{ssp}: member {name!r} unpacks to {m.file_size} bytes, above the limit of "
                           f"{MAX_SSP_MEMBER_BYTES} bytes")
        total += m.file_size
    if total > MAX_SSP_BYTES:
        raise SspError(f"{ssp}: its members unpack to {total} bytes, above the limit of {MAX_SSP_BYTES} bytes")


def _unpack(path: Path, into: Path):
    """The SSD of an SSP file, its members extracted into `into` after the archive was checked."""
    from fmpy.ssp.ssd import read_ssd

    try:
        fd = open_regular(path, "SSP file")
    except InputFileError as exc:
        raise SspError(str(exc)) from None
    try:
        with os.fdopen(fd, "rb") as fh, zipfile.ZipFile(fh) as z:
            _check_archive(z, path)
            ssd = read_ssd(str(path))
            z.extractall(into)
    except SspError:
        raise
    except (zipfile.BadZipFile, KeyError, OSError, EOFError) as exc:
        raise SspError(f"{path}: not a readable SSP file ({exc})") from None
    except Exception as exc:  # schema validation errors of fmpy
        raise SspError(f"{path}: invalid SystemStructure.ssd ({str(exc).splitlines()[0]})") from None
    return ssd


def _parameter_value(ssp: Path, p):
    """An SSV parameter value as its type says, finite."""
    try:
        if p.type == "Real":
            value = float(p.value)
        elif p.type == "Boolean":
            value = p.value in (True, "true")
        else:
            value = int(p.value)
    except (TypeError, ValueError):
        raise SspError(f"{ssp}: parameter {p.name}: {p.value!r} is not a {p.type} value") from None
    if isinstance(value, float) and not math.isfinite(value):
        raise SspError(f"{ssp}: parameter {p.name}: must be a finite number (got {p.value!r})")
    return value


def read_ssp(path: Path, into: Path) -> dict:
    """Unpack an SSP written by write_ssp: FMUs, connections, parameter values and the case text."""
    path = Path(path)
    ssd = _unpack(path, Path(into))
    case_file = Path(into) / CASE_RESOURCE
    if not case_file.is_file():
        raise SspError(f"{path}: no {CASE_RESOURCE} (not written by pantohil build --ssp)")
    system = ssd.system
    fmus = {c.name: _member_fmu(path, Path(into), c.name, c.source) for c in system.elements}
    connections = tuple((c.startElement, c.startConnector, c.endElement, c.endConnector) for c in system.connections)
    parameters: dict[str, dict] = {}
    for binding in system.parameterBindings:
        for pset in binding.parameterValues:
            for p in pset.parameters:
                if "." not in str(p.name):
                    raise SspError(f"{path}: parameter {p.name!r}: expected COMPONENT.VARIABLE")
                comp, var = p.name.split(".", 1)
                parameters.setdefault(comp, {})[var] = _parameter_value(path, p)
    return {"fmus": fmus, "connections": connections, "parameters": parameters, "case_file": case_file}


def _member_fmu(ssp: Path, into: Path, component: str, source: str) -> Path:
    """The FMU of a component: a member of the archive (a path that leaves it is refused) that is an
    FMU for this platform (a model description and a shared library of the platform's format)."""
    root = into.resolve()
    fmu = (root / source).resolve()
    if "://" in source or not fmu.is_relative_to(root) or fmu == root:
        raise SspError(f"{ssp}: component {component!r}: source {source!r} is not a member of the archive")
    if not fmu.is_file():
        raise SspError(f"{ssp}: component {component!r}: {source} is not in the archive")
    check_fmu(fmu, f"{ssp}: component {component!r}: {source}")
    return fmu


def check_fmu(fmu: Path, what: str) -> None:
    """Refuse, in one line, a file that is not an FMU 2.0 co-simulation unit runnable on this platform."""
    from fmpy import platform, sharedLibraryExtension

    try:
        md = read_model_description(str(fmu))
        if md.coSimulation is None:
            raise SspError(f"{what}: not a co-simulation FMU")
        binary = f"binaries/{platform}/{md.coSimulation.modelIdentifier}{sharedLibraryExtension}"
        with zipfile.ZipFile(fmu) as z, z.open(binary) as lib:
            magic = lib.read(4)
    except SspError:
        raise
    except KeyError:
        raise SspError(f"{what}: no binary for {platform} in the FMU") from None
    except Exception as exc:  # a bad zip, a bad or invalid modelDescription.xml
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SspError(f"{what}: not a readable FMU ({detail})") from None
    if sharedLibraryExtension == ".so" and magic != b"\x7fELF":
        raise SspError(f"{what}: its binary {binary} is not a shared library")


def temporary_dir(prefix: str) -> Path:
    """A new temporary folder whose name starts with `prefix`."""
    return Path(tempfile.mkdtemp(prefix=prefix))


def _same(a, b) -> bool:
    """Equal values, reals to 1e-9 relative (an SSP written by another build of the same case)."""
    if isinstance(a, float) or isinstance(b, float):
        return isinstance(a, (int, float)) and isinstance(b, (int, float)) and math.isclose(a, b, rel_tol=1e-9,
                                                                                           abs_tol=1e-12)
    return a == b


def _case_value(key, names: list[str], given: dict, current):
    """The case value a key's FMU variables in an SSP stand for (the naming rule of models/parameters.py)."""
    if key.param.choices and isinstance(key.param.choices[0], str):
        index = given[names[0]]
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(key.param.choices):
            raise CaseError(f"{key.dotted} (FMU variable {names[0]}): {index!r} is not the index of one of "
                            f"{key.param.choices}")
        return key.param.choices[index]
    if key.type is bool:
        return bool(given[names[0]])
    if key.param.fmu_items:
        return [given[n] for n in names[:max(1, len(current))]]  # the items past the list must stay 0 (checked)
    return given[names[0]]


def _ssp_changes(case, parameters: dict, expected: dict) -> dict:
    """{section: {key: value}} of the case keys whose FMU variables the SSP gives other values than its case."""
    changes: dict[str, dict] = {}
    for comp, given in parameters.items():
        for key in fmu_keys(comp):
            names = fmu_variable_names(key)
            if any(n in given and not _same(given[n], expected[comp].get(n)) for n in names):
                present = {n: given.get(n, expected[comp][n]) for n in names}
                value = _case_value(key, names, present, case.values[key.section][key.name])
                changes.setdefault(key.section, {})[key.name] = value
    return changes


def _key_variables(comp: str) -> set[str]:
    return {n for key in fmu_keys(comp) for n in fmu_variable_names(key)}


def _check_matches(ssp: Path, parameters: dict, expected: dict, before: dict) -> None:
    """Every SSP parameter must be what the case it stands for gives its FMU. A derived value (dt, speed, the
    reference height...) may also be the one of the embedded case (the SSP's key values changed, not it); it
    is then recomputed from the case that runs."""
    for comp, given in parameters.items():
        if comp not in expected:
            raise SspError(f"{ssp}: parameter {comp}.*: no component {comp!r} in a pantohil system")
        keys = _key_variables(comp)
        for var, value in given.items():
            if var not in expected[comp]:
                raise SspError(f"{ssp}: parameter {comp}.{var}: not a parameter of the {comp} FMU")
            want = expected[comp][var]
            stale = var not in keys and _same(value, before[comp][var])
            if not (_same(value, want) or stale):
                raise SspError(f"{ssp}: parameter {comp}.{var} = {value!r} is not what its case gives ({want!r}): "
                               f"an SSP's parameters must form a valid case")


def ssp_case(ssp: Path, system: dict, overrides: list[str]):
    """The case an SSP runs: its embedded case with the SSP's parameter values in place of the case's, validated
    as any case (ranges, combinations), so that the run's summary reports the values that ran; the FMU
    parameters of `system` become that case's. CaseError (one line naming the SSP and the key) for a value out
    of range; SspError for a parameter that no case gives."""
    from .fmu_parameters import default_delay_steps, fmu_parameters

    parameters = system["parameters"]
    if "pantograph_2" in system["fmus"] or parameters.get("catenary", {}).get("second_pantograph"):
        raise CaseError(f"second_pantograph: pantohil run runs one pantograph; SSP file {ssp} has two (its OSP "
                        "system structure runs in libcosim, the SSP in OMSimulator)", key="second_pantograph")
    raw, source = load_case_dict(system["case_file"])
    case = build_case(apply_overrides(raw, overrides), source)
    before = fmu_parameters(case, default_delay_steps(case))
    try:
        changes = _ssp_changes(case, parameters, before)
        if changes:
            raw = {**raw, **{s: {**raw.get(s, {}), **v} for s, v in changes.items()}}
            case = build_case(apply_overrides(raw, overrides), source)
    except CaseError as exc:
        raise CaseError(f"SSP file {ssp}: parameters.ssv: {exc}") from None
    expected = fmu_parameters(case, default_delay_steps(case))
    _check_matches(ssp, parameters, expected, before)
    system["parameters"] = {comp: expected[comp] for comp in parameters}
    return case
