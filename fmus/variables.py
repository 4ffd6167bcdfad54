"""Declarative FMU variables: one table per FMU gives names, units, descriptions and ranges; the
same table registers the variables with pythonfmu and lets the builder decorate modelDescription.xml.
The variables that carry case keys are derived from the declarations in models/parameters.py
(`case_variables`), named by its naming rule; a table adds only what the FMU itself defines.

Case values reach the FMU through `resources/parameters.json`, read when the slave is created, so the
FMU alone (in any master) reproduces the case; a master may still set parameters before initialising.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Variability, Integer, Real, String

from pantohil.models.parameters import AUTO, Key, fmu_keys, fmu_variable_names

PARAMETERS_FILE = "parameters.json"
REQUIREMENTS_FILE = "requirements.txt"  # what `pythonfmu deploy` installs on a host
REQUIREMENTS = ("numpy>=1.26", "scipy>=1.11")

# SI base-unit exponents of every unit used by the FMUs (FMI 2.0 <BaseUnit>).
UNITS = {
    "m": {"m": 1}, "s": {"s": 1}, "kg": {"kg": 1}, "N": {"kg": 1, "m": 1, "s": -2},
    "m/s": {"m": 1, "s": -1}, "Hz": {"s": -1}, "1/s": {"s": -1}, "kg/m": {"kg": 1, "m": -1},
    "N/m": {"kg": 1, "s": -2}, "N/m2": {"kg": 1, "m": -1, "s": -2}, "N.s/m": {"kg": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2}, "1": {},
}
# Display units offered to tools: name -> (factor, of unit); display = factor * value
DISPLAY_UNITS = {"m": ("mm", 1000.0), "m/s": ("km/h", 3.6), "N/m": ("kN/m", 1e-3)}


@dataclass(frozen=True)
class Var:
    """One FMU variable: name, type, causality, unit, description, start value and range."""
    name: str
    kind: str  # "real" | "integer" | "boolean" | "string"
    causality: str  # "parameter" | "input" | "output"
    unit: str
    description: str
    start: float | int | bool = 0
    min: float | None = None
    max: float | None = None
    # an output's inputs at initialisation (FMI 2.0 InitialUnknowns dependencies; None: every input): what the
    # value it has after exitInitializationMode depends on besides the parameters
    initial_inputs: tuple[str, ...] | None = ()


def _key_variables(key: Key) -> list[Var]:
    p = key.param
    names = fmu_variable_names(key)
    if p.choices and isinstance(p.choices[0], str):
        listed = ", ".join(f"{i}: {c}" for i, c in enumerate(p.choices))
        return [Var(names[0], "integer", "parameter", "1", f"{p.description} ({listed})", 0, 0, len(p.choices) - 1)]
    if key.type is bool:
        described = f"{p.description} (1: true, 0: false)"
        return [Var(names[0], "integer", "parameter", "1", described, int(key.default), 0, 1)]
    kind = "integer" if key.type is int else "real"
    if p.fmu_items:
        starts = list(key.default) + [0.0] * (p.fmu_items - len(key.default))
        return [Var(n, kind, "parameter", p.unit, f"{p.description}: item {i + 1}", starts[i], p.low, p.high)
                for i, n in enumerate(names)]
    no_number = key.default is AUTO or not isinstance(key.default, (int, float))
    start = p.fmu_start if p.fmu_start is not None and no_number else key.default
    return [Var(names[0], kind, "parameter", p.unit, p.description, start, p.low, p.high)]


def case_variables(fmu: str) -> list[Var]:
    """The FMU parameters that carry case keys, from their declarations (models/parameters.py)."""
    return [v for key in fmu_keys(fmu) for v in _key_variables(key)]


def load_parameters(resources: str | None) -> dict:
    """The case values an FMU carries in resources/parameters.json (empty if there are none)."""
    if not resources:
        return {}
    path = Path(resources) / PARAMETERS_FILE
    return json.loads(path.read_text()) if path.exists() else {}


def register_all(slave, variables: list[Var]) -> None:
    """Set each variable's attribute (case value or start) and register it with pythonfmu."""
    given = load_parameters(slave.resources)
    slave._declared = {v.name: v for v in variables if v.causality == "parameter"}
    slave._built = given
    for var in variables:
        value = given.get(var.name, var.start) if var.causality == "parameter" else var.start
        if not isinstance(getattr(type(slave), var.name, None), property):  # a property computes its value
            setattr(slave, var.name, {"real": float, "integer": int, "boolean": bool, "string": str}[var.kind](value))
        causality = getattr(Fmi2Causality, var.causality)
        desc = f"{var.description} [{var.unit}]" if var.unit != "1" else var.description
        if var.causality == "parameter":
            kw = dict(causality=causality, variability=Fmi2Variability.fixed)
        elif var.causality == "input":
            kw = dict(causality=causality,
                      variability=Fmi2Variability.continuous if var.kind == "real" else Fmi2Variability.discrete)
        else:
            kw = dict(causality=causality, initial=Fmi2Initial.exact,
                      variability=Fmi2Variability.continuous if var.kind == "real" else Fmi2Variability.discrete)
        cls = {"real": Real, "integer": Integer, "boolean": Boolean, "string": String}[var.kind]
        slave.register_variable(cls(var.name, description=desc, **kw), nested=False)
