"""Periodic catenary FMU: receives the measured contact force, runs the HIL iteration and commands the
contact-point height, advanced by the delay D (Paper B sec. 3, Paper D sec. 3). The iteration is the
registered catenary model's (models/catenary/interface.py) that `catenary_model` names: ASM2, the
analytical string (Papers A-B), the PFEM, one span of a finite-element catenary with periodic boundaries
and dropper slackening (Papers C-D), or another package's; built from what it staged in resources/."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

# pythonfmu imports this script from the FMU's resources/: its pantohil imports are the FMU's own copy of the
# package there, whatever pantohil the process holds (fmus/own_package.py, loaded by its path from beside this file)
_spec = importlib.util.spec_from_file_location("pantohil_own_package", Path(__file__).with_name("own_package.py"))
_binding = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_binding)

with _binding.own_package(globals()):
    from pantohil.fmus.fmu_support import PantohilSlave
    from pantohil.fmus.variables import Var, case_variables, register_all
    from pantohil.models.catenary.asm.pair import POSITIONS, PairSpec
    from pantohil.models.catenary.grid import SpanGrid
    from pantohil.models.catenary.interface import CATENARIES
    from pantohil.models.catenary.pfem.model import MAX_DROPPERS
    from pantohil.models.catenary.receptance import harmonic_count
    from pantohil.models.hil.loop import MAX_HORIZON_STEPS, UPDATES, HilSettings
    from pantohil.models.rig.compensation import read_response_csv

_NO_DROPPERS = np.zeros(0)  # the dropper outputs of a catenary without slackening, read every step (never written)

VARIABLES = [
    *case_variables("catenary"),
    Var("speed", "real", "parameter", "m/s", "Pantograph speed V", 69.44444444444444, 0.0, 200.0),
    Var(
        "time_step",
        "real",
        "parameter",
        "s",
        "Sampling time dt; a span holds samples_per_span samples",
        0.001,
        1e-5,
        0.1,
    ),
    Var("samples_per_span", "integer", "parameter", "1", "Samples per span N = L / (V dt)", 936, 2),
    Var(
        "rig_compensation",
        "integer",
        "parameter",
        "1",
        "0: delay advance D only; 1: also the rig's response at the kept "
        "harmonics from resources/rig_response.csv (command = G_z^-1 z, force = G_f^-1 f_meas)",
        0,
        0,
        1,
    ),
    Var(
        "contact_force",
        "real",
        "input",
        "N",
        "Measured contact force (pushing the wire up is positive); NaN: not measured",
        0.0,
    ),
    Var(
        "horizon_steps",
        "integer",
        "parameter",
        "1",
        "Heights of the horizon H: height_command and height_ahead_1 .. height_ahead_{H-1} "
        "(docs/udp-protocol.md); the outputs beyond repeat the last",
        1,
        1,
        MAX_HORIZON_STEPS,
    ),
    Var("height_command", "real", "output", "m", "Contact-point height commanded D samples ahead", 0.0),
    Var("second_pantograph", "integer", "parameter", "1", "1: a second contact point on the catenary, "
        "second_spacing_m from the first (Paper A sec. 3.4; models/hil/pair.py); 0: one", 0, 0, 1),
    Var("second_spacing_m", "real", "parameter", "m", "Distance L of the second contact point from the first",
        200.0, 1e-3, 10_000.0),
    Var("second_position", "integer", "parameter", "1", "Where the second runs: 0 behind the first (trailing), "
        "1 ahead of it (leading)", 0, 0, 1),
    Var("coupling_compensation", "integer", "parameter", "1", "1: the pair's force residuals through the coupling "
        "compensation (resources/pantograph_receptance.csv); 0: the plain iteration", 1, 0, 1),
    Var("delay_steps_2", "integer", "parameter", "1", "Delay advance D of the second contact point [steps]", 2, 0,
        100_000),
    Var("contact_force_2", "real", "input", "N", "Contact force at the second contact point; NaN: not measured",
        0.0),
    Var("height_command_2", "real", "output", "m", "Height commanded at the second contact point, its D ahead",
        0.0),
    Var("height_at_sample_2", "real", "output", "m", "Converging wire height at the second point, sample_index",
        0.0),
    Var("profile_at_sample_2", "real", "output", "m", "Static height z0 at the second point, sample_index", 0.0),
    Var("force_at_sample_2", "real", "output", "N", "Force in use at the second point, sample_index", 0.0),
    *[
        Var(
            f"height_ahead_{i}",
            "real",
            "output",
            "m",
            f"The height the {i}-th next step commands if the iterate no longer changes (exactly that at "
            "convergence): the horizon a late answer leaves the rig",
            0.0,
        )
        for i in range(1, MAX_HORIZON_STEPS)
    ],
    Var("sample_index", "integer", "output", "1", "Label n of the force just received, 0..N-1 in the span", 0),
    Var("span_index", "integer", "output", "1", "Virtual span (block) of the force just received", 0),
    Var("height_at_sample", "real", "output", "m", "Converging wire height at sample_index", 0.0),
    Var("profile_at_sample", "real", "output", "m", "Static wire height z0 (unfiltered) at sample_index", 0.0),
    Var(
        "force_at_sample",
        "real",
        "output",
        "N",
        "Force in use at sample_index: the measured one (the true-force estimate G_f^-1 f_meas with "
        "rig_compensation = 1), or the previous span's if it was not measured (NaN input)",
        0.0,
    ),
    Var("harmonics", "integer", "output", "1", "Harmonics kept N_h (0..N_h-1)", 0),
    Var("slack_droppers", "integer", "output", "1", "PFEM: droppers corrected at this step (slack)", 0),
    *[
        Var(
            f"dropper_correction_{d + 1}",
            "real",
            "output",
            "N",
            f"PFEM: correction force of dropper {d + 1} at this step's instant of its window (Paper C eq. 39); "
            "0 if absent",
            0.0,
        )
        for d in range(MAX_DROPPERS)
    ],
]
_PARAMETER_NAMES = tuple(v.name for v in case_variables("catenary"))  # what a catenary model is built from
SECOND_POINT_PARAMETERS = ("second_pantograph", "second_spacing_m", "second_position", "coupling_compensation",
                           "delay_steps_2")
SECOND_POINT_OUTPUTS = ("height_command_2", "height_at_sample_2", "profile_at_sample_2", "force_at_sample_2")


def one_pantograph_parameters() -> dict:
    """The second-point parameters of a catenary with one contact point: their declared start values."""
    return {v.name: v.start for v in VARIABLES if v.name in SECOND_POINT_PARAMETERS}


class PantohilCatenary(PantohilSlave):
    """The catenary FMU: the periodic operator (ASM2 or PFEM) and the HIL iteration (Paper D sec. 3)."""
    author = "pantohil"
    description = ("Periodic catenary (ASM2 analytical string, Gil et al. Papers A-B, or PFEM with dropper "
                   "slackening, Papers C-D) for steady-state HIL "
                   "pantograph tests: valid for the steady state of equal spans only.")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._hil = None
        self._ahead = None  # the horizon of this step, computed when a master first reads it
        register_all(self, VARIABLES)

    @property
    def stepped_iteration(self):
        """The HIL iteration this FMU steps (PeriodicHil or PfemHil), for an engine that steps it in process."""
        return self._hil

    @property
    def static_heights_m(self) -> np.ndarray:
        """The static contact-line height at the span's samples."""
        return np.asarray(self._z0, dtype=float)

    def constants(self) -> dict[str, object]:
        """The operators, the profile and what the iteration precomputes from them (fixed after initialisation)."""
        if self._hil is None:
            return {}
        return {"profile": self._z0, **{f"hil.{a}": getattr(self._hil, a) for a in self._hil.CONSTANT_ATTRIBUTES}}

    @property
    def structural(self) -> tuple[str, ...]:
        """The parameters the built resources depend on: the sample grid and the profile, the rig's response
        file, and those the model's staged resources fix (its `structural_keys`)."""
        grid = ("speed", "time_step", "samples_per_span", "span_m", "catenary_model", "max_frequency_hz",
                "rig_compensation", "second_pantograph", "coupling_compensation")
        built = self._built.get("catenary_model")
        return grid if built is None else grid + CATENARIES.get(CATENARIES.name_of(built)).structural_keys

    def exit_initialization_mode(self):
        """Build the iteration of the registered catenary model that catenary_model names, from the staged
        resources (models/catenary/interface.py)."""
        self.check_parameters()
        n = int(self.samples_per_span)
        self.harmonics = harmonic_count(self.max_frequency_hz, n, self.time_step)
        settings = HilSettings(update=UPDATES[self.hil_update], relaxation=self.relaxation,
                               delay_steps=self.delay_steps, ramp_steps=self.ramp_steps,
                               hold_steps=int(self.hold_steps))
        comp = read_response_csv(Path(self.resources), n, self.harmonics) if self.rig_compensation == 1 else None
        model = CATENARIES.get(CATENARIES.name_of(self.catenary_model, "catenary_model"))
        grid = SpanGrid(self.speed, self.time_step, n, self.harmonics, self.span_m)
        parameters = {name: getattr(self, name) for name in _PARAMETER_NAMES}
        if self.second_pantograph:
            self._hil, z0 = self._pair_iteration(model, grid, parameters, settings, comp)
        else:
            self._hil, z0 = model.iteration(grid, parameters, Path(self.resources), settings, comp)
        self._z0 = np.asarray(z0, dtype=float)
        if getattr(self._hil, "nd", 0) > MAX_DROPPERS:
            raise ValueError(f"the catenary has {self._hil.nd} slackening droppers; this FMU reports at most "
                             f"{MAX_DROPPERS}")
        self._label = 0
        self._ahead = None
        if self.second_pantograph:
            ramped = self.ramp_steps > 0
            self.height_command = 0.0 if ramped else float(self._hil.z[0, self.delay_steps % n])
            self.height_command_2 = 0.0 if ramped else float(self._hil.z[1, int(self.delay_steps_2) % n])
            return
        self.height_command = 0.0 if self.ramp_steps > 0 else self._hil.command_at(self._hil.z, self.delay_steps % n)

    def _pair_iteration(self, model, grid, parameters, settings, comp):
        """The iteration of two contact points, from a model that has one (`pair_iteration`)."""
        if comp is not None or not hasattr(model, "pair_iteration"):
            raise ValueError(f"{type(self).__name__}: second_pantograph = 1 needs a catenary model with two contact "
                             "points (asm) and rig_compensation = 0")
        pair = PairSpec(float(self.second_spacing_m), POSITIONS[int(self.second_position)],
                        bool(self.coupling_compensation))
        return model.pair_iteration(grid, parameters, Path(self.resources), settings,
                                    (int(self.delay_steps), int(self.delay_steps_2)), pair)

    def do_step(self, current_time, step_size):
        """Take the measured force of this step and output the height to command (Paper D eqs. 2-3, 10)."""
        hil = self._hil
        self._label = hil.k % hil.n
        if self.second_pantograph:
            self.height_command, self.height_command_2 = hil.step((self.contact_force, self.contact_force_2))
        else:
            self.height_command = hil.step(self.contact_force)
        self._ahead = None
        return True

    def height_ahead(self, i: int) -> float:
        """Output height_ahead_i: the command of the i-th next step as the iterate stands (Paper D eqs. 2-3
        with the delay advance, the hold and the ramp; `commands_ahead`); beyond the horizon, its last."""
        if self._hil is None:
            return 0.0
        if self._ahead is None:
            self._ahead = self._hil.ahead(max(int(self.horizon_steps) - 1, 1)).tolist()
        return self._ahead[min(i, len(self._ahead)) - 1]

    # Per-step outputs other than the command are read from the iteration's state when a master asks
    # for them, so that do_step does only the work of the loop.
    _label = 0

    @property
    def sample_index(self) -> int:
        """Output: the sample n_bar of the span the last force belonged to."""
        return self._label

    @property
    def span_index(self) -> int:
        """Output: the virtual span b the last force belonged to."""
        return 0 if self._hil is None else max(self._hil.k - 1, 0) // self._hil.n

    def _point(self, source: str, point: int) -> float:
        """A per-sample value of contact point `point` (0 the first) at sample_index: the iteration's `source`
        ("z", "force_estimate"), or "profile" (z0); 0 before initialisation or for a second point the catenary
        does not have."""
        if self._hil is None:
            return 0.0
        values = self._z0 if source == "profile" else getattr(self._hil, source)
        if self.second_pantograph:
            return float(values[point, self._label])
        return 0.0 if point else float(values[self._label])

    @property
    def height_at_sample(self) -> float:
        """Output: the converging wire height at sample_index [m]."""
        return self._point("z", 0)

    @property
    def profile_at_sample(self) -> float:
        """Output: the static height z0 at sample_index [m]."""
        return self._point("profile", 0)

    @property
    def force_at_sample(self) -> float:
        """Output: the force in use at sample_index (the measured one, or the previous span's) [N]."""
        return self._point("force_estimate", 0)

    @property
    def height_at_sample_2(self) -> float:
        """Output: the converging wire height at the second point at sample_index [m]."""
        return self._point("z", 1)

    @property
    def profile_at_sample_2(self) -> float:
        """Output: the static height z0 at the second point at sample_index [m]."""
        return self._point("profile", 1)

    @property
    def force_at_sample_2(self) -> float:
        """Output: the force in use at the second point at sample_index [N]."""
        return self._point("force_estimate", 1)

    @property
    def slack_droppers(self) -> int:
        """Output: the number of droppers with a correction force (slack) at this step."""
        return int(np.count_nonzero(self._dropper_forces()))

    def _dropper_forces(self) -> np.ndarray:
        hil = self._hil
        return hil.current_correction if (hil is not None and getattr(hil, "nd", 0)) else _NO_DROPPERS


def _dropper_output(d: int) -> property:
    def get(self) -> float:
        f = self._dropper_forces()
        return float(f[d]) if d < len(f) else 0.0
    return property(get)


for _d in range(MAX_DROPPERS):
    setattr(PantohilCatenary, f"dropper_correction_{_d + 1}", _dropper_output(_d))


def _ahead_output(i: int) -> property:
    return property(lambda self: self.height_ahead(i))


for _i in range(1, MAX_HORIZON_STEPS):
    setattr(PantohilCatenary, f"height_ahead_{_i}", _ahead_output(_i))
