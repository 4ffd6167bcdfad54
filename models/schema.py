"""One schema mechanism for every input file pantohil reads: case, rig, catenary and sweep files.

A file kind is a `FileSchema`: its [sections], each a frozen dataclass whose fields declare its keys
with `param(...)` (unit, range, description, and for case keys the FMU that receives the value). From
the declarations come the validation (`FileSchema.validate`: unknown sections and keys, types, finite
numbers, ranges, choices, list lengths, defaults, one line naming the key in the file kind's error)
and the generated key references in docs/ (`models/file_reference.py`). What a file means beyond
single keys (either of two keys, a sum that must equal the span, the grid of a sweep) its loader
checks after validation.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from pantohil.models.errors import InputError

AUTO = "auto"
REQUIRED = object()  # a field without a default: the file must give it
# A field declared with the default None is optional and has no default value: absent, it validates to None.

XS_INT_MIN = -(2**31)  # FMI 2.0 Integer is xs:int
XS_INT_MAX = 2**31 - 1
MAX_LIST_LENGTH = 100  # values in a list, unless its declaration allows more


@dataclass(frozen=True)
class Param:
    """What a key is: unit (FMI unit string, "1" for none), description and range."""

    unit: str
    description: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple = ()
    fmu: str | None = None  # the FMU whose variable (named by the naming rule) receives the value
    auto: bool = False  # "auto" (computed by pantohil) is allowed, and is the default
    fmu_items: int = 0  # a list reaches the FMU as this many variables <key>_1 ... (padded with 0)
    fmu_start: float | None = None  # the FMU variable's start value where the key has no default number
    max_items: int = MAX_LIST_LENGTH  # a list's longest length

    def range_text(self) -> str:
        """The range as a mathematician writes it, e.g. `(0, 1e+06]`."""
        if self.choices:
            return " or ".join(json_like(c) for c in self.choices)
        if self.low is None and self.high is None:
            return "any"
        lo = "-inf" if self.low is None else f"{self.low:g}"
        hi = "inf" if self.high is None else f"{self.high:g}"
        opening = "(" if self.low_open or self.low is None else "["
        closing = ")" if self.high_open or self.high is None else "]"
        return f"{opening}{lo}, {hi}{closing}"

    def contains(self, x: float) -> bool:
        """Whether x lies in the parameter's range (open or closed at each end)."""
        if self.low is not None and (x <= self.low if self.low_open else x < self.low):
            return False
        return not (self.high is not None and (x >= self.high if self.high_open else x > self.high))


def json_like(value) -> str:
    """A value as written in TOML or JSON (strings quoted, booleans lower case), for messages and docs."""
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, bool):
        return "true" if value else "false"
    return f"{value:g}" if isinstance(value, float) else str(value)


def param(default, unit: str, description: str, low=None, high=None, *, low_open=False, high_open=False,
          choices=(), fmu=None, auto=False, fmu_items=0, fmu_start=None, max_items=MAX_LIST_LENGTH):
    """A dataclass field declaring one key (default None: optional, with no default value)."""
    meta = Param(unit, description, low, high, low_open, high_open, tuple(choices), fmu, auto, fmu_items, fmu_start,
                 max_items)
    if isinstance(default, (list, tuple)):
        return field(default=tuple(default), metadata={"param": meta})
    return field(default=default, metadata={"param": meta})


@dataclass(frozen=True)
class Key:
    """One declared key: section, name, Python type, default and its Param."""

    section: str
    name: str
    type: type
    default: object
    param: Param

    @property
    def dotted(self) -> str:
        """The key as `section.name`."""
        return f"{self.section}.{self.name}"


_TYPES = {"str": str, "float": float, "int": int, "bool": bool, "tuple": tuple}


def declared_keys(section: str, cls: type) -> dict[str, Key]:
    """The keys a section dataclass declares, in declaration order."""
    return {f.name: Key(section, f.name, _TYPES[f.type] if isinstance(f.type, str) else f.type, f.default,
                        f.metadata["param"]) for f in dataclasses.fields(cls)}


@dataclass(frozen=True)
class FileSchema:
    """A kind of input file: its sections' declarations, the error it raises and its reference page."""

    kind: str  # "case file", "rig file", ...: how messages and the reference name it
    sections: dict[str, type]
    error: type[InputError]
    required_sections: tuple[str, ...] = ()
    optional_sections: tuple[str, ...] = ()  # absent, the section validates to None (its required keys with it)
    free_sections: dict[str, str] = field(default_factory=dict)  # section -> what its (free) keys are
    reference: str = ""  # its key reference, docs/<reference>.md (orchestrator/file_reference.py writes it)
    to_fmus: bool = False  # its keys reach the FMUs (the reference names their variables)

    def keys(self, section: str) -> dict[str, Key]:
        """The declared keys of a section."""
        return declared_keys(section, self.sections[section])

    def all_keys(self) -> list[Key]:
        """Every declared key of every section, in declaration order."""
        return [k for s in self.sections for k in self.keys(s).values()]

    def validate(self, raw: dict) -> dict:
        """Fill defaults and check every key against its declaration; {section: {key: value}} with every
        declared section, and each free section as given (a table)."""
        known = [*self.sections, *self.free_sections]
        for section in raw:
            if section not in known:
                raise self.error(f"{section}: unknown section (known: {', '.join(known)})", key=section)
            if not isinstance(raw[section], dict):
                raise self.error(f"{section}: expected a table of keys", key=section)
        for section in self.required_sections:
            if section not in raw:
                raise self.error(f"{section}: missing section", key=section)
        out = {section: dict(raw.get(section, {})) for section in self.free_sections}
        for section in self.sections:
            absent = section not in raw and section in self.optional_sections
            out[section] = None if absent else self._section(section, raw.get(section, {}))
        return out

    def _section(self, section: str, given: dict) -> dict:
        keys = self.keys(section)
        for name in given:
            if name not in keys:
                raise self.error(f"{section}.{name}: unknown key (known: {', '.join(keys)})", key=f"{section}.{name}")
        values = {}
        for name, key in keys.items():
            if name in given:
                values[name] = coerce(key, given[name], self.error)
            elif key.default is REQUIRED:
                raise self.error(f"{section}.{name}: missing (required)", key=f"{section}.{name}")
            else:
                values[name] = list(key.default) if isinstance(key.default, tuple) else key.default
        return values


def _shown(value) -> str:
    """A refused number as given, with every digit that tells it from the range's bound (repr)."""
    return str(value) if isinstance(value, int) else repr(float(value))


def _coerce_number(key: Key, value, error: type[InputError]):
    name, p = key.dotted, key.param
    if key.type is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise error(f"{name}: expected an integer, got {value!r}", key=name)
        if not XS_INT_MIN <= value <= XS_INT_MAX:
            raise error(f"{name}: {value} is outside the FMI integer range [{XS_INT_MIN}, {XS_INT_MAX}]", key=name)
    elif isinstance(value, bool) or not isinstance(value, (int, float)):
        raise error(f"{name}: expected a number, got {value!r}", key=name)
    elif not math.isfinite(value):
        raise error(f"{name}: must be a finite number, got {value!r}", key=name)
    else:
        value = float(value)
    if not p.contains(value):
        unit = f" {p.unit}" if p.unit != "1" else ""
        raise error(f"{name}: {_shown(value)}{unit} is outside its range {p.range_text()}", key=name)
    return value


def _coerce_list(key: Key, value, error: type[InputError]) -> list:
    name, p = key.dotted, key.param
    if not isinstance(value, list):
        raise error(f"{name}: expected a list of numbers, got {value!r}", key=name)
    if len(value) > p.max_items:
        raise error(f"{name}: {len(value)} values, above the limit of {p.max_items}", key=name)
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise error(f"{name}[{i}]: expected a number, got {v!r}", key=name)
        if not math.isfinite(v):
            raise error(f"{name}[{i}]: must be a finite number, got {v!r}", key=name)
        if not p.contains(v):
            unit = f" {p.unit}" if p.unit != "1" else ""
            raise error(f"{name}[{i}]: {_shown(v)}{unit} is outside its range {p.range_text()}", key=name)
    return [float(v) for v in value]


def coerce(key: Key, value, error: type[InputError]):
    """A given value checked against its declaration (type, finiteness, FMI type, range, choices)."""
    name, p = key.dotted, key.param
    if p.auto and value == AUTO:
        return AUTO
    if p.choices:
        if isinstance(value, bool) != isinstance(p.choices[0], bool) or value not in p.choices:
            raise error(f"{name}: must be {p.range_text()} (got {value!r})", key=name)
        return value
    if key.type in (int, float):
        try:
            return _coerce_number(key, value, error)
        except error as exc:
            if p.auto and not isinstance(value, str):
                raise error(f"{exc} (or \"{AUTO}\")", key=name) from None
            raise
    if key.type is bool and not isinstance(value, bool):
        raise error(f"{name}: expected true or false, got {value!r}", key=name)
    if key.type is str and not isinstance(value, str):
        raise error(f"{name}: expected a string, got {value!r}", key=name)
    if key.type is tuple:
        return _coerce_list(key, value, error)
    return value
