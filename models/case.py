"""Case files (TOML): loading, overrides, validation and the derived run quantities.

Every key is declared once, in models/parameters.py, with its type, default, range and unit; an unknown
key, a value out of range or an inconsistent combination raises CaseError with one line naming the key.
"""
from __future__ import annotations

import copy
import functools
import dataclasses
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pantohil.models.catenary.asm.string import AsmParameters
from pantohil.models.catenary.interface import CATENARIES
from pantohil.models.catenary.profile import DropperProfile, ProfileError, TabulatedProfile, read_profile_csv
from pantohil.models.catenary.receptance import harmonic_count
from pantohil.models.data import CASES_DIR, catalog
from pantohil.models.errors import InputError
from pantohil.models.hil.loop import HORIZON_AUTO_S, MAX_HORIZON_STEPS, HilSettings
from pantohil.models.input_files import InputFileError, TomlSyntaxError, load_toml, loads_toml
from pantohil.models.pantograph.interface import PANTOGRAPHS
from pantohil.models.pantograph.lumped import PantographParameters
from pantohil.models.parameters import (
    AUTO,
    MAX_SAMPLES_PER_SPAN,
    OPTIONAL_SECTIONS,
    SECTIONS,
    CaseSections,
    Key,
    PantographSection,
    pantograph_parameters,
    section_keys,
)
from pantohil.models.rig.chain import RigParameters
from pantohil.models.rig.drive_chain import RigSpec, frequency_response
from pantohil.models.rig.drive_chain import latency_steps as chain_latency_steps
from pantohil.models.rig.drive_chain import pattern_spans as chain_pattern_spans
from pantohil.models.rig.rig_file import RigFileError, load_rig_file
from pantohil.models.schema import FileSchema

_RIG_CHAIN_KEYS = ("delay_steps", "comm_decimation", "servo_bandwidth_hz", "servo_damping", "loadcell_cutoff_hz")
DEFAULT_CASE = CASES_DIR / "asm_250.toml"


class CaseError(InputError):
    """A case that cannot run; the message is one line naming the key."""


CASE_FILE = FileSchema("case file", SECTIONS, CaseError, optional_sections=OPTIONAL_SECTIONS,
                       reference="case-reference", to_fmus=True)
SCHEMA: dict[str, dict[str, Key]] = {section: section_keys(section) for section in SECTIONS}
"""Every case key, by section, derived from the declarations in models/parameters.py."""

_SET_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def load_case_dict(path: Path | None) -> tuple[dict, Path]:
    """Read a case file (the built-in asm_250 if none) as a dict; CaseError with one line on a bad file."""
    path = catalog.resolve(path, "case") if path is not None else DEFAULT_CASE
    try:
        return load_toml(path, "case file"), path
    except InputFileError as exc:
        bare = not path.exists() and len(path.parts) == 1
        hint = " (nor a shipped case: `pantohil cases` lists them)" if bare else ""
        raise CaseError(f"{exc}{hint}") from None


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Apply `section.key=value` overrides; values are parsed as TOML, else taken as strings."""
    out = copy.deepcopy(raw)
    for item in overrides:
        if any(ch in item for ch in "\n\r\0"):
            raise CaseError(f"override {item.splitlines()[0] if item.strip() else ''!r}...: a value must be one line")
        if "=" not in item or "." not in item.split("=", 1)[0]:
            raise CaseError(f"override {item!r}: expected section.key=value")
        dotted, value = item.split("=", 1)
        section, key = (part.strip() for part in dotted.split(".", 1))
        if not _SET_KEY.fullmatch(section) or not _SET_KEY.fullmatch(key):
            raise CaseError(f"override {item!r}: expected section.key=value with plain names")
        parsed = _override_value(item, f"{section}.{key}", value.strip())
        table = out.setdefault(section, {})
        if not isinstance(table, dict):
            raise CaseError(f"override {item!r}: {section} is not a table in the case file (it is {table!r})")
        table[key] = parsed
    return out


def _override_value(item: str, dotted: str, value: str):
    """An override's value parsed as TOML (checked as every input file is), else taken as a string."""
    try:
        return loads_toml(f"v = {value}", "override")["v"]
    except TomlSyntaxError:
        return value
    except InputFileError as exc:
        message = str(exc).removeprefix("override: ")
        if message.startswith("v"):
            message = dotted + message[1:]
        raise CaseError(f"override {item[:60]!r}: {message}") from None


def validate(raw: dict) -> dict:
    """Fill defaults and check every key against its declaration; returns {section: {key: value}}."""
    return CASE_FILE.validate(raw)


@dataclass
class Case:
    """A validated case with everything the run derives from it."""

    name: str
    source: Path
    values: dict
    catenary: AsmParameters
    pantograph: PantographParameters
    rig: RigParameters
    profile: object
    speed_m_s: float
    span_m: float
    samples_per_span: int
    dt_s: float
    n_harmonics: int
    hil_update: str
    relaxation: float
    ramp_steps: int
    delay_compensation: bool
    delay_override: int | None  # None: automatic (hil.delay_steps = "auto")
    model: str = "asm"
    definition_path: Path | None = None
    rig_spec: RigSpec | None = None  # the rig file's chain, if the case names one
    rig_compensation: str = "delay"
    overrides: tuple = ()  # the `section.key=value` overrides given on top of the case file

    @functools.cached_property
    def sections(self) -> CaseSections:
        """The validated case as its typed sections: `case.sections.run.max_spans`."""
        return CaseSections.of(self.values)

    @property
    def title(self) -> str:
        """The case's name with its overrides, for plot titles: `asm_250 [hil.update=span]`."""
        return f"{self.name} [{', '.join(self.overrides)}]" if self.overrides else self.name

    @property
    def compensates_rig_response(self) -> bool:
        """Whether the rig file's response is compensated harmonic by harmonic (rig_compensation "response")."""
        return self.rig_spec is not None and self.rig_compensation == "response" and self.delay_compensation

    def rig_latency_steps(self) -> int:
        """The rig's latency in whole steps (its low-frequency group delay, rounded)."""
        if self.rig_spec is not None:
            return chain_latency_steps(self.rig_spec, self.dt_s)
        return self.rig.latency_steps(self.dt_s)

    def rig_period_spans(self) -> int:
        """Spans after which the steady state repeats (the rig's clocks against the span)."""
        if self.rig_spec is None:
            return 1
        return chain_pattern_spans(self.rig_spec, self.dt_s, self.samples_per_span)

    def rig_response(self, n_harmonics: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The rig's gains at the kept harmonics (or at harmonics 0..n_harmonics-1): the rig file's measured
        response, else its model's."""
        n_h = self.n_harmonics if n_harmonics is None else n_harmonics
        if self.rig_spec.measured is not None:
            freqs = np.arange(n_h) / (self.samples_per_span * self.dt_s)
            gz, gf = self.rig_spec.measured.at(freqs[1:])
            return np.concatenate([[1.0], gz]), np.concatenate([[1.0], gf])
        return frequency_response(self.rig_spec, self.dt_s, self.samples_per_span, n_h)

    def pfem_settings(self):
        """The discretisation of this case's PFEM operators (Paper C sec. 3, Paper D sec. 3.5/3.7)."""
        from pantohil.models.catenary.pfem.operators import PfemSettings

        p = self.sections.pfem
        return PfemSettings(self.speed_m_s, self.dt_s, self.samples_per_span, self.n_harmonics,
                            harmonic_count(p.dropper_max_frequency_hz, self.samples_per_span, self.dt_s),
                            p.omega_max_rad_s, "graded", p.grid_resolution, taper=p.taper)

    @property
    def speed_kmh(self) -> float:
        """Pantograph speed [km/h]."""
        return self.speed_m_s * 3.6

    def hil_settings(self, delay_steps: int) -> HilSettings:
        """The case's HIL settings with delay advance D = delay_steps (Paper D sec. 3)."""
        return HilSettings(update=self.hil_update, relaxation=self.relaxation, delay_steps=delay_steps,
                           ramp_steps=self.ramp_steps, hold_steps=self.hold_steps)

    def sample_positions_m(self) -> np.ndarray:
        """Position x of the contact point at each of the N samples of a span [m]."""
        return np.arange(self.samples_per_span) * self.speed_m_s * self.dt_s

    def z0_samples(self) -> np.ndarray:
        """Static contact-wire height z0 at the N samples of a span [m]."""
        return self.profile.heights(self.sample_positions_m())

    def refuse_second_pantograph(self, what: str) -> None:
        """CaseError for a case with a [second_pantograph] given to `what`, which runs one pantograph: a
        result that leaves the second out is not the case's."""
        if self.sections.second_pantograph is not None:
            raise CaseError(f"second_pantograph: {what} runs one pantograph; this case has two (two run in "
                            "`pantohil run`, a virtual HIL of FMUs, in `pantohil direct`, `pantohil stability` and "
                            "`pantohil fem-sim`)",
                            key="second_pantograph")

    def reference_height_m(self) -> float:
        """Wire height at which the pantograph's static force equals the uplift force: the mean
        converged height z0_mean + H(0) F_m (the catenary model's static compliance), so that the
        converged mean force is F_m."""
        h0 = CATENARIES.get(self.model, "catenary.model").static_compliance_m_N(self)
        return float(np.mean(self.z0_samples())) + h0 * self.pantograph.uplift_force_N

    @property
    def hold_steps(self) -> int:
        """The extra loop delay E of hil.hold_steps [steps] (Paper D sec. 4)."""
        return int(self.sections.hil.hold_steps)

    @property
    def horizon_steps(self) -> int:
        """H of link.horizon_steps: the heights each answer carries for the rig's next ticks; "auto": the
        steps of HORIZON_AUTO_S, at most MAX_HORIZON_STEPS (docs/udp-protocol.md)."""
        value = self.sections.link.horizon_steps
        if value == AUTO:
            return min(MAX_HORIZON_STEPS, math.ceil(HORIZON_AUTO_S / self.dt_s - 1e-9))
        return int(value)

    def delay_steps(self, loop_steps: int) -> int:
        """Delay advance D = loop latency of the master's connections + the extra delay E + the rig's latency."""
        if self.delay_override is not None:
            return self.delay_override
        if not self.delay_compensation:
            return loop_steps
        if self.compensates_rig_response:
            return loop_steps + self.hold_steps  # the rig's own delays are in its compensated response
        return loop_steps + self.hold_steps + self.rig_latency_steps()


def mean_force_en50367(speed_kmh: float) -> float:
    """EN 50367 AC target mean force F_m = 0.00097 v^2 + 70 N, v in km/h (Paper A eq. 37, corrected)."""
    return 0.00097 * speed_kmh**2 + 70.0


def _check_pantograph(v: dict) -> PantographParameters:
    p = v["pantograph"]
    names = ("masses_kg", "stiffnesses_N_m", "dampings_Ns_m")
    if PANTOGRAPHS.get(p["model"], "pantograph.model").fixed_to_actuator:
        if len(p["masses_kg"]) != 1:
            raise CaseError(f"pantograph.masses_kg: a mass fixed to the actuator ({p['model']}) takes exactly one "
                            "mass")
    else:
        n = len(p["masses_kg"])
        if not 1 <= n <= 3:
            raise CaseError(f"pantograph.masses_kg: a chain has 1 to 3 masses (got {n})")
        for key in names[1:]:
            if len(p[key]) != n:
                raise CaseError(f"pantograph.{key}: needs {n} values, one per mass (got {len(p[key])})")
    for key in names:
        if any(x <= 0 for x in p[key]) if key == "masses_kg" else any(x < 0 for x in p[key]):
            bound = "> 0" if key == "masses_kg" else ">= 0"
            raise CaseError(f"pantograph.{key}: every value must be {bound} (got {p[key]})")
    section = PantographSection(**{k: tuple(x) if isinstance(x, list) else x for k, x in p.items()})
    return pantograph_parameters(section, mean_force_en50367(v["run"]["speed_kmh"]))


def _analysis(case_path: Path, name: str, key: str):
    from pantohil.models.catenary.fe.analysis import cached_analysis
    from pantohil.models.catenary.fe.definition import CatenaryError

    try:
        return cached_analysis(case_path.parent / name)
    except CatenaryError as exc:
        raise CaseError(f"{key}: {exc}") from None


def _fill_from_definition(raw: dict, source: Path) -> dict:
    """[catenary] definition_file: take the ASM2 data not given in the case from the file's fit
    (Paper A sec. 4), and z0 from its form-finding unless [profile] says otherwise."""
    cat = raw.get("catenary", {})
    name = cat.get("definition_file")
    if not name:
        return raw
    if not isinstance(name, str):
        raise CaseError(f"catenary.definition_file: expected a file name, got {name!r}")
    a = _analysis(source, name, "catenary.definition_file")
    fitted = {"span_m": a.span_m, "tension_N": a.contact_tension_N, "density_kg_m": a.fitted_density_kg_m,
              "support_stiffness_N_m2": a.support_stiffness_N_m2, "alpha_1_s": a.alpha_1_s, "beta_s": a.beta_s}
    out = copy.deepcopy(raw)
    out["catenary"] = {**fitted, **cat}
    if "profile" not in raw:
        out["profile"] = {"source": "catenary", "catenary_file": name}
    return out


def _check_profile(v: dict, case_path: Path):
    pr, span = v["profile"], v["catenary"]["span_m"]
    if pr["source"] == "catenary":
        if not pr["catenary_file"]:
            raise CaseError("profile.catenary_file: required when profile.source = \"catenary\"")
        a = _analysis(case_path, pr["catenary_file"], "profile.catenary_file")
        if abs(a.span_m - span) > 1e-9 * span:
            raise CaseError(f"profile.catenary_file: its span ({a.span_m:g} m) is not catenary.span_m ({span:g} m)")
        return TabulatedProfile(span, np.array(a.profile_x_m), np.array(a.profile_z_m))
    if pr["source"] == "csv":
        if not pr["csv_file"]:
            raise CaseError("profile.csv_file: required when profile.source = \"csv\"")
        try:
            return read_profile_csv(case_path.parent / pr["csv_file"], span)
        except ProfileError as exc:
            raise CaseError(f"profile.csv_file: {exc}") from None
    spacing = pr["dropper_spacing_m"]
    if len(spacing) < 2 or any(s <= 0 for s in spacing):
        raise CaseError("profile.dropper_spacing_m: needs at least two positive intervals")
    if abs(sum(spacing) - span) > 1e-6 * span:
        raise CaseError(f"profile.dropper_spacing_m: intervals sum to {sum(spacing):g} m, not the span {span:g} m")
    tension = pr["wire_tension_N"] or v["catenary"]["tension_N"]
    return DropperProfile(span, tuple(np.cumsum(spacing)[:-1]), pr["wire_mass_kg_m"], tension, pr["presag_m"])


def _check_rig_file(v: dict, source: Path, dt: float, given: dict) -> RigSpec | None:
    """[rig] file: the rig chain of a rig file, at the case's dt."""
    name = v["rig"]["file"]
    if not name:
        return None
    clash = [k for k in _RIG_CHAIN_KEYS if k in given]
    if clash:
        raise CaseError(f"rig.{clash[0]}: not with rig.file (the rig file describes the chain)")
    try:
        spec = load_rig_file(source.parent / name)
    except RigFileError as exc:
        raise CaseError(f"rig.file: {exc}") from None
    if abs(spec.model_step_s - dt) > 1e-6 * dt:
        raise CaseError(f"rig.file: the rig runs at dt = {spec.model_step_s:g} s; the case's step is {dt:.6g} s "
                        f"(set run.dt_s so that the span holds a whole number of rig steps)")
    return spec


def build_case(raw: dict, source: Path) -> Case:
    """Validate a parsed case (taking ASM2 data and z0 from its catenary file if it names one) into a Case.

    Adjusts dt so that a span holds a whole number of samples; CaseError names the key at fault.
    """
    v = validate(_fill_from_definition(raw, source))
    c, run, hil = v["catenary"], v["run"], v["hil"]
    cat = AsmParameters(**{f.name: c[f.name] for f in dataclasses.fields(AsmParameters)})
    speed = run["speed_kmh"] / 3.6
    if speed >= cat.wave_speed_m_s:
        raise CaseError(f"run.speed_kmh: {run['speed_kmh']:g} km/h is at or above the ASM wave speed "
                        f"sqrt(T/mu) = {cat.wave_speed_m_s * 3.6:.1f} km/h")
    span = c["span_m"]
    samples = span / (speed * run["dt_s"])
    if samples > MAX_SAMPLES_PER_SPAN:
        raise CaseError(f"run.dt_s: a span of {span:g} m at {run['speed_kmh']:g} km/h and dt = {run['dt_s']:g} s "
                        f"holds {samples:.3g} samples, above the limit of {MAX_SAMPLES_PER_SPAN} samples per span")
    n = max(2, int(round(samples)))
    dt = span / (speed * n)
    nyquist = 0.5 / dt
    if hil["max_frequency_hz"] > nyquist:
        raise CaseError(f"hil.max_frequency_hz: {hil['max_frequency_hz']:g} Hz is above the Nyquist "
                        f"frequency {nyquist:.1f} Hz of dt = {dt:.6g} s")
    pan = _check_pantograph(v)
    r = v["rig"]
    rig = RigParameters(**{k: val for k, val in r.items() if k != "file"})
    rig_spec = _check_rig_file(v, source, dt, raw.get("rig", {}))
    if rig_spec is None and rig.latency_steps(dt) >= n:
        raise CaseError(f"rig.delay_steps: the rig's latency ({rig.latency_steps(dt)} steps) must be shorter "
                        f"than a span ({n} steps)")
    delay_override = None if hil["delay_steps"] == AUTO else hil["delay_steps"]
    if delay_override is not None and delay_override >= n:
        raise CaseError(f"hil.delay_steps: {hil['delay_steps']} steps must be shorter than a span ({n} steps)")
    act = v["actuator"]
    if not act["stroke_min_m"] < act["stroke_max_m"]:
        raise CaseError(f"actuator.stroke_max_m: must be above actuator.stroke_min_m ({act['stroke_min_m']:g} m)")
    profile = _check_profile(v, source)
    model = c["model"]
    definition = (source.parent / c["definition_file"]).resolve() if c["definition_file"] else None
    case = Case(v["case"]["name"], source, v, cat, pan, rig, profile, speed, span, n, dt,
                harmonic_count(hil["max_frequency_hz"], n, dt), hil["update"], hil["relaxation"],
                hil["ramp_steps"], hil["delay_compensation"], delay_override, model, definition, rig_spec,
                hil["rig_compensation"])
    _check_measured_response(case)
    try:
        CATENARIES.get(model, "catenary.model").check(case)
    except CaseError:
        raise
    except InputError as exc:
        raise CaseError(str(exc), key=exc.key) from None
    return case


def _check_measured_response(case: Case) -> None:
    """A rig file's measured response (pantohil rig-identify) must hold every harmonic the case keeps."""
    if case.compensates_rig_response and case.rig_spec.measured is not None:
        try:
            case.rig_response()
        except ValueError as exc:
            raise CaseError(f"rig.file: {exc}") from None


def load_case(path: Path | None = None, overrides: list[str] | None = None) -> Case:
    """Load, override (`section.key=value` strings) and validate a case file into a Case."""
    raw, source = load_case_dict(path)
    return dataclasses.replace(build_case(apply_overrides(raw, overrides or []), source),
                               overrides=tuple(overrides or ()))
