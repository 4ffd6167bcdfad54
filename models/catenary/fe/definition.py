"""Catenary definition files (TOML): one span of a catenary with its wires, droppers and supports.

Every key carries its unit in its name. A wire gives either `density_kg_m3` and `area_m2` or
`linear_mass_kg_m`, and either `youngs_modulus_Pa` and `second_moment_m4` or `bending_stiffness_N_m2`.
Droppers are placed by `dropper_spacing_m` (intervals support-1, 1-2, ..., n-support, summing to the
span) or by `dropper_positions_m` (from the span's first support). Errors are one line naming the key.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pantohil.models.errors import InputError
from pantohil.models.input_files import InputFileError, load_toml


class CatenaryError(InputError):
    """A catenary file that cannot be built; one line naming the key."""


@dataclass(frozen=True)
class Wire:
    """A tensioned wire: tension, mass per length and bending stiffness EI."""
    tension_N: float
    mass_kg_m: float
    bending_stiffness_N_m2: float

    @property
    def wave_speed_m_s(self) -> float:
        """Wave speed sqrt(T / m) of the wire [m/s]."""
        return math.sqrt(self.tension_N / self.mass_kg_m)


@dataclass(frozen=True)
class CatenaryDefinition:
    """A catenary file, validated: span, encumbrance, pre-sag, droppers, wires, clamps, steady arms, damping."""
    name: str
    source: Path | None
    span_m: float
    encumbrance_m: float
    presag_m: float
    dropper_positions_m: tuple
    contact: Wire
    messenger: Wire
    stitch: Wire | None
    stitch_length_m: float
    dropper_mass_kg_m: float
    dropper_axial_stiffness_N: float  # E A
    clamp_mass_messenger_kg: float
    clamp_mass_contact_kg: float
    steady_arm_mass_kg: float
    steady_arm_stiffness_N_m: float
    messenger_support_stiffness_N_m: float  # 0: fixed
    alpha_1_s: float
    beta_s: float
    mesh_size_m: float
    values: dict
    presag_span: str = "supports"  # the pre-sag parabola runs between the "supports" or the "end_droppers"

    def design_height(self, x: np.ndarray) -> np.ndarray:
        """Design contact-wire height (negative down): the pre-sag parabola, 0 at the supports, or 0 at the
        first and last droppers and level with the supports outside them."""
        x = np.asarray(x, dtype=float)
        a, b = (0.0, self.span_m) if self.presag_span == "supports" else (self.dropper_positions_m[0],
                                                                           self.dropper_positions_m[-1])
        return -4.0 * self.presag_m * np.clip(x - a, 0, None) * np.clip(b - x, 0, None) / (b - a) ** 2

    def on_stitch(self, x: float) -> bool:
        """Does the dropper at x (within the span) hang from the stitch wire rather than the messenger?"""
        if self.stitch is None:
            return False
        half = self.stitch_length_m / 2
        return x < half or x > self.span_m - half


_SCHEMA = {
    "catenary": {"name", "description", "span_m", "encumbrance_m", "contact_height_m", "presag_m", "presag_between",
                 "dropper_spacing_m", "dropper_positions_m", "mesh_size_m", "alpha_1_s", "beta_s"},
    "contact_wire": {"tension_N", "density_kg_m3", "area_m2", "linear_mass_kg_m", "youngs_modulus_Pa",
                     "second_moment_m4", "bending_stiffness_N_m2"},
    "messenger_wire": {"tension_N", "density_kg_m3", "area_m2", "linear_mass_kg_m", "youngs_modulus_Pa",
                       "second_moment_m4", "bending_stiffness_N_m2"},
    "stitch_wire": {"length_m", "tension_N", "density_kg_m3", "area_m2", "linear_mass_kg_m", "youngs_modulus_Pa",
                    "second_moment_m4", "bending_stiffness_N_m2"},
    "droppers": {"density_kg_m3", "area_m2", "linear_mass_kg_m", "youngs_modulus_Pa", "clamp_mass_messenger_kg",
                 "clamp_mass_contact_kg"},
    "steady_arm": {"mass_kg", "stiffness_N_m"},
    "messenger_support": {"type", "stiffness_N_m"},
}


# Stated physical ranges of catenary-file keys (upper bounds; lower bounds are given where read).
UPPER_BOUNDS = {
    "span_m": 1000.0, "encumbrance_m": 10.0, "presag_m": 10.0, "mesh_size_m": 10.0, "length_m": 1000.0,
    "tension_N": 1e6, "linear_mass_kg_m": 100.0, "density_kg_m3": 1e5, "area_m2": 0.01, "youngs_modulus_Pa": 1e13,
    "second_moment_m4": 1e-3, "bending_stiffness_N_m2": 1e6, "clamp_mass_messenger_kg": 100.0,
    "clamp_mass_contact_kg": 100.0, "mass_kg": 1000.0, "stiffness_N_m": 1e9, "alpha_1_s": 100.0, "beta_s": 1.0,
}
MIN_MESH_SIZE_M = 0.05
MAX_DROPPERS = 100
# Elements of a wire in one span (span_m / mesh_size_m). The static stiffness solve of the analysis holds a
# dense block of (4 dofs x 5 spans x E) x E float64 numbers, twice: 0.3 GiB at the limit, 120 GiB at the
# documented extremes (a 1000 m span in 0.05 m elements); the shipped catenaries have 220 and 260.
MAX_ELEMENTS_PER_SPAN = 1000


def _check_elements(span: float, mesh: float) -> None:
    """Refuse a span whose mesh would need more memory than MAX_ELEMENTS_PER_SPAN allows (one line)."""
    elements = span / mesh
    if elements > MAX_ELEMENTS_PER_SPAN:
        gib = 2 * 8 * (4 * 5 * elements) * elements / 2**30
        raise CatenaryError(f"catenary.span_m / catenary.mesh_size_m: {span:g} m in elements of {mesh:g} m is "
                            f"{elements:.0f} elements per span, above the limit of {MAX_ELEMENTS_PER_SPAN} "
                            f"(the stiffness solve would take {gib:.1f} GiB)")


def _num(section: dict, sec: str, key: str, default=None, positive=False, nonneg=False) -> float:
    if key not in section:
        if default is None:
            raise CatenaryError(f"{sec}.{key}: missing (required)")
        return default
    v = section[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise CatenaryError(f"{sec}.{key}: expected a finite number, got {v!r}")
    if positive and v <= 0:
        raise CatenaryError(f"{sec}.{key}: must be > 0 (got {v!r})")
    if nonneg and v < 0:
        raise CatenaryError(f"{sec}.{key}: must be >= 0 (got {v!r})")
    high = UPPER_BOUNDS.get(key)
    if high is not None and abs(v) > high:
        raise CatenaryError(f"{sec}.{key}: {v:g} is beyond the physical range of a catenary (|value| <= {high:g})")
    return float(v)


def _number_list(c: dict, key: str, minimum: int) -> list[float]:
    values = c[key]
    if (not isinstance(values, list) or len(values) < minimum
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values)):
        raise CatenaryError(f"catenary.{key}: expected a list of at least {minimum} finite numbers [m]")
    if len(values) > MAX_DROPPERS + 1:
        raise CatenaryError(f"catenary.{key}: {len(values)} values, above the limit of {MAX_DROPPERS} droppers")
    return [float(v) for v in values]


def _wire(raw: dict, sec: str) -> Wire:
    s = raw[sec]
    tension = _num(s, sec, "tension_N", positive=True)
    if "linear_mass_kg_m" in s:
        mass = _num(s, sec, "linear_mass_kg_m", positive=True)
    elif "density_kg_m3" in s or "area_m2" in s:
        mass = _num(s, sec, "density_kg_m3", positive=True) * _num(s, sec, "area_m2", positive=True)
    else:
        raise CatenaryError(f"{sec}.linear_mass_kg_m: missing (or give density_kg_m3 and area_m2)")
    if "bending_stiffness_N_m2" in s:
        ei = _num(s, sec, "bending_stiffness_N_m2", nonneg=True)
    else:
        ei = _num(s, sec, "youngs_modulus_Pa", 0.0, nonneg=True) * _num(s, sec, "second_moment_m4", 0.0, nonneg=True)
    return Wire(tension, mass, ei)


def _presag_span(c: dict) -> str:
    v = c.get("presag_between", "supports")
    if v not in ("supports", "end_droppers"):
        raise CatenaryError(f"catenary.presag_between: must be \"supports\" or \"end_droppers\" (got {v!r})")
    return v


def _check_sections(raw: dict) -> None:
    """Every section and key known, the four required sections present."""
    for sec, body in raw.items():
        if sec not in _SCHEMA:
            raise CatenaryError(f"{sec}: unknown section (known: {', '.join(_SCHEMA)})")
        if not isinstance(body, dict):
            raise CatenaryError(f"{sec}: expected a table of keys")
        for key in body:
            if key not in _SCHEMA[sec]:
                raise CatenaryError(f"{sec}.{key}: unknown key (known: {', '.join(sorted(_SCHEMA[sec]))})")
    for sec in ("catenary", "contact_wire", "messenger_wire", "droppers"):
        if sec not in raw:
            raise CatenaryError(f"{sec}: missing section")


def _dropper_positions(c: dict, span: float) -> tuple[float, ...]:
    """Dropper positions from the span's first support, from `dropper_spacing_m` or `dropper_positions_m`."""
    if "dropper_positions_m" in c and "dropper_spacing_m" in c:
        raise CatenaryError("catenary.dropper_positions_m: give either dropper_positions_m or dropper_spacing_m")
    if "dropper_spacing_m" in c:
        spacing = _number_list(c, "dropper_spacing_m", 2)
        if any(v <= 0 for v in spacing):
            raise CatenaryError("catenary.dropper_spacing_m: overlapping droppers (an interval <= 0)")
        if abs(sum(spacing) - span) > 1e-6 * span:
            raise CatenaryError(
                f"catenary.dropper_spacing_m: intervals sum to {sum(spacing):g} m, not the span {span:g} m"
            )
        positions = tuple(float(v) for v in np.cumsum(spacing)[:-1])
    elif "dropper_positions_m" in c:
        positions = tuple(_number_list(c, "dropper_positions_m", 1))
        if any(p <= 0 or p >= span for p in positions):
            raise CatenaryError(f"catenary.dropper_positions_m: a dropper outside the span (0, {span:g}) m")
        if any(b <= a for a, b in zip(positions, positions[1:], strict=False)):
            raise CatenaryError("catenary.dropper_positions_m: overlapping droppers (positions must increase)")
    else:
        raise CatenaryError("catenary.dropper_spacing_m: missing (or give dropper_positions_m)")
    return positions


def _stitch(raw: dict, span: float) -> tuple[Wire | None, float]:
    """The stitch wire and its length, or (None, 0) without one."""
    if "stitch_wire" not in raw:
        return None, 0.0
    stitch = _wire(raw, "stitch_wire")
    stitch_len = _num(raw["stitch_wire"], "stitch_wire", "length_m", positive=True)
    if stitch_len >= span:
        raise CatenaryError(f"stitch_wire.length_m: must be shorter than the span ({span:g} m)")
    return stitch, stitch_len


def build_definition(raw: dict, source: Path | None = None) -> CatenaryDefinition:
    """A catenary definition from the parsed TOML of a catenary file; CatenaryError naming the key."""
    _check_sections(raw)
    c = raw["catenary"]
    span = _num(c, "catenary", "span_m", positive=True)
    positions = _dropper_positions(c, span)
    d = raw["droppers"]
    if "linear_mass_kg_m" in d:
        dmass = _num(d, "droppers", "linear_mass_kg_m", positive=True)
    else:
        dmass = _num(d, "droppers", "density_kg_m3", positive=True) * _num(d, "droppers", "area_m2", positive=True)
    ea = _num(d, "droppers", "youngs_modulus_Pa", 1.1e11, positive=True) * _num(
        d, "droppers", "area_m2", 10e-6, positive=True
    )
    stitch, stitch_len = _stitch(raw, span)
    sa = raw.get("steady_arm", {})
    ms = raw.get("messenger_support", {})
    support_type = ms.get("type", "fixed")
    if support_type not in ("fixed", "spring"):
        raise CatenaryError(f"messenger_support.type: must be \"fixed\" or \"spring\" (got {support_type!r})")
    k_support = _num(ms, "messenger_support", "stiffness_N_m", positive=True) if support_type == "spring" else 0.0
    mesh = _num(c, "catenary", "mesh_size_m", 0.25, positive=True)
    if mesh < MIN_MESH_SIZE_M:
        raise CatenaryError(f"catenary.mesh_size_m: {mesh:g} m is below the limit of {MIN_MESH_SIZE_M:g} m")
    _check_elements(span, mesh)
    if mesh > min(np.diff((0.0, *positions, span))):
        raise CatenaryError(f"catenary.mesh_size_m: {mesh:g} m is longer than the shortest dropper interval")
    return CatenaryDefinition(
        name=str(c.get("name", source.stem if source else "catenary")), source=source, span_m=span,
        encumbrance_m=_num(c, "catenary", "encumbrance_m", positive=True),
        presag_m=_num(c, "catenary", "presag_m", 0.0), dropper_positions_m=positions,
        presag_span=_presag_span(c),
        contact=_wire(raw, "contact_wire"), messenger=_wire(raw, "messenger_wire"), stitch=stitch,
        stitch_length_m=stitch_len, dropper_mass_kg_m=dmass, dropper_axial_stiffness_N=ea,
        clamp_mass_messenger_kg=_num(d, "droppers", "clamp_mass_messenger_kg", 0.0, nonneg=True),
        clamp_mass_contact_kg=_num(d, "droppers", "clamp_mass_contact_kg", 0.0, nonneg=True),
        steady_arm_mass_kg=_num(sa, "steady_arm", "mass_kg", 0.0, nonneg=True),
        steady_arm_stiffness_N_m=_num(sa, "steady_arm", "stiffness_N_m", 0.0, nonneg=True),
        messenger_support_stiffness_N_m=k_support,
        alpha_1_s=_num(c, "catenary", "alpha_1_s", 0.0125, nonneg=True),
        beta_s=_num(c, "catenary", "beta_s", 1e-4, nonneg=True), mesh_size_m=mesh, values=raw)


def load_definition(path: Path) -> CatenaryDefinition:
    """Read and validate a catenary file (TOML); CatenaryError with one line on any fault."""
    path = Path(path)
    try:
        raw = load_toml(path, "catenary file")
    except InputFileError as exc:
        raise CatenaryError(str(exc)) from None
    return build_definition(raw, path)
