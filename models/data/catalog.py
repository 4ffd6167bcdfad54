"""The shipped data by name: `pantohil run pfem_benchmark_250` finds models/data/cases/pfem_benchmark_250.toml
from any folder, after a plain install as in a checkout; `pantohil cases` lists what is shipped.

A name is a bare word (no folder, with or without `.toml`) that is not a file in the current folder;
a path is always taken as it is.
"""
from __future__ import annotations

import re
from pathlib import Path

from pantohil.models.input_files import InputFileError, load_toml

from . import CASES_DIR, CATENARIES_DIR, RIGS_DIR, SWEEPS_DIR

KINDS = {"case": (CASES_DIR, "case"), "catenary": (CATENARIES_DIR, "catenary"), "rig": (RIGS_DIR, "rig"),
         "sweep": (SWEEPS_DIR, "sweep")}  # kind -> (folder, table holding `description` or `name`)
PLURALS = {"case": "cases", "catenary": "catenaries", "rig": "rigs", "sweep": "sweeps"}
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")


def resolve(path: Path | str, kind: str) -> Path:
    """`path` itself if it exists or names a folder; else the shipped file of that kind with that name
    (or `path` unchanged, so that the caller's error names what was given)."""
    given = Path(path)
    if given.exists() or len(given.parts) != 1 or not _NAME.fullmatch(given.name):
        return given
    shipped = KINDS[kind][0] / (given.name if given.suffix == ".toml" else f"{given.name}.toml")
    return shipped if shipped.is_file() else given


def names(kind: str) -> list[str]:
    """The names of the shipped files of a kind, sorted."""
    return sorted(p.stem for p in KINDS[kind][0].glob("*.toml"))


def description(kind: str, name: str) -> str:
    """The one-line description of a shipped file: its `description` (or `name`) key."""
    folder, table = KINDS[kind]
    try:
        raw = load_toml(folder / f"{name}.toml", f"{kind} file")
    except InputFileError as exc:
        return f"(unreadable: {exc})"
    section = raw.get(table, {}) if isinstance(raw.get(table), dict) else {}
    text = section.get("description") or section.get("name") or ""
    return " ".join(str(text).split())


def listing() -> str:
    """Every shipped case, catenary, rig and sweep with its description, as text for a terminal."""
    lines = []
    for kind in KINDS:
        lines.append(f"{PLURALS[kind]} ({KINDS[kind][0]}):")
        width = max((len(n) for n in names(kind)), default=0)
        lines += [f"  {n:<{width}}  {description(kind, n)}" for n in names(kind)]
    return "\n".join(lines)
