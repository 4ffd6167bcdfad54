"""System files for exchange: an SSP 1.0 package (SystemStructure.ssd + FMUs + parameter values in an
.ssv + the case file) and an OspSystemStructure.xml for libcosim, both of the standard topology."""
from __future__ import annotations

import shutil
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from fmpy import read_model_description

from pantohil.fmus.fmu_support import UNITS
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
                     description: str, dt: float) -> tuple[bytes, bytes]:
    """SystemStructure.ssd and parameters.ssv (bytes) for the FMUs of the standard topology."""
    root = ET.Element(_q(SSD, "SystemStructureDescription"), {"version": "1.0", "name": name,
                                                              "generationTool": "pantohil"})
    system = ET.SubElement(root, _q(SSD, "System"), {"name": "hil", "description": description})
    bindings = ET.SubElement(system, _q(SSD, "ParameterBindings"))
    ET.SubElement(bindings, _q(SSD, "ParameterBinding"), {"source": PARAMETERS_RESOURCE})
    elements = ET.SubElement(system, _q(SSD, "Elements"))
    units = set()
    for comp, path in fmus.items():
        c = ET.SubElement(elements, _q(SSD, "Component"), {"name": comp, "type": FMU_TYPE,
                                                           "source": f"resources/{comp}.fmu"})
        conns = ET.SubElement(c, _q(SSD, "Connectors"))
        for v in _variables(path):
            con = ET.SubElement(conns, _q(SSD, "Connector"), {"name": v.name, "kind": v.causality})
            attrs = {"unit": v.unit} if v.type == "Real" and v.unit else {}
            units.update(attrs.values())
            ET.SubElement(con, _q(SSC, v.type), attrs)
    connections = ET.SubElement(system, _q(SSD, "Connections"))
    for src, out, dst, inp in CONNECTIONS:
        ET.SubElement(connections, _q(SSD, "Connection"), {"startElement": src, "startConnector": out,
                                                          "endElement": dst, "endConnector": inp})
    _oms_annotation(system).append(ET.Element(_q(OMS, "FixedStepMaster"), {  # Jacobi, as pantohil's masters
        "description": "oms-ma", "stepSize": repr(float(dt)), "absoluteTolerance": "0.0001",
        "relativeTolerance": "0.0001"}))
    _units(ET.SubElement(root, _q(SSD, "Units")), units)
    experiment = ET.SubElement(root, _q(SSD, "DefaultExperiment"), {"startTime": "0.0",
                                                                     "stopTime": repr(float(stop_time_s))})
    _oms_annotation(experiment, resultFile=f"{name}_res.csv", loggingInterval=repr(float(dt)))
    ET.indent(root)
    pset = _parameter_set(name, fmus, parameters)
    ET.indent(pset)
    def decl(el):
        return ET.tostring(el, encoding="UTF-8", xml_declaration=True)
    return decl(root), decl(pset)


def osp_system_structure(fmus: dict[str, Path], parameters: dict[str, dict], dt: float, fmu_dir: str = "") -> bytes:
    """OspSystemStructure.xml: the same system for libcosim (Simulators, InitialValues, Connections)."""
    ET.register_namespace("", OSP)
    root = ET.Element(_q(OSP, "OspSystemStructure"), {"version": "0.1"})
    ET.SubElement(root, _q(OSP, "StartTime")).text = "0.0"
    ET.SubElement(root, _q(OSP, "BaseStepSize")).text = repr(float(dt))
    ET.SubElement(root, _q(OSP, "Algorithm")).text = "fixedStep"
    sims = ET.SubElement(root, _q(OSP, "Simulators"))
    for comp, path in fmus.items():
        sim = ET.SubElement(sims, _q(OSP, "Simulator"), {"name": comp, "source": f"{fmu_dir}{comp}.fmu",
                                                         "stepSize": repr(float(dt))})
        values = parameters.get(comp, {})
        if values:
            kinds = {v.name: v.type for v in _variables(path)}
            init = ET.SubElement(sim, _q(OSP, "InitialValues"))
            for var, value in values.items():
                iv = ET.SubElement(init, _q(OSP, "InitialValue"), {"variable": var})
                ET.SubElement(iv, _q(OSP, kinds[var]), {"value": _fmt(kinds[var], value)})
    conns = ET.SubElement(root, _q(OSP, "Connections"))
    for src, out, dst, inp in CONNECTIONS:
        vc = ET.SubElement(conns, _q(OSP, "VariableConnection"))
        ET.SubElement(vc, _q(OSP, "Variable"), {"simulator": src, "name": out})
        ET.SubElement(vc, _q(OSP, "Variable"), {"simulator": dst, "name": inp})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def write_ssp(path: Path, name: str, fmus: dict[str, Path], parameters: dict[str, dict], case_text: str,
              stop_time_s: float, dt: float, description: str) -> Path:
    """Write FILE.ssp atomically, and OspSystemStructure.xml with the FMUs in a folder next to it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ssd, ssv = system_structure(name, fmus, parameters, stop_time_s, description, dt)
    with atomic_path(path) as part, zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", ssd)
        z.writestr(PARAMETERS_RESOURCE, ssv)
        z.writestr(CASE_RESOURCE, case_text)
        for comp, fmu in fmus.items():
            z.write(fmu, f"resources/{comp}.fmu")
    osp_dir = path.parent / f"{path.stem}_osp"
    osp_dir.mkdir(exist_ok=True)
    for comp, fmu in fmus.items():
        shutil.copy2(fmu, osp_dir / f"{comp}.fmu")
    (osp_dir / "OspSystemStructure.xml").write_bytes(osp_system_structure(fmus, parameters, dt))
    return path


class SspError(ValueError):
    """An SSP file that cannot be run; one line."""


def read_ssp(path: Path, into: Path) -> dict:
    """Unpack an SSP written by write_ssp: FMUs, connections, parameter values and the case text."""
    from fmpy.ssp.ssd import read_ssd

    path = Path(path)
    try:
        ssd = read_ssd(str(path))
        with zipfile.ZipFile(path) as z:
            z.extractall(into)
    except (zipfile.BadZipFile, KeyError, OSError) as exc:
        raise SspError(f"{path}: not a readable SSP file ({exc})") from None
    except Exception as exc:  # schema validation errors of fmpy
        raise SspError(f"{path}: invalid SystemStructure.ssd ({str(exc).splitlines()[0]})") from None
    case_file = Path(into) / CASE_RESOURCE
    if not case_file.exists():
        raise SspError(f"{path}: no {CASE_RESOURCE} (not written by pantohil build --ssp)")
    system = ssd.system
    fmus = {c.name: _member_fmu(path, Path(into), c.name, c.source) for c in system.elements}
    connections = tuple((c.startElement, c.startConnector, c.endElement, c.endConnector) for c in system.connections)
    parameters: dict[str, dict] = {}
    for binding in system.parameterBindings:
        for pset in binding.parameterValues:
            for p in pset.parameters:
                comp, var = p.name.split(".", 1)
                value = (
                    float(p.value)
                    if p.type == "Real"
                    else (p.value in (True, "true") if p.type == "Boolean" else int(p.value))
                )
                parameters.setdefault(comp, {})[var] = value
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
