"""Rig files (TOML): a rig chain as the papers describe it, read into a `RigSpec` and written back
with a measured frequency response (`pantohil rig-identify`). Every key is declared once below with
its type, default, range and unit; a bad file raises RigFileError with one line naming the key.
"""
from __future__ import annotations

import cmath
import math
from dataclasses import replace
from pathlib import Path

from ..errors import InputError
from ..input_files import InputFileError, load_toml
from ..parameters import MAX_SAMPLES_PER_SPAN
from .actuator import ActuatorLimits
from .drive_chain import ForcePath, HeightPath, MeasuredResponse, RigSpec


class RigFileError(InputError):
    """A rig file that cannot be used; the message is one line naming the key."""


# Bounds on what sets a run's work and memory, each as for the case's keys (models/parameters.py):
MIN_STEP_S, MAX_STEP_S = 1e-5, 1.0  # the dt a HELLO may carry on the rig link
MAX_DELAY_STEPS = MAX_SAMPLES_PER_SPAN  # a delay must be shorter than a span, and a span holds at most this many
DELAY_RANGE = f"must lie in 0..{MAX_DELAY_STEPS} (a delay shorter than the longest span)"
MAX_DECIMATION = 10_000  # as the case's rig.comm_decimation
MAX_SUB_STEPS = 100  # drive sub-references per model step (Paper B's drive: 3.2); each costs a loop update
MAX_RESPONSE_POINTS = 10_000  # measured frequencies (rig-identify writes one per kept harmonic)

# section -> key -> (type, default, check, requirement, description [unit])
SCHEMA = {
    "rig": {
        "name": (str, "unnamed", None, "", "rig name"),
        "description": (str, "", None, "", "free text"),
        "model_step_s": (float, None, lambda x: MIN_STEP_S <= x <= MAX_STEP_S,
                         f"must lie in [{MIN_STEP_S:g}, {MAX_STEP_S:g}] s (the rig link's range of dt)",
                         "model step dt the rig runs at [s]"),
        "stated_delay_s": (float, 0.0, lambda x: x >= 0, "must be >= 0", "total delay the source states [s]"),
    },
    "height": {
        "delay_steps": (int, 0, lambda x: 0 <= x <= MAX_DELAY_STEPS, DELAY_RANGE, "pure delay to the drive [steps]"),
        "decimation": (int, 1, lambda x: 1 <= x <= MAX_DECIMATION, f"must lie in 1..{MAX_DECIMATION}",
                       "N_com: one height of every N_com sent [-]"),
        "ramp_s": (float, 0.0, lambda x: x >= 0, "must be >= 0", "drive ramp, 0 = N_com dt [s]"),
        "sub_step_s": (float, 0.0, lambda x: x >= 0, "must be >= 0", "drive sub-reference period, 0 = none [s]"),
        "servo_frequency_hz": (
            float,
            0.0,
            lambda x: x >= 0,
            "must be >= 0",
            "position loop natural frequency, 0 = ideal [Hz]",
        ),
        "servo_damping": (float, 0.7, lambda x: x > 0, "must be > 0", "position loop damping ratio [-]"),
    },
    "force": {
        "filter_hz": (float, 0.0, lambda x: x >= 0, "must be >= 0", "amplifier low-pass cut-off, 0 = none [Hz]"),
        "filter_order": (int, 2, lambda x: 1 <= x <= 8, "must be 1 to 8", "Butterworth order [-]"),
        "delay_steps": (int, 0, lambda x: 0 <= x <= MAX_DELAY_STEPS, DELAY_RANGE, "acquisition delay [steps]"),
    },
    "limits": {
        "stroke_min_m": (float, -0.12, None, "", "lowest actuator position [m]"),
        "stroke_max_m": (float, 0.12, None, "", "highest actuator position [m]"),
        "max_velocity_m_s": (float, 5.4, lambda x: x > 0, "must be > 0", "motion-profile velocity limit [m/s]"),
        "max_acceleration_m_s2": (
            float,
            300.0,
            lambda x: x > 0,
            "must be > 0",
            "motion-profile acceleration limit [m/s^2]",
        ),
    },
    "response": {
        "frequencies_hz": (list, None, None, "", "measured frequencies [Hz]"),
        "height_gain": (list, None, None, "", "|actuator height / command| [-]"),
        "height_phase_deg": (list, None, None, "", "phase of actuator height / command [deg]"),
        "force_gain": (list, None, None, "", "|measured / true force| [-]"),
        "force_phase_deg": (list, None, None, "", "phase of measured / true force [deg]"),
    },
}


def _value(section: str, key: str, raw, typ):
    name = f"{section}.{key}"
    if typ is float and isinstance(raw, int) and not isinstance(raw, bool):
        raw = float(raw)
    if typ is list:
        if not isinstance(raw, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in raw):
            raise RigFileError(f"{name}: expected a list of numbers, got {raw!r}")
        if not all(math.isfinite(v) for v in raw):
            raise RigFileError(f"{name}: every value must be finite")
        return [float(v) for v in raw]
    if not isinstance(raw, typ) or isinstance(raw, bool):
        raise RigFileError(f"{name}: expected {typ.__name__}, got {raw!r}")
    if typ is float and not math.isfinite(raw):
        raise RigFileError(f"{name}: must be finite, got {raw!r}")
    return raw


def _validated(raw: dict) -> dict:
    for section in raw:
        if section not in SCHEMA:
            raise RigFileError(f"{section}: unknown section (known: {', '.join(SCHEMA)})")
        if not isinstance(raw[section], dict):
            raise RigFileError(f"{section}: expected a table of keys")
    out = {}
    for section, keys in SCHEMA.items():
        given = raw.get(section, {})
        for key in given:
            if key not in keys:
                raise RigFileError(f"{section}.{key}: unknown key (known: {', '.join(keys)})")
        out[section] = {}
        for key, (typ, default, check, req, _doc) in keys.items():
            if key not in given:
                if default is None and section == "rig":
                    raise RigFileError(f"{section}.{key}: missing (required)")
                out[section][key] = default
                continue
            value = _value(section, key, given[key], typ)
            if check is not None and not check(value):
                raise RigFileError(f"{section}.{key}: {req} (got {value!r})")
            out[section][key] = value
    return out


def _measured(resp: dict) -> MeasuredResponse | None:
    given = {k: v for k, v in resp.items() if v is not None}
    if not given:
        return None
    missing = [k for k in SCHEMA["response"] if k not in given]
    if missing:
        raise RigFileError(
            f"response.{missing[0]}: missing (the response needs all of {', '.join(SCHEMA['response'])})"
        )
    n = len(given["frequencies_hz"])
    if n > MAX_RESPONSE_POINTS:
        raise RigFileError(f"response.frequencies_hz: {n} frequencies, above the limit of {MAX_RESPONSE_POINTS}")
    for key, vals in given.items():
        if len(vals) != n:
            raise RigFileError(f"response.{key}: {len(vals)} values for {n} frequencies")
    freqs = given["frequencies_hz"]
    if n == 0 or freqs[0] <= 0 or any(b <= a for a, b in zip(freqs, freqs[1:], strict=False)):
        raise RigFileError("response.frequencies_hz: one or more frequencies > 0, increasing")
    if any(g <= 0 for g in given["height_gain"] + given["force_gain"]):
        raise RigFileError("response: every gain must be > 0")
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
    v = _validated(raw)
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
        "limits": {k: getattr(lim, k) for k in SCHEMA["limits"]},
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
