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
from pantohil.models.schema import REQUIRED, FileSchema, param


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
    dropper_heights_m: tuple | None = None  # design heights at the droppers, in place of the pre-sag parabola

    def design_height(self, x: np.ndarray) -> np.ndarray:
        """Design contact-wire height (negative down): the pre-sag parabola, 0 at the supports, or 0 at the
        first and last droppers and level with the supports outside them; or, given, the heights at the
        droppers, 0 at the supports and straight between (form-finding holds the droppers' points only)."""
        x = np.asarray(x, dtype=float)
        if self.dropper_heights_m is not None:
            return np.interp(x, (0.0, *self.dropper_positions_m, self.span_m), (0.0, *self.dropper_heights_m, 0.0))
        a, b = (0.0, self.span_m) if self.presag_span == "supports" else (self.dropper_positions_m[0],
                                                                           self.dropper_positions_m[-1])
        return -4.0 * self.presag_m * np.clip(x - a, 0, None) * np.clip(b - x, 0, None) / (b - a) ** 2

    def on_stitch(self, x: float) -> bool:
        """Does the dropper at x (within the span) hang from the stitch wire rather than the messenger?"""
        if self.stitch is None:
            return False
        half = self.stitch_length_m / 2
        return x < half or x > self.span_m - half


MIN_MESH_SIZE_M = 0.05
MAX_DROPPERS = 100
# Elements of a wire in one span (span_m / mesh_size_m). The static stiffness solve of the analysis holds a
# dense block of (4 dofs x 5 spans x E) x E float64 numbers, twice: 0.3 GiB at the limit, 120 GiB at the
# documented extremes (a 1000 m span in 0.05 m elements); the shipped catenaries have 220 and 260.
MAX_ELEMENTS_PER_SPAN = 1000


@dataclass(frozen=True)
class SpanSection:
    """[catenary]: the span, its droppers, the contact wire's pre-sag, the mesh and the damping."""

    name: str = param("", "1", "catenary name (empty: the file's name)")
    description: str = param("", "1", "free text")
    span_m: float = param(REQUIRED, "m", "span length", 0.0, 1000.0, low_open=True)
    encumbrance_m: float = param(REQUIRED, "m", "height of the messenger above the contact wire at the supports",
                                 0.0, 10.0, low_open=True)
    presag_m: float = param(0.0, "m", "contact-wire pre-sag at mid-span (negative: hogging)", -10.0, 10.0)
    presag_between: str = param("supports", "1", "the pre-sag parabola runs between the supports, or between the "
                                                 "first and last droppers (level outside them)",
                                choices=("supports", "end_droppers"))
    dropper_spacing_m: tuple = param(None, "m", "intervals support-1, 1-2, ..., n-support, summing to the span "
                                                "(or dropper_positions_m)", 0.0, 1000.0, low_open=True,
                                     max_items=MAX_DROPPERS + 1)
    dropper_positions_m: tuple = param(None, "m", "dropper positions from the span's first support, increasing "
                                                  "(or dropper_spacing_m)", 0.0, 1000.0, low_open=True,
                                       max_items=MAX_DROPPERS)
    contact_wire_heights_m: tuple = param(None, "m", "design contact-wire height at each dropper, in dropper order, "
                                                     "relative to the supports (negative: below); in place of "
                                                     "presag_m", -10.0, 10.0, max_items=MAX_DROPPERS)
    mesh_size_m: float = param(0.25, "m", "element length, at most the shortest dropper interval", MIN_MESH_SIZE_M,
                               10.0)
    alpha_1_s: float = param(0.0125, "1/s", "Rayleigh alpha", 0.0, 100.0)
    beta_s: float = param(1e-4, "s", "Rayleigh beta", 0.0, 1.0)


@dataclass(frozen=True)
class WireSection:
    """[contact_wire], [messenger_wire]: a tensioned wire; its mass as linear_mass_kg_m or density_kg_m3 x
    area_m2, its bending stiffness as bending_stiffness_N_m2 or youngs_modulus_Pa x second_moment_m4."""

    tension_N: float = param(REQUIRED, "N", "tension", 0.0, 1e6, low_open=True)
    linear_mass_kg_m: float = param(None, "kg/m", "mass per length", 0.0, 100.0, low_open=True)
    density_kg_m3: float = param(None, "kg/m3", "density (with area_m2)", 0.0, 1e5, low_open=True)
    area_m2: float = param(None, "m2", "cross-section (with density_kg_m3)", 0.0, 0.01, low_open=True)
    bending_stiffness_N_m2: float = param(None, "N.m2", "bending stiffness EI", 0.0, 1e6)
    youngs_modulus_Pa: float = param(0.0, "Pa", "Young's modulus (with second_moment_m4)", 0.0, 1e13)
    second_moment_m4: float = param(0.0, "m4", "second moment of area (with youngs_modulus_Pa)", 0.0, 1e-3)


@dataclass(frozen=True)
class StitchWireSection(WireSection):
    """[stitch_wire] (optional): the stitch wire at each support, as a wire, with its length; the droppers
    within half its length of a support hang from it."""

    length_m: float = param(REQUIRED, "m", "stitch-wire length, shorter than the span", 0.0, 1000.0, low_open=True)


@dataclass(frozen=True)
class DroppersSection:
    """[droppers]: the droppers' wire and clamps; mass as linear_mass_kg_m or density_kg_m3 x area_m2."""

    linear_mass_kg_m: float = param(None, "kg/m", "mass per length", 0.0, 100.0, low_open=True)
    density_kg_m3: float = param(None, "kg/m3", "density (with area_m2)", 0.0, 1e5, low_open=True)
    area_m2: float = param(10e-6, "m2", "cross-section, for the axial stiffness E A (and the mass with "
                                        "density_kg_m3)", 0.0, 0.01, low_open=True)
    youngs_modulus_Pa: float = param(1.1e11, "Pa", "Young's modulus, for the axial stiffness E A", 0.0, 1e13,
                                     low_open=True)
    clamp_mass_messenger_kg: float = param(0.0, "kg", "clamp mass on the messenger", 0.0, 100.0)
    clamp_mass_contact_kg: float = param(0.0, "kg", "clamp mass on the contact wire", 0.0, 100.0)


@dataclass(frozen=True)
class SteadyArmSection:
    """[steady_arm] (optional): the mass and vertical stiffness of the steady arm at each support."""

    mass_kg: float = param(0.0, "kg", "steady-arm mass on the contact wire", 0.0, 1000.0)
    stiffness_N_m: float = param(0.0, "N/m", "vertical stiffness", 0.0, 1e9)


@dataclass(frozen=True)
class MessengerSupportSection:
    """[messenger_support] (optional): how the messenger wire is held at the supports."""

    type: str = param("fixed", "1", "fixed, or a vertical spring", choices=("fixed", "spring"))
    stiffness_N_m: float = param(None, "N/m", "the spring's stiffness (type = \"spring\")", 0.0, 1e9, low_open=True)


CATENARY_FILE = FileSchema(
    "catenary file",
    {"catenary": SpanSection, "contact_wire": WireSection, "messenger_wire": WireSection,
     "stitch_wire": StitchWireSection, "droppers": DroppersSection, "steady_arm": SteadyArmSection,
     "messenger_support": MessengerSupportSection},
    CatenaryError, required_sections=("catenary", "contact_wire", "messenger_wire", "droppers"),
    optional_sections=("stitch_wire",), reference="catenary-reference")


def _check_elements(span: float, mesh: float) -> None:
    """Refuse a span whose mesh would need more memory than MAX_ELEMENTS_PER_SPAN allows (one line)."""
    elements = span / mesh
    if elements > MAX_ELEMENTS_PER_SPAN:
        gib = 2 * 8 * (4 * 5 * elements) * elements / 2**30
        raise CatenaryError(f"catenary.span_m / catenary.mesh_size_m: {span:g} m in elements of {mesh:g} m is "
                            f"{elements:.0f} elements per span, above the limit of {MAX_ELEMENTS_PER_SPAN} "
                            f"(the stiffness solve would take {gib:.1f} GiB)")


def _number_list(c: dict, key: str, minimum: int) -> list[float]:
    values = c[key]
    if len(values) < minimum:
        raise CatenaryError(f"catenary.{key}: expected a list of at least {minimum} numbers [m]", key=f"catenary.{key}")
    return values


def _mass(s: dict, sec: str) -> float:
    """A wire's or the droppers' mass per length: given, or density x area."""
    if s["linear_mass_kg_m"] is not None:
        return s["linear_mass_kg_m"]
    if s["density_kg_m3"] is None or s["area_m2"] is None:
        raise CatenaryError(f"{sec}.linear_mass_kg_m: missing (or give density_kg_m3 and area_m2)",
                            key=f"{sec}.linear_mass_kg_m")
    return s["density_kg_m3"] * s["area_m2"]


def _wire(s: dict, sec: str) -> Wire:
    ei = s["bending_stiffness_N_m2"]
    if ei is None:
        ei = s["youngs_modulus_Pa"] * s["second_moment_m4"]
    return Wire(s["tension_N"], _mass(s, sec), ei)


def _dropper_positions(c: dict, span: float) -> tuple[float, ...]:
    """Dropper positions from the span's first support, from `dropper_spacing_m` or `dropper_positions_m`."""
    spacing, given = c["dropper_spacing_m"], c["dropper_positions_m"]
    if spacing is not None and given is not None:
        raise CatenaryError("catenary.dropper_positions_m: give either dropper_positions_m or dropper_spacing_m",
                            key="catenary.dropper_positions_m")
    if spacing is not None:
        _number_list(c, "dropper_spacing_m", 2)
        if abs(sum(spacing) - span) > 1e-6 * span:
            raise CatenaryError(f"catenary.dropper_spacing_m: intervals sum to {sum(spacing):g} m, not the span "
                                f"{span:g} m", key="catenary.dropper_spacing_m")
        return tuple(float(v) for v in np.cumsum(spacing)[:-1])
    if given is None:
        raise CatenaryError("catenary.dropper_spacing_m: missing (or give dropper_positions_m)",
                            key="catenary.dropper_spacing_m")
    positions = tuple(_number_list(c, "dropper_positions_m", 1))
    if any(x >= span for x in positions):
        raise CatenaryError(f"catenary.dropper_positions_m: a dropper outside the span (0, {span:g}) m",
                            key="catenary.dropper_positions_m")
    if any(b <= a for a, b in zip(positions, positions[1:], strict=False)):
        raise CatenaryError("catenary.dropper_positions_m: overlapping droppers (positions must increase)",
                            key="catenary.dropper_positions_m")
    return positions


def _dropper_heights(c: dict, positions: tuple[float, ...]) -> tuple[float, ...] | None:
    """The design heights at the droppers, one per dropper, or None (the pre-sag parabola)."""
    heights = c["contact_wire_heights_m"]
    if heights is None:
        return None
    if len(heights) != len(positions):
        raise CatenaryError(f"catenary.contact_wire_heights_m: {len(heights)} heights for {len(positions)} droppers",
                            key="catenary.contact_wire_heights_m")
    if c["presag_m"] != 0:
        raise CatenaryError("catenary.contact_wire_heights_m: give either the heights at the droppers or presag_m",
                            key="catenary.contact_wire_heights_m")
    return tuple(float(h) for h in heights)


def _stitch(v: dict, span: float) -> tuple[Wire | None, float]:
    """The stitch wire and its length, or (None, 0) without one."""
    s = v["stitch_wire"]
    if s is None:
        return None, 0.0
    if s["length_m"] >= span:
        raise CatenaryError(f"stitch_wire.length_m: must be shorter than the span ({span:g} m)",
                            key="stitch_wire.length_m")
    return _wire(s, "stitch_wire"), s["length_m"]


def _support_stiffness(ms: dict) -> float:
    """The messenger support's vertical stiffness (0: fixed)."""
    if ms["type"] == "fixed":
        return 0.0
    if ms["stiffness_N_m"] is None:
        raise CatenaryError("messenger_support.stiffness_N_m: missing (required with type = \"spring\")",
                            key="messenger_support.stiffness_N_m")
    return ms["stiffness_N_m"]


def _check_mesh(mesh: float, span: float, positions: tuple[float, ...]) -> None:
    _check_elements(span, mesh)
    if mesh > min(np.diff((0.0, *positions, span))):
        raise CatenaryError(f"catenary.mesh_size_m: {mesh:g} m is longer than the shortest dropper interval",
                            key="catenary.mesh_size_m")


def build_definition(raw: dict, source: Path | None = None) -> CatenaryDefinition:
    """A catenary definition from the parsed TOML of a catenary file (its keys: CATENARY_FILE,
    docs/catenary-reference.md); CatenaryError naming the key."""
    v = CATENARY_FILE.validate(raw)
    c, d, sa = v["catenary"], v["droppers"], v["steady_arm"]
    span = c["span_m"]
    positions = _dropper_positions(c, span)
    _check_mesh(c["mesh_size_m"], span, positions)
    stitch, stitch_len = _stitch(v, span)
    return CatenaryDefinition(
        name=c["name"] or (source.stem if source else "catenary"), source=source, span_m=span,
        encumbrance_m=c["encumbrance_m"], presag_m=c["presag_m"], dropper_positions_m=positions,
        presag_span=c["presag_between"], contact=_wire(v["contact_wire"], "contact_wire"),
        messenger=_wire(v["messenger_wire"], "messenger_wire"), stitch=stitch, stitch_length_m=stitch_len,
        dropper_mass_kg_m=_mass(d, "droppers"), dropper_axial_stiffness_N=d["youngs_modulus_Pa"] * d["area_m2"],
        clamp_mass_messenger_kg=d["clamp_mass_messenger_kg"], clamp_mass_contact_kg=d["clamp_mass_contact_kg"],
        steady_arm_mass_kg=sa["mass_kg"], steady_arm_stiffness_N_m=sa["stiffness_N_m"],
        messenger_support_stiffness_N_m=_support_stiffness(v["messenger_support"]),
        alpha_1_s=c["alpha_1_s"], beta_s=c["beta_s"], mesh_size_m=c["mesh_size_m"], values=raw,
        dropper_heights_m=_dropper_heights(c, positions))


def load_definition(path: Path) -> CatenaryDefinition:
    """Read and validate a catenary file (TOML); CatenaryError with one line on any fault."""
    path = Path(path)
    try:
        raw = load_toml(path, "catenary file")
    except InputFileError as exc:
        raise CatenaryError(str(exc)) from None
    return build_definition(raw, path)
