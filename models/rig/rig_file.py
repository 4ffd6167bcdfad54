"""Rig files (TOML): a rig chain as the papers describe it, read into a `RigSpec` and written back
with a measured frequency response (`pantohil rig-identify`). Every key is declared once below with
its type, default, range and unit (models/schema.py; docs/rig-reference.md is generated from them); a
bad file raises RigFileError with one line naming the key.
"""
from __future__ import annotations

import cmath
import math
from dataclasses import dataclass, replace
from pathlib import Path

from ..errors import InputError
from ..input_files import InputFileError, load_toml
from ..schema import REQUIRED, FileSchema, param
from .actuator import ActuatorLimits
from .drive_chain import ForcePath, HeightPath, MeasuredResponse, RigSpec


class RigFileError(InputError):
    """A rig file that cannot be used; the message is one line naming the key."""


# Bounds on what sets a run's work and memory, each as for the case's keys (models/parameters.py):
MIN_STEP_S, MAX_STEP_S = 1e-5, 1.0  # the dt a HELLO may carry on the rig link
MAX_SUB_STEPS = 100  # drive sub-references per model step (Paper B's drive: 3.2); each costs a loop update
MAX_RESPONSE_POINTS = 10_000  # measured frequencies (rig-identify writes one per kept harmonic)

@dataclass(frozen=True)
class RigHeaderSection:
    """[rig]: what the rig is and the step it runs at."""

    name: str = param("unnamed", "1", "rig name")
    description: str = param("", "1", "free text")
    model_step_s: float = param(REQUIRED, "s", "model step dt the rig runs at (the rig link's range of dt)",
                                MIN_STEP_S, MAX_STEP_S)
    stated_delay_s: float = param(0.0, "s", "total delay the source states", 0.0)


@dataclass(frozen=True)
class ResponseSection:
    """[response]: the rig's measured frequency response at the kept harmonics (`pantohil rig-identify`
    writes it); all five lists or none, one value per frequency."""

    frequencies_hz: tuple = param(None, "Hz", "measured frequencies, increasing", 0.0, low_open=True,
                                  max_items=MAX_RESPONSE_POINTS)
    height_gain: tuple = param(None, "1", "|actuator height / command|", 0.0, low_open=True,
                               max_items=MAX_RESPONSE_POINTS)
    height_phase_deg: tuple = param(None, "deg", "phase of actuator height / command",
                                    max_items=MAX_RESPONSE_POINTS)
    force_gain: tuple = param(None, "1", "|measured / true force|", 0.0, low_open=True, max_items=MAX_RESPONSE_POINTS)
    force_phase_deg: tuple = param(None, "deg", "phase of measured / true force", max_items=MAX_RESPONSE_POINTS)


RIG_FILE = FileSchema("rig file", {"rig": RigHeaderSection, "height": HeightPath, "force": ForcePath,
                                   "limits": ActuatorLimits, "response": ResponseSection}, RigFileError,
                      reference="rig-reference")


def _measured(resp: dict) -> MeasuredResponse | None:
    given = {k: v for k, v in resp.items() if v is not None}
    if not given:
        return None
    missing = [k for k in resp if k not in given]
    if missing:
        raise RigFileError(f"response.{missing[0]}: missing (the response needs all of {', '.join(resp)})")
    n = len(given["frequencies_hz"])
    for key, vals in given.items():
        if len(vals) != n:
            raise RigFileError(f"response.{key}: {len(vals)} values for {n} frequencies")
    freqs = given["frequencies_hz"]
    if n == 0 or any(b <= a for a, b in zip(freqs, freqs[1:], strict=False)):
        raise RigFileError("response.frequencies_hz: one or more frequencies > 0, increasing")
    z = tuple(
        g * cmath.exp(1j * math.radians(p))
        for g, p in zip(given["height_gain"], given["height_phase_deg"], strict=False)
    )
    f = tuple(
        g * cmath.exp(1j * math.radians(p)) for g, p in zip(given["force_gain"], given["force_phase_deg"], strict=False)
    )
    return MeasuredResponse(tuple(given["frequencies_hz"]), z, f)


def rig_from_dict(raw: dict) -> RigSpec:
    """Validate a parsed rig file into a RigSpec; RigFileError names the key at fault."""
    v = RIG_FILE.validate(raw)
    r, h, f, lim = v["rig"], v["height"], v["force"], v["limits"]
    if not lim["stroke_min_m"] < lim["stroke_max_m"]:
        raise RigFileError(f"limits.stroke_max_m: must be above limits.stroke_min_m ({lim['stroke_min_m']:g} m)")
    dt = r["model_step_s"]
    if 0 < h["sub_step_s"] < dt / MAX_SUB_STEPS:
        raise RigFileError(f"height.sub_step_s: {h['sub_step_s']!r} s gives {dt / h['sub_step_s']:.3g} sub-steps per "
                           f"model step (dt = {dt:g} s), above the limit of {MAX_SUB_STEPS}")
    if h["sub_step_s"] > dt * h["decimation"] + 1e-15 and h["sub_step_s"] > 0:
        raise RigFileError(f"height.sub_step_s: {h['sub_step_s']:g} s is longer than a reference period "
                           f"(N_com dt = {dt * h['decimation']:g} s)")
    if h["ramp_s"] > dt * h["decimation"] + 1e-15:
        raise RigFileError(f"height.ramp_s: {h['ramp_s']:g} s is longer than a reference period "
                           f"(N_com dt = {dt * h['decimation']:g} s): the ramp would not finish")
    if f["filter_hz"] >= 0.5 / dt:
        raise RigFileError(
            f"force.filter_hz: {f['filter_hz']:g} Hz is at or above the Nyquist frequency {0.5 / dt:g} Hz"
        )
    return RigSpec(r["name"], dt, HeightPath(**h), ForcePath(**f), ActuatorLimits(**lim), r["stated_delay_s"],
                   r["description"], _measured(v["response"]))


def load_rig_file(path: Path) -> RigSpec:
    """Read and validate a rig file (TOML); RigFileError with one line on any fault."""
    try:
        raw = load_toml(Path(path), "rig file")
    except InputFileError as exc:
        raise RigFileError(str(exc)) from None
    return rig_from_dict(raw)


def _toml_value(v) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, float):
        return repr(float(v))  # a numpy float's repr is not TOML
    return repr(v)


def rig_sections(spec: RigSpec) -> dict:
    """The rig file's sections of `spec` as plain data (its measured response, if any, as gains and
    phases in degrees): what rig_to_toml writes and a run's summary.json reports."""
    lim = spec.limits
    sections = {
        "rig": {"name": spec.name, "description": spec.description, "model_step_s": spec.model_step_s,
                "stated_delay_s": spec.stated_delay_s},
        "height": vars(spec.height), "force": vars(spec.force),
        "limits": {k: getattr(lim, k) for k in RIG_FILE.keys("limits")},
    }
    m = spec.measured
    if m is not None:
        sections["response"] = {
            "frequencies_hz": [float(f) for f in m.frequencies_hz],
            "height_gain": [abs(g) for g in m.height],
            "height_phase_deg": [math.degrees(cmath.phase(g)) for g in m.height],
            "force_gain": [abs(g) for g in m.force],
            "force_phase_deg": [math.degrees(cmath.phase(g)) for g in m.force],
        }
    return sections


def rig_to_toml(spec: RigSpec, header: str = "") -> str:
    """The rig file of `spec` (with its measured response, if any)."""
    lines = [f"# {line}" for line in header.splitlines()]
    for name, keys in rig_sections(spec).items():
        lines += ["", f"[{name}]"] + [f"{k} = {_toml_value(v)}" for k, v in keys.items()]
    return "\n".join(lines).lstrip("\n") + "\n"


def with_measured(spec: RigSpec, measured: MeasuredResponse) -> RigSpec:
    """The rig with a measured frequency response (from pantohil rig-identify) attached."""
    return replace(spec, measured=measured)
