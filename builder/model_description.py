"""An FMU's modelDescription.xml as pantohil states it: units and display units, ranges, the fixed step and
the default experiment, the state capabilities, the output dependencies, and a GUID derived from the build's
inputs (FMI 2.0 secs. 2.2.2-2.2.8)."""
from __future__ import annotations

import uuid
import xml.etree.ElementTree as ET

from pantohil.fmus.variables import DISPLAY_UNITS, UNITS


# What the loader library and the state hooks make true of every pantohil FMU
CAPABILITIES = {"canHandleVariableCommunicationStepSize": "false", "canGetAndSetFMUstate": "true",
                "canSerializeFMUstate": "true"}


def _declare_behaviour(root: ET.Element, experiment: tuple[float, float], variables) -> None:
    """Capabilities, DefaultExperiment and ModelStructure as they are. Outputs: computed in doStep from
    the inputs of the step before (dependencies=""), and computed during initialisation (the pantograph
    settles on its input height, the catenary commands its first height), hence initial="calculated",
    listed in InitialUnknowns with their dependencies there: the parameters (knowns with initial="exact")
    and the inputs each declares (`Var.initial_inputs`), so that a master sees no algebraic loop at
    initialisation where there is none."""
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
        ET.SubElement(initial, "Unknown", {"index": unknown.get("index"),
                                           "dependencies": " ".join(map(str, _initial_dependencies(
                                               root, variables, int(unknown.get("index")))))})


def _initial_dependencies(root: ET.Element, variables, index: int) -> list[int]:
    """The knowns an output (1-based `index`) depends on at initialisation, ascending: every parameter and the
    inputs its declaration names (all of them for None)."""
    by_name = {v.name: v for v in variables}
    scalars = list(root.find("ModelVariables").iter("ScalarVariable"))
    wanted = by_name[scalars[index - 1].get("name")].initial_inputs
    return [i for i, sv in enumerate(scalars, start=1)
            if sv.get("causality") == "parameter"
            or (sv.get("causality") == "input" and (wanted is None or sv.get("name") in wanted))]


def decorate_model_description(xml_bytes: bytes, variables, experiment: tuple[float, float], identity: str) -> bytes:
    """Add unit and display-unit definitions, units, ranges and the generation tool to pythonfmu's
    modelDescription.xml; state the fixed step, the default experiment (step, stop time), the state
    capabilities and the output dependencies (FMI 2.0 sec. 2.2.8: no output depends directly on an
    input: every output is computed in doStep or read from the state it leaves). The GUID is derived
    from `identity` (the digest of the build's inputs) and the build time is left out, so that the same
    inputs give the same FMU, byte for byte."""
    root = ET.fromstring(xml_bytes)
    root.set("generationTool", f"pantohil {pantohil_version()} with {root.get('generationTool')}")
    root.set("guid", str(uuid.uuid5(uuid.NAMESPACE_URL, f"pantohil-fmu:{identity}")))
    root.attrib.pop("generationDateAndTime", None)
    _declare_behaviour(root, experiment, variables)
    by_name = {v.name: v for v in variables}
    used = sorted({v.unit for v in variables if v.kind == "real"})
    units = ET.Element("UnitDefinitions")
    for u in used:
        unit = ET.SubElement(units, "Unit", name=u)
        ET.SubElement(unit, "BaseUnit", {k: str(e) for k, e in UNITS[u].items()})
        if u in DISPLAY_UNITS:
            name, factor = DISPLAY_UNITS[u]
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


def pantohil_version() -> str:
    """The installed pantohil's version ("unknown" when run from a source tree)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("pantohil")
    except PackageNotFoundError:
        return "unknown"
