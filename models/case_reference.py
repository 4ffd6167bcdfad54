"""The case-key reference (docs/case-reference.md), generated from the declarations in
models/parameters.py, so that the documentation cannot drift from what the loader accepts.

    python -m pantohil.models.case_reference docs/case-reference.md
"""
from __future__ import annotations

import sys
from pathlib import Path

from pantohil.models import parameters as P

HEADER = """# Case reference

Every key of a case file, generated from the declarations in `models/parameters.py` by
`python -m pantohil.models.case_reference docs/case-reference.md` (a test checks that this file is
current). Units are SI; the range is what the loader accepts, anything else is refused with one
line naming the key. A key marked *required* has no default.

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


def _default(key: P.Key) -> str:
    if key.default is P.REQUIRED:
        return "*required*"
    if isinstance(key.default, tuple):
        return "[" + ", ".join(P.json_like(v) for v in key.default) + "]" if key.default else "[]"
    return P.json_like(key.default) if key.default != "" else '""'


def _row(key: P.Key) -> str:
    p = key.param
    unit = "" if p.unit == "1" else p.unit
    fmu = f"{p.fmu}: `{P.fmu_variable_names(key)[0]}`" if p.fmu else ""
    if p.fmu and len(P.fmu_variable_names(key)) > 1:
        fmu += " ..."
    allowed = p.range_text() + (' or "auto"' if p.auto else "")
    return f"| `{key.name}` | {unit} | {allowed} | {_default(key)} | {p.description} | {fmu} |"


def reference_markdown() -> str:
    """The whole reference page."""
    parts = [HEADER.format(samples=P.MAX_SAMPLES_PER_SPAN, spans=P.MAX_SPANS, items=P.MAX_LIST_LENGTH)]
    for section, cls in P.SECTIONS.items():
        parts.append(f"\n## [{section}]\n\n{' '.join((cls.__doc__ or '').split()).split(': ', 1)[-1]}\n\n"
                     "| key | unit | range | default | description | FMU variable |\n|---|---|---|---|---|---|")
        parts.extend(_row(k) for k in P.section_keys(section).values())
    return "\n".join(parts) + "\n"


def main(argv: list[str]) -> int:
    """Write the case-key reference (default docs/case-reference.md) from the declarations."""
    target = Path(argv[0]) if argv else Path("docs/case-reference.md")
    target.write_text(reference_markdown(), encoding="utf-8")
    print(f"written {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
