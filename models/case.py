"""Case files (TOML): loading, `--set` overrides, validation and the derived run quantities.

Every key is declared once in SCHEMA with its type, default, range and unit; an unknown key, a value
out of range or an inconsistent combination raises CaseError with one line naming the key.
"""
from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pantohil.models.catenary.asm.string import AsmParameters, receptance_direct
from pantohil.models.hil.loop import UPDATES, HilSettings
from pantohil.models.pantograph.lumped import PantographParameters
from pantohil.models.catenary.profile import DropperProfile, ProfileError, TabulatedProfile, read_profile_csv
from pantohil.models.catenary.receptance import harmonic_count
from pantohil.models.data import CASES_DIR
from pantohil.models.rig.chain import RigParameters

DEFAULT_CASE = CASES_DIR / "asm_250.toml"


class CaseError(ValueError):
    """A case that cannot run; the message is one line naming the key."""


def _pos(x):
    return x > 0


def _nonneg(x):
    return x >= 0


def _unit(x):
    return 0 < x <= 1


_REQUIRED = object()

# section -> key -> (type, default, check, requirement text, unit/description)
SCHEMA = {
    "case": {
        "name": (str, "unnamed", None, "", "case name"),
        "description": (str, "", None, "", "free text"),
    },
    "catenary": {
        "model": (str, "asm", lambda s: s in ("asm", "pfem"), "must be \"asm\" or \"pfem\"", "catenary model"),
        "definition_file": (str, "", None, "", "catenary file (relative to the case): ASM2 fitted to its FE model, "
                            "or the span of the PFEM"),
        "span_m": (float, _REQUIRED, _pos, "must be > 0", "span length [m]"),
        "tension_N": (float, _REQUIRED, _pos, "must be > 0", "contact-wire tension T [N]"),
        "density_kg_m": (float, _REQUIRED, _pos, "must be > 0", "string linear density mu [kg/m]"),
        "support_stiffness_N_m2": (float, _REQUIRED, _pos, "must be > 0", "support stiffness kbar [N/m^2]"),
        "alpha_1_s": (float, 0.0125, _nonneg, "must be >= 0", "Rayleigh alpha [1/s]"),
        "beta_s": (float, 1e-4, _nonneg, "must be >= 0", "Rayleigh beta [s]"),
    },
    "profile": {
        "source": (str, "droppers", lambda s: s in ("droppers", "csv", "catenary"),
                   "must be \"droppers\", \"csv\" or \"catenary\"", "where z0 comes from"),
        "catenary_file": (str, "", None, "", "catenary file whose form-found z0 to use, relative to the case"),
        "dropper_spacing_m": (list, [], None, "", "intervals support-dropper-...-support [m]"),
        "wire_mass_kg_m": (float, 1.374, _pos, "must be > 0", "contact-wire mass per length [kg/m]"),
        "wire_tension_N": (float, 0.0, _nonneg, "must be >= 0", "tension for the sag (0: catenary.tension_N) [N]"),
        "presag_m": (float, 0.0, None, "", "mid-span pre-sag [m]"),
        "csv_file": (str, "", None, "", "x_m,z0_m file, relative to the case file"),
    },
    "pantograph": {
        "model": (str, "chain", lambda s: s in ("chain", "rigid_mass"), "must be \"chain\" or \"rigid_mass\"",
                  "pantograph model"),
        "masses_kg": (list, [6.6, 5.8, 5.8], None, "", "masses, head first [kg]"),
        "stiffnesses_N_m": (list, [7000.0, 14100.0, 80.0], None, "", "element stiffnesses [N/m]"),
        "dampings_Ns_m": (list, [0.0, 0.0, 70.0], None, "", "element dampings [N s/m]"),
        "contact_stiffness_N_m": (float, 50000.0, _pos, "must be > 0", "penalty stiffness k_c [N/m]"),
        "uplift_force_N": (float, -1.0, None, "", "uplift force; omit for 0.00097 v^2 + 70 [N]"),
        "gravity_m_s2": (float, 0.0, _nonneg, "must be >= 0", "gravity felt by a rigid mass [m/s^2]"),
    },
    "rig": {
        "delay_steps": (int, 0, _nonneg, "must be >= 0", "pure delay [steps]"),
        "comm_decimation": (int, 1, _pos, "must be >= 1", "N_com [-]"),
        "servo_bandwidth_hz": (float, 0.0, _nonneg, "must be >= 0", "servo natural frequency, 0 = ideal [Hz]"),
        "servo_damping": (float, 0.7, _pos, "must be > 0", "servo damping ratio [-]"),
        "loadcell_cutoff_hz": (float, 0.0, _nonneg, "must be >= 0", "load-cell low-pass, 0 = none [Hz]"),
        "force_offset_N": (float, 0.0, None, "", "force added to the measurement [N]"),
        "noise_std_N": (float, 0.0, _nonneg, "must be >= 0", "measurement noise std [N]"),
        "noise_seed": (int, 0, _nonneg, "must be >= 0", "noise seed [-]"),
    },
    "link": {
        "receive_timeout_s": (float, 0.0003, _pos, "must be > 0", "how long a step waits for the awaited answer [s]"),
        "pipeline_steps": (int, 1, lambda p: p in (0, 1), "must be 0 or 1",
                           "1: use the answer to the previous command (no waiting on the network) [steps]"),
        "tolerated_losses": (int, 50, _nonneg, "must be >= 0", "consecutive missing answers before a fault [-]"),
        "local_port": (int, 0, lambda p: 0 <= p < 65536, "must be a port number (0: any)", "local UDP port [-]"),
    },
    "actuator": {
        "stroke_min_m": (float, -0.12, None, "", "lowest actuator position [m]"),
        "stroke_max_m": (float, 0.12, None, "", "highest actuator position [m]"),
        "max_velocity_m_s": (float, 5.4, _pos, "must be > 0", "velocity limit (LinMot PS10-70x240U) [m/s]"),
        "max_acceleration_m_s2": (float, 300.0, _pos, "must be > 0", "acceleration limit [m/s^2]"),
    },
    "hil": {
        "update": (str, "step", lambda s: s in UPDATES, "must be \"step\" or \"span\"", "update strategy"),
        "relaxation": (float, 0.1, _unit, "must be in (0, 1]", "mu_c [-]"),
        "max_frequency_hz": (float, 25.0, _pos, "must be > 0", "f_max of the frequency reduction [Hz]"),
        "ramp_steps": (int, 0, _nonneg, "must be >= 0", "initial ramp N_r [steps]"),
        "delay_compensation": (bool, True, None, "", "advance the height by the rig's latency"),
        "delay_steps": (int, -1, None, "", "override the delay advance D; omit to compute it [steps]"),
    },
    "pfem": {
        "droppers": (bool, True, None, "", "dropper slackening (Paper C sec. 5); false: the linear catenary"),
        "dropper_max_frequency_hz": (float, 20.0, _pos, "must be > 0", "f_max of the elongations, N_hd [Hz]"),
        "dropper_relaxation": (float, 1.0, _unit, "must be in (0, 1]", "mu_d [-]"),
        "omega_max_rad_s": (float, 750.0, _pos, "must be > 0", "highest frequency of the transform [rad/s]"),
        "grid_resolution": (float, 0.094, _pos, "must be > 0", "frequency step / (alpha + beta w^2) [-]"),
        "taper": (float, 0.25, lambda x: 0 <= x < 1, "must be in [0, 1)", "tapered top fraction of [0, w_max] [-]"),
    },
    "run": {
        "speed_kmh": (float, _REQUIRED, _pos, "must be > 0", "pantograph speed [km/h]"),
        "dt_s": (float, 0.001, _pos, "must be > 0", "target time step; adjusted to fit the span [s]"),
        "max_spans": (int, 200, _pos, "must be >= 1", "span limit [-]"),
        "convergence_tol": (float, 1e-4, _pos, "must be > 0", "rms span-to-span change / std [-]"),
        "force_limit_N": (float, 2000.0, _pos, "must be > 0", "|force| beyond this is divergence [N]"),
        "height_limit_m": (float, 1.0, _pos, "must be > 0", "|height| beyond this is divergence [m]"),
        "divergence_change": (float, 0.8, _pos, "must be > 0", "median span-to-span change / std beyond which "
                              "the iteration has diverged (a limit cycle with contact loss) [-]"),
        "divergence_spans": (int, 10, _pos, "must be > 0", "spans over which that median is taken [-]"),
    },
}


def load_case_dict(path: Path | None) -> tuple[dict, Path]:
    path = Path(path) if path is not None else DEFAULT_CASE
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise CaseError(f"case file {path} does not exist") from None
    except OSError as exc:
        raise CaseError(f"case file {path}: {exc.strerror}") from None
    try:
        return tomllib.loads(text), path
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(f"case file {path} is not valid TOML: {exc}") from None


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Apply `section.key=value` overrides; values are parsed as TOML, else taken as strings."""
    out = copy.deepcopy(raw)
    for item in overrides:
        if "=" not in item or "." not in item.split("=", 1)[0]:
            raise CaseError(f"--set {item!r}: expected section.key=value")
        dotted, value = item.split("=", 1)
        section, key = dotted.strip().split(".", 1)
        try:
            parsed = tomllib.loads(f"v = {value.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            parsed = value.strip()
        out.setdefault(section, {})[key] = parsed
    return out


def _coerce(section: str, key: str, value, typ):
    name = f"{section}.{key}"
    if typ is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise CaseError(f"{name}: expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise CaseError(f"{name}: must be finite, got {value!r}")
        return value
    if typ is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise CaseError(f"{name}: expected an integer, got {value!r}")
        return value
    if typ is bool and not isinstance(value, bool):
        raise CaseError(f"{name}: expected true or false, got {value!r}")
    if typ is str and not isinstance(value, str):
        raise CaseError(f"{name}: expected a string, got {value!r}")
    if typ is list:
        if not isinstance(value, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            raise CaseError(f"{name}: expected a list of numbers, got {value!r}")
        return [float(v) for v in value]
    return value


def validate(raw: dict) -> dict:
    """Fill defaults and check every key against SCHEMA; returns {section: {key: value}}."""
    for section in raw:
        if section not in SCHEMA:
            raise CaseError(f"{section}: unknown section (known: {', '.join(SCHEMA)})")
        if not isinstance(raw[section], dict):
            raise CaseError(f"{section}: expected a table of keys")
    out = {}
    for section, keys in SCHEMA.items():
        given = raw.get(section, {})
        for key in given:
            if key not in keys:
                raise CaseError(f"{section}.{key}: unknown key (known: {', '.join(keys)})")
        out[section] = {}
        for key, (typ, default, check, req, _doc) in keys.items():
            if key in given:
                value = _coerce(section, key, given[key], typ)
            elif default is _REQUIRED:
                raise CaseError(f"{section}.{key}: missing (required)")
            else:
                value = copy.deepcopy(default)
            if check is not None and key in given and not check(value):
                raise CaseError(f"{section}.{key}: {req} (got {value!r})")
            out[section][key] = value
    return out


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
    delay_override: int
    model: str = "asm"
    definition_path: Path | None = None

    def pfem_settings(self):
        """The discretisation of this case's PFEM operators (Paper C sec. 3, Paper D sec. 3.5/3.7)."""
        from pantohil.models.catenary.pfem.operators import PfemSettings

        p = self.values["pfem"]
        return PfemSettings(self.speed_m_s, self.dt_s, self.samples_per_span, self.n_harmonics,
                            harmonic_count(p["dropper_max_frequency_hz"], self.samples_per_span, self.dt_s),
                            p["omega_max_rad_s"], "graded", p["grid_resolution"], taper=p["taper"])

    @property
    def speed_kmh(self) -> float:
        return self.speed_m_s * 3.6

    def hil_settings(self, delay_steps: int) -> HilSettings:
        return HilSettings(self.hil_update, self.relaxation, delay_steps, self.ramp_steps)

    def sample_positions_m(self) -> np.ndarray:
        return np.arange(self.samples_per_span) * self.speed_m_s * self.dt_s

    def z0_samples(self) -> np.ndarray:
        return self.profile.heights(self.sample_positions_m())

    def reference_height_m(self) -> float:
        """Wire height at which the pantograph's static force equals the uplift force: the mean
        converged height z0_mean + H11(0) F_m, so that the converged mean force is F_m."""
        h0 = float(np.real(receptance_direct(self.catenary, 0.0, self.speed_m_s)))
        return float(np.mean(self.z0_samples())) + h0 * self.pantograph.uplift_force_N

    def delay_steps(self, loop_steps: int) -> int:
        """Delay advance D = loop latency of the master's connections + the rig's latency."""
        if self.delay_override >= 0:
            return self.delay_override
        rig = self.rig.latency_steps(self.dt_s) if self.delay_compensation else 0
        return loop_steps + rig


def mean_force_en50367(speed_kmh: float) -> float:
    """EN 50367 AC target mean force F_m = 0.00097 v^2 + 70 N, v in km/h (Paper A eq. 37, corrected)."""
    return 0.00097 * speed_kmh**2 + 70.0


def _check_pantograph(v: dict) -> PantographParameters:
    p = v["pantograph"]
    names = ("masses_kg", "stiffnesses_N_m", "dampings_Ns_m")
    if p["model"] == "rigid_mass":
        if len(p["masses_kg"]) != 1:
            raise CaseError("pantograph.masses_kg: a rigid mass takes exactly one mass")
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
    uplift = p["uplift_force_N"] if p["uplift_force_N"] >= 0 else mean_force_en50367(v["run"]["speed_kmh"])
    n = len(p["masses_kg"])
    return PantographParameters(tuple(p["masses_kg"]), tuple(p["stiffnesses_N_m"][:n] or [0.0]),
                                tuple(p["dampings_Ns_m"][:n] or [0.0]), p["contact_stiffness_N_m"],
                                uplift, p["model"], p["gravity_m_s2"])


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


def build_case(raw: dict, source: Path) -> Case:
    v = validate(_fill_from_definition(raw, source))
    c, run, hil = v["catenary"], v["run"], v["hil"]
    cat = AsmParameters(c["tension_N"], c["density_kg_m"], c["support_stiffness_N_m2"], c["alpha_1_s"], c["beta_s"])
    speed = run["speed_kmh"] / 3.6
    if speed >= cat.wave_speed_m_s:
        raise CaseError(f"run.speed_kmh: {run['speed_kmh']:g} km/h is at or above the ASM wave speed "
                        f"sqrt(T/mu) = {cat.wave_speed_m_s * 3.6:.1f} km/h")
    span = c["span_m"]
    n = max(2, int(round(span / (speed * run["dt_s"]))))
    dt = span / (speed * n)
    nyquist = 0.5 / dt
    if hil["max_frequency_hz"] > nyquist:
        raise CaseError(f"hil.max_frequency_hz: {hil['max_frequency_hz']:g} Hz is above the Nyquist "
                        f"frequency {nyquist:.1f} Hz of dt = {dt:.6g} s")
    pan = _check_pantograph(v)
    r = v["rig"]
    rig = RigParameters(r["delay_steps"], r["comm_decimation"], r["servo_bandwidth_hz"], r["servo_damping"],
                        r["loadcell_cutoff_hz"], r["force_offset_N"], r["noise_std_N"], r["noise_seed"])
    if rig.latency_steps(dt) >= n:
        raise CaseError(f"rig.delay_steps: the rig's latency ({rig.latency_steps(dt)} steps) must be shorter "
                        f"than a span ({n} steps)")
    if hil["delay_steps"] >= n:
        raise CaseError(f"hil.delay_steps: {hil['delay_steps']} steps must be shorter than a span ({n} steps)")
    act = v["actuator"]
    if not act["stroke_min_m"] < act["stroke_max_m"]:
        raise CaseError(f"actuator.stroke_max_m: must be above actuator.stroke_min_m ({act['stroke_min_m']:g} m)")
    profile = _check_profile(v, source)
    model, definition = c["model"], None
    if model == "pfem":
        if not c["definition_file"]:
            raise CaseError("catenary.definition_file: required when catenary.model = \"pfem\" (the span to model)")
        definition = (source.parent / c["definition_file"]).resolve()
        _analysis(source, c["definition_file"], "catenary.definition_file")  # a readable, form-findable file
        if v["pfem"]["omega_max_rad_s"] > math.pi / dt:
            raise CaseError(f"pfem.omega_max_rad_s: {v['pfem']['omega_max_rad_s']:g} rad/s is above the Nyquist "
                            f"frequency pi/dt = {math.pi / dt:.1f} rad/s")
    return Case(v["case"]["name"], source, v, cat, pan, rig, profile, speed, span, n, dt,
                harmonic_count(hil["max_frequency_hz"], n, dt), hil["update"], hil["relaxation"],
                hil["ramp_steps"], hil["delay_compensation"], hil["delay_steps"], model, definition)


def load_case(path: Path | None = None, overrides: list[str] | None = None) -> Case:
    raw, source = load_case_dict(path)
    return build_case(apply_overrides(raw, overrides or []), source)
