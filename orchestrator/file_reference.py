"""The key references of pantohil's input files (docs/case-reference.md, rig-reference.md,
catenary-reference.md, sweep-reference.md), generated from their declarations (models/schema.py), so
that the documentation cannot drift from what the loaders accept.

    python -m pantohil.orchestrator.file_reference docs
"""
from __future__ import annotations

import sys
from pathlib import Path

from pantohil.models import parameters as P
from pantohil.models.case import CASE_FILE
from pantohil.models.catenary.fe.definition import CATENARY_FILE, MAX_ELEMENTS_PER_SPAN
from pantohil.models.rig.rig_file import RIG_FILE
from pantohil.models.schema import REQUIRED, FileSchema, Key, json_like

from .sweep import SWEEP_FILE

COMMAND = "python -m pantohil.orchestrator.file_reference docs"

GENERATED = f"""generated from its declarations by `{COMMAND}` (a test checks that this file is current).
Units are SI; the range is what the loader accepts, anything else is refused with one line naming the
key (exit 2). A key marked *required* has no default; one marked *optional* may be left out."""

CASE_INTRO = """# Case reference

Every key of a case file, {generated}

## Naming rule

A parameter has one name, `snake_case`, ending in its SI unit (`_m`, `_s`, `_N`, `_N_m`, `_kg_m`,
`_hz`, `_1_s`, ...; none for a pure number or a choice). The name is the same in the case file
(`[rig] servo_bandwidth_hz`), in the FMU's modelDescription.xml (`servo_bandwidth_hz`) and in
summary.json. Two kinds of key reach an FMU under a derived name: a choice becomes an Integer, the
index of its value in the listed choices, named `<section>_<key>` (`catenary_model`,
`pantograph_model`, `hil_update`); a list becomes one variable per item, `<key>_<i>` from 1
(`masses_kg_1`). Speed is the one key in km/h (`run.speed_kmh`), as railway engineers state it.
A value written `"auto"` is computed by pantohil and is the default where it is allowed; no number
stands for "automatic".

Limits on sizes, checked before anything is allocated: at most {samples} samples per span, {spans}
spans, {items} values in a list; input files are regular UTF-8 files of at most 4 MiB.
"""

RIG_INTRO = """# Rig file reference

Every key of a rig file (`models/data/rigs/*.toml`, `[rig] file = ...` in a case, `pantohil
rig-emulator --rig`, written by `pantohil rig-identify`), {generated}

A rig file describes the chain between the model computer and the pantograph as Paper B sec. 4 and
Paper D sec. 2 do. Beyond single keys the loader checks that the stroke's maximum lies above its
minimum, that the drive's ramp and sub-reference period fit in a reference period (N_com dt), that a
reference period holds at most 100 sub-references, and that the force filter lies below the Nyquist
frequency.
"""

CATENARY_INTRO = """# Catenary file reference

Every key of a catenary file (`models/data/catenaries/*.toml`, `pantohil catenary`, `pantohil
fem-sim`, `[catenary] definition_file` of a PFEM case), {generated}

A catenary file describes one span. Beyond single keys the loader checks that the droppers are given
once (`dropper_spacing_m` summing to the span, or `dropper_positions_m` increasing inside it), that a
wire's mass and the droppers' are given (as a mass per length, or a density and an area), that the
stitch wire is shorter than the span, that a spring support has its stiffness, and that the mesh fits
the shortest dropper interval with at most {elements} elements per span.
"""

SWEEP_INTRO = """# Sweep file reference

Every key of a sweep file (`models/data/sweeps/*.toml`, `pantohil sweep`), {generated}

Every point's case is validated before anything runs; a grid or set key must be a case key
([case-reference.md](case-reference.md)) or, with `kind = "direct"`, `direct.second_pantograph_m`.
"""

PAGES: dict[str, tuple[FileSchema, str]] = {
    schema.reference: (schema, intro) for schema, intro in (
        (CASE_FILE, CASE_INTRO), (RIG_FILE, RIG_INTRO), (CATENARY_FILE, CATENARY_INTRO), (SWEEP_FILE, SWEEP_INTRO))
}


def _default(key: Key) -> str:
    if key.default is REQUIRED:
        return "*required*"
    if key.default is None:
        return "*optional*"
    if isinstance(key.default, tuple):
        return "[" + ", ".join(json_like(v) for v in key.default) + "]" if key.default else "[]"
    return json_like(key.default) if key.default != "" else '""'


def _row(key: Key, with_fmu: bool) -> str:
    p = key.param
    unit = "" if p.unit == "1" else p.unit
    allowed = "true or false" if key.type is bool else p.range_text() + (' or "auto"' if p.auto else "")
    if key.type is tuple and p.max_items != P.MAX_LIST_LENGTH:
        allowed += f", at most {p.max_items} values"
    row = f"| `{key.name}` | {unit} | {allowed} | {_default(key)} | {p.description} |"
    if not with_fmu:
        return row
    names = P.fmu_variable_names(key)
    fmu = f"{p.fmu}: `{names[0]}`" + (" ..." if len(names) > 1 else "") if p.fmu else ""
    return f"{row} {fmu} |"


def _section_text(cls: type) -> str:
    """A section class's docstring without its `[name]:` head, on one line."""
    text = " ".join((cls.__doc__ or "").split()).split(": ", 1)[-1]
    return text[:1].upper() + text[1:]


def reference_markdown(name: str = "case-reference") -> str:
    """The whole reference page `name` (docs/<name>.md)."""
    schema, intro = PAGES[name]
    parts = [intro.format(generated=GENERATED, samples=P.MAX_SAMPLES_PER_SPAN, spans=P.MAX_SPANS,
                          items=P.MAX_LIST_LENGTH, elements=MAX_ELEMENTS_PER_SPAN)]
    with_fmu = schema.to_fmus
    head = "| key | unit | range | default | description |" + (" FMU variable |" if with_fmu else "")
    rule = "|---|---|---|---|---|" + ("---|" if with_fmu else "")
    for section, cls in schema.sections.items():
        status = " (required)" if section in schema.required_sections else ""
        parts.append(f"\n## [{section}]{status}\n\n{_section_text(cls)}\n\n{head}\n{rule}")
        parts.extend(_row(k, with_fmu) for k in schema.keys(section).values())
    for section, text in schema.free_sections.items():
        parts.append(f"\n## [{section}]\n\nIts keys are {text}.")
    return "\n".join(parts) + "\n"


def main(argv: list[str]) -> int:
    """Write every key reference into the folder argv[0] (default docs)."""
    folder = Path(argv[0]) if argv else Path("docs")
    for name in PAGES:
        target = folder / f"{name}.md"
        target.write_text(reference_markdown(name), encoding="utf-8")
        print(f"written {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
