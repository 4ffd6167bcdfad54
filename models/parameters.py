"""One declaration per case parameter: a frozen dataclass per case section.

Each field's metadata (`Param`, models/schema.py) carries the unit, the range, the description, the FMI
type and the FMU that receives it. The case schema and its validation (`models/case.py`), the FMU
variable tables (`fmus/`), the builder's mapping (`builder/fmu_parameters.py`) and the key reference
(`docs/case-reference.md`, orchestrator/file_reference.py) are derived from these declarations.

Naming rule (case keys, FMU variables and summary fields): a parameter has one name, `snake_case`,
ending in its SI unit (`_m`, `_s`, `_N`, `_N_m`, `_kg_m`, `_hz`, `_1_s`, ...; none for a pure number
or a choice), and it is the same in the case file (`[rig] servo_bandwidth_hz`), in the FMU's
modelDescription.xml (`servo_bandwidth_hz`) and in summary.json. A choice reaches an FMU as an
Integer, the index of its value in the choices, named `<section>_<key>` (`catenary_model`,
`pantograph_model`, `hil_update`); a list as one variable per item, `<key>_<i>` from 1
(`masses_kg_1`). Speed is the one key given in km/h (`run.speed_kmh`), as railway engineers state it.

A value written `"auto"` is computed by pantohil (it is the default where it is allowed); no number
stands for "automatic".
"""
from __future__ import annotations

from dataclasses import dataclass

from pantohil.models.catenary.interface import CATENARIES
from pantohil.models.pantograph.interface import PANTOGRAPHS
from pantohil.models.pantograph.lumped import PantographParameters
from pantohil.models.rig.actuator import ActuatorLimits
from pantohil.models.rig.chain import RigParameters
from pantohil.models.schema import (  # noqa: F401 (the case's names for the schema's parts)
    AUTO,
    MAX_LIST_LENGTH,
    REQUIRED,
    XS_INT_MAX,
    XS_INT_MIN,
    Key,
    Param,
    declared_keys,
    json_like,
    param,
)

# Limits on sizes, named in the messages that refuse them (checked before anything is allocated).
MAX_SAMPLES_PER_SPAN = 100_000
MAX_SPANS = 10_000


@dataclass(frozen=True)
class CaseSection:
    """[case]: what the case is."""

    name: str = param("unnamed", "1", "case name (the default run folder's name)")
    description: str = param("", "1", "free text")


@dataclass(frozen=True)
class CatenarySection:
    """[catenary]: the periodic catenary model (Paper A sec. 3, Paper C)."""

    model: str = param("asm", "1", "catenary model: ASM2 string (Paper A), PFEM (Paper C), or one another "
                                   "package registers (`pantohil.catenaries`)",
                       choices=CATENARIES.names(), fmu="catenary")
    definition_file: str = param("", "1", "catenary file (relative to the case): ASM2 fitted to its FE model, "
                                          "or the span of the PFEM")
    span_m: float = param(REQUIRED, "m", "span length L", 1.0, 1000.0, fmu="catenary", fmu_start=65.0)
    tension_N: float = param(REQUIRED, "N", "contact-wire tension T", 0.0, 1e6, low_open=True, fmu="catenary",
                            fmu_start=31500.0)
    density_kg_m: float = param(REQUIRED, "kg/m", "string linear density mu", 0.0, 100.0, low_open=True,
                                fmu="catenary", fmu_start=1.4735)
    support_stiffness_N_m2: float = param(REQUIRED, "N/m2", "visco-elastic support stiffness kbar", 0.0, 1e6,
                                          low_open=True, fmu="catenary", fmu_start=51.15)
    alpha_1_s: float = param(0.0125, "1/s", "Rayleigh alpha", 0.0, 100.0, fmu="catenary")
    beta_s: float = param(1e-4, "s", "Rayleigh beta", 0.0, 1.0, fmu="catenary")


@dataclass(frozen=True)
class ProfileSection:
    """[profile]: the static contact-wire height z0 along a span (Paper A sec. 5.1)."""

    source: str = param("droppers", "1", "where z0 comes from", choices=("droppers", "csv", "catenary"))
    catenary_file: str = param("", "1", "catenary file whose form-found z0 to use, relative to the case")
    dropper_spacing_m: tuple = param((), "m", "intervals support-dropper-...-support", 0.0, 1000.0, low_open=True)
    wire_mass_kg_m: float = param(1.374, "kg/m", "contact-wire mass per length", 0.0, 100.0, low_open=True)
    wire_tension_N: float = param(0.0, "N", "tension for the sag (0: catenary.tension_N)", 0.0, 1e6)
    presag_m: float = param(0.0, "m", "mid-span pre-sag", -10.0, 10.0)
    csv_file: str = param("", "1", "x_m,z0_m file, relative to the case file")


@dataclass(frozen=True)
class PantographSection:
    """[pantograph]: the lumped pantograph (Paper A sec. 2, Table A.3)."""

    model: str = param("chain", "1", "pantograph model (models/pantograph/interface.py; other packages add "
                                         "theirs under the entry-point group pantohil.pantographs)",
                       choices=PANTOGRAPHS.names(), fmu="pantograph")
    masses_kg: tuple = param((6.6, 5.8, 5.8), "kg", "masses, head first", 0.0, 1000.0, low_open=True,
                             fmu="pantograph", fmu_items=3)
    stiffnesses_N_m: tuple = param((7000.0, 14100.0, 80.0), "N/m", "element stiffnesses (mass i to mass i+1 or "
                                   "ground)", 0.0, 1e8, fmu="pantograph", fmu_items=3)
    dampings_Ns_m: tuple = param((0.0, 0.0, 70.0), "N.s/m", "element dampings", 0.0, 1e6, fmu="pantograph",
                                 fmu_items=3)
    contact_stiffness_N_m: float = param(50000.0, "N/m", "penalty contact stiffness k_c", 0.0, 1e8,
                                         low_open=True, fmu="pantograph")
    uplift_force_N: float = param(AUTO, "N", "static uplift force; \"auto\": F_m = 0.00097 v^2 + 70 (EN 50367, "
                                             "Paper A eq. 37)", 0.0, 2000.0, low_open=True, fmu="pantograph",
                                  auto=True, fmu_start=130.0)
    gravity_m_s2: float = param(0.0, "m/s2", "gravity felt by a rigid mass (load cell not tared)", 0.0, 100.0,
                                fmu="pantograph")


def pantograph_parameters(section: PantographSection, uplift_force_N: float | None = None) -> PantographParameters:
    """The pantograph model's parameters of a [pantograph] section: its lists cut to its masses (an empty
    list: one element of 0), the uplift the section gives, or `uplift_force_N` where it says "auto"."""
    uplift = section.uplift_force_N
    if uplift == AUTO:
        if uplift_force_N is None:
            raise ValueError("pantograph.uplift_force_N is \"auto\": the uplift in use must be given")
        uplift = uplift_force_N
    n = len(section.masses_kg)
    return PantographParameters(masses_kg=tuple(section.masses_kg),
                                stiffnesses_N_m=tuple(section.stiffnesses_N_m[:n]) or (0.0,),
                                dampings_Ns_m=tuple(section.dampings_Ns_m[:n]) or (0.0,),
                                contact_stiffness_N_m=section.contact_stiffness_N_m, uplift_force_N=float(uplift),
                                model=section.model, gravity_m_s2=section.gravity_m_s2)


@dataclass(frozen=True)
class RigSection(RigParameters):
    """[rig]: the simulated rig between model and pantograph (Paper B sec. 4, Paper D sec. 2)."""

    file: str = param("", "1", "rig file (relative to the case; models/data/rigs/*.toml): the chain of Paper B or "
                               "D, which replaces the five keys above (force offset and noise still apply)")


@dataclass(frozen=True)
class LinkSection:
    """[link]: the UDP link to a rig controller (docs/udp-protocol.md)."""

    receive_timeout_s: float = param(0.0003, "s", "how long a step waits for the awaited answer", 1e-6, 1.0,
                                     fmu="adapter")
    pipeline_steps: int = param(1, "1", "1: use the answer to the previous command (no waiting on the network)",
                                choices=(0, 1), fmu="adapter")
    tolerated_losses: int = param(50, "1", "consecutive missing answers before a fault", 0, 1_000_000,
                                  fmu="adapter")
    local_port: int = param(0, "1", "local UDP port (0: any free port)", 0, 65535, fmu="adapter")
    local_host: str = param("", "1", "local address to bind (empty: the interface that reaches the rig)")
    key_file: str = param("", "1", "pre-shared key file authenticating every datagram (HMAC-SHA256); empty: none")
    paced_by: str = param("model", "1", "who owns the clock: the model (a COMMAND per step) or the rig (a SAMPLE "
                                        "per rig tick, answered at once)", choices=("model", "rig"), fmu="adapter")
    sample_timeout_s: float = param(0.5, "s", "rig-paced: silence of the rig after which the link is in fault",
                                    1e-3, 60.0, fmu="adapter")
    settle_after_hold_s: float = param(0.1, "s", "rig-paced: after a tick no answer covered (the actuator held), "
                                                  "the forces of this long are not taken as measured (the "
                                                  "actuator's return to the wanted height disturbs them)",
                                       0.0, 10.0, fmu="adapter")
    horizon_steps: int = param(AUTO, "1", "heights each answer carries for the rig's next ticks "
                                          "(docs/udp-protocol.md); \"auto\": the steps of 0.1 s, at most 64", 1, 64,
                               auto=True)
    min_measured_fraction: float = param(0.5, "1", "smallest share of a span's forces that must be measured; a span "
                                                   "with fewer is a link fault, whatever link.tolerated_losses says",
                                         0.0, 1.0, low_open=True)


ActuatorSection = ActuatorLimits  # [actuator]: the limits the adapter keeps every command within


@dataclass(frozen=True)
class HilSection:
    """[hil]: the periodic HIL update (Paper B sec. 3, Paper D sec. 3)."""

    update: str = param("step", "1", "update strategy: step-by-step (Paper D eq. 2) or span-by-span (eq. 3)",
                        choices=("step", "span"), fmu="catenary")
    relaxation: float = param(0.1, "1", "relaxation mu_c (Paper D eq. 10)", 0.0, 1.0, low_open=True, fmu="catenary")
    max_frequency_hz: float = param(25.0, "Hz", "f_max of the frequency reduction", 0.0, 1e4, low_open=True,
                                    fmu="catenary")
    ramp_steps: int = param(0, "1", "initial ramp N_r [steps]", 0, 100_000_000, fmu="catenary")
    delay_compensation: bool = param(True, "1", "advance the height by the rig's latency")
    delay_steps: int = param(AUTO, "1", "delay advance D [steps]; \"auto\": the loop latency of the master plus "
                                        "the rig's (Paper D sec. 3.4)", 0, 100_000, fmu="catenary", auto=True,
                             fmu_start=1)
    hold_steps: int = param(0, "1", "extra loop delay E [steps]: the catenary sends each height E steps after "
                                    "computing it and D grows by E, so that the loop's total delay falls in a "
                                    "stable zone (Paper D sec. 4, Fig. 7)", 0, 100_000, fmu="catenary")
    rig_compensation: str = param("response", "1", "with a rig file: compensate its frequency response at the kept "
                                                   "harmonics (\"response\"), or only its latency in whole steps "
                                                   "(\"delay\")", choices=("response", "delay"))


@dataclass(frozen=True)
class PfemSection:
    """[pfem]: the PFEM catenary's discretisation and dropper slackening (Paper C sec. 3-5)."""

    droppers: bool = param(True, "1", "dropper slackening (Paper C sec. 5); false: the linear catenary",
                           fmu="catenary")
    dropper_max_frequency_hz: float = param(20.0, "Hz", "f_max of the elongations, N_hd", 0.0, 1e4, low_open=True)
    dropper_relaxation: float = param(1.0, "1", "relaxation of the dropper corrections mu_d (Paper D sec. 3.7)",
                                      0.0, 1.0, low_open=True, fmu="catenary")
    omega_max_rad_s: float = param(750.0, "rad/s", "highest frequency of the transform", 0.0, 1e5, low_open=True)
    grid_resolution: float = param(0.094, "1", "frequency step / (alpha + beta w^2)", 1e-3, 10.0)
    taper: float = param(0.25, "1", "tapered top fraction of [0, w_max]", 0.0, 1.0, high_open=True)


@dataclass(frozen=True)
class RunSection:
    """[run]: speed, time step and when a run stops."""

    speed_kmh: float = param(REQUIRED, "km/h", "pantograph speed", 1.0, 600.0)
    dt_s: float = param(0.001, "s", "target time step; adjusted to fit the span", 1e-5, 0.1)
    max_spans: int = param(200, "1", "span limit", 1, MAX_SPANS)
    duration_s: float = param(0.0, "s", "run this long (whole spans), converged or not, as a rig's fixed-length "
                                        "test (Paper D: 120 s); 0: stop at convergence", 0.0, 1e6)
    convergence_tol: float = param(1e-4, "1", "rms span-to-span change / std", 0.0, 1.0, low_open=True)
    force_limit_N: float = param(2000.0, "N", "|force| beyond this is divergence", 0.0, 1e6, low_open=True)
    height_limit_m: float = param(1.0, "m", "|height| beyond this is divergence", 0.0, 100.0, low_open=True)
    divergence_change: float = param(0.8, "1", "median span-to-span change / std beyond which the iteration "
                                               "has diverged (a limit cycle with contact loss)", 0.0, 100.0,
                                     low_open=True)
    divergence_spans: int = param(10, "1", "spans over which that median is taken", 1, MAX_SPANS)


@dataclass(frozen=True)
class SecondPantographSection:
    """[second_pantograph]: a second pantograph on the same catenary, L apart (Paper A secs. 3.4 and 5); absent,
    the line carries one. It is the first pantograph's model and parameters, running virtual."""

    spacing_m: float = param(REQUIRED, "m", "distance L between the two pantographs", 0.0, 10_000.0, low_open=True)
    position: str = param("trailing", "1", "where the second runs relative to the first: behind it (trailing) or "
                                           "ahead of it (leading)", choices=("trailing", "leading"))
    coupling_compensation: bool = param(True, "1", "apply the force residuals through the pair's coupling "
                                                   "compensation, from the pantograph model's receptance, so that "
                                                   "each contact point iterates as if alone (models/hil/pair.py); "
                                                   "false: the plain iteration of Paper D for the pair")


SECTIONS: dict[str, type] = {
    "case": CaseSection, "catenary": CatenarySection, "profile": ProfileSection, "pantograph": PantographSection,
    "rig": RigSection, "link": LinkSection, "actuator": ActuatorSection, "hil": HilSection, "pfem": PfemSection,
    "run": RunSection, "second_pantograph": SecondPantographSection,
}
OPTIONAL_SECTIONS = ("second_pantograph",)  # absent from a case file: None


@dataclass(frozen=True)
class CaseSections:
    """A validated case as its typed sections, one frozen dataclass per [section] (lists as tuples)."""

    case: CaseSection
    catenary: CatenarySection
    profile: ProfileSection
    pantograph: PantographSection
    rig: RigSection
    link: LinkSection
    actuator: ActuatorSection
    hil: HilSection
    pfem: PfemSection
    run: RunSection
    second_pantograph: SecondPantographSection | None

    @classmethod
    def of(cls, values: dict) -> CaseSections:
        """The sections of validated values ({section: {key: value}}, every key present)."""
        return cls(**{name: None if values.get(name) is None else
                      SECTIONS[name](**{key: tuple(v) if isinstance(v, list) else v for key, v in values[name].items()})
                      for name in SECTIONS})


def section_keys(section: str) -> dict[str, Key]:
    """The declared keys of a case section, in declaration order."""
    return declared_keys(section, SECTIONS[section])


def all_keys() -> list[Key]:
    """Every case key of every section, in declaration order."""
    return [k for s in SECTIONS for k in section_keys(s).values()]


def fmu_keys(fmu: str) -> list[Key]:
    """The case keys that reach an FMU, as variables of the same name."""
    return [k for k in all_keys() if k.param.fmu == fmu]


def fmu_variable_names(key: Key) -> list[str]:
    """The FMU variables a case key reaches (naming rule in the module docstring)."""
    if key.param.choices and isinstance(key.param.choices[0], str):
        return [f"{key.section}_{key.name}"]
    if key.param.fmu_items:
        return [f"{key.name}_{i}" for i in range(1, key.param.fmu_items + 1)]
    return [key.name]


def fmu_values(fmu: str, values: dict, resolved: dict | None = None) -> dict:
    """{FMU variable: value} of the case keys that reach an FMU (naming rule in the module docstring).
    `values` is the validated case ({section: {key: value}}); `resolved` gives, by dotted key, the value in
    use where the case's differs ("auto", or a list the model shortens)."""
    resolved = resolved or {}
    out = {}
    for key in fmu_keys(fmu):
        value = resolved.get(key.dotted, values[key.section][key.name])
        names = fmu_variable_names(key)
        if key.param.choices and isinstance(key.param.choices[0], str):
            out[names[0]] = key.param.choices.index(value)
        elif key.type is bool:
            out[names[0]] = int(value)
        elif key.param.fmu_items:
            padded = list(value) + [0.0] * (len(names) - len(value))
            out.update(zip(names, padded, strict=True))
        else:
            out[names[0]] = value
    return out
