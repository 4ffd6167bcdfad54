"""Pantograph FMU: a lumped chain of 1-3 masses with penalty contact and contact loss, HHT-integrated,
or a rigid mass on the actuator (Paper A sec. 2, Paper B sec. 5.1)."""
from __future__ import annotations

import importlib.util
from pathlib import Path

# pythonfmu imports this script from the FMU's resources/: its pantohil imports are the FMU's own copy of the
# package there, whatever pantohil the process holds (fmus/own_package.py, loaded by its path from beside this file)
_spec = importlib.util.spec_from_file_location("pantohil_own_package", Path(__file__).with_name("own_package.py"))
_binding = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_binding)

with _binding.own_package(globals()):
    from pantohil.fmus.fmu_support import PantohilSlave
    from pantohil.fmus.variables import Var, case_variables, register_all
    from pantohil.models.pantograph.interface import PANTOGRAPHS, make_pantograph
    from pantohil.models.pantograph.lumped import PantographParameters

VARIABLES = [
    *case_variables("pantograph"),
    Var("n_masses", "integer", "parameter", "1", "Masses in the chain, head first", 3, 1, 3),
    Var(
        "reference_height",
        "real",
        "parameter",
        "m",
        "Wire height at which the static contact force equals the uplift force",
        0.0,
    ),
    Var("time_step", "real", "parameter", "s", "Integration step dt (equal to the communication step)", 0.001, 1e-6),
    Var("height", "real", "input", "m", "Actuator (contact-point) height at the end of the step", 0.0),
    # the pantograph settles on the height it is given
    Var("contact_force", "real", "output", "N", "Contact force on the wire (load-cell reading without the rig)", 0.0,
        initial_inputs=("height",)),
    Var("head_height", "real", "output", "m", "Height of the head (mass 1)", 0.0, initial_inputs=("height",)),
    Var("in_contact", "boolean", "output", "1", "True while the head touches the wire", True,
        initial_inputs=("height",)),
]


class PantohilPantograph(PantohilSlave):
    """The pantograph FMU: a lumped chain with penalty contact, or a rigid mass, HHT-integrated."""
    author = "pantohil"
    description = "Lumped pantograph (Paper A Table A.3 chain, HHT alpha=-0.05) with penalty contact and contact loss."

    structural = ("time_step",)  # the integration step is the communication step the loader enforces

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        register_all(self, VARIABLES)
        self._model = None

    @property
    def stepped_pantograph(self):
        """The pantograph model this FMU steps, for an engine that steps it in process."""
        return self._model

    def exit_initialization_mode(self):
        """Build the pantograph from its parameters and settle it at the actuator's starting height."""
        self.check_parameters()
        model = PANTOGRAPHS.name_of(self.pantograph_model, "pantograph_model")
        n = 1 if PANTOGRAPHS.get(model).fixed_to_actuator else int(self.n_masses)
        def pick(stem):
            return tuple(float(getattr(self, f"{stem}_{i}")) for i in range(1, n + 1))
        params = PantographParameters(
            masses_kg=pick("masses_kg"),
            stiffnesses_N_m=pick("stiffnesses_N_m"),
            dampings_Ns_m=pick("dampings_Ns_m"),
            contact_stiffness_N_m=self.contact_stiffness_N_m,
            uplift_force_N=self.uplift_force_N,
            model=model,
            gravity_m_s2=self.gravity_m_s2,
        )
        self._model = make_pantograph(params, self.time_step, self.reference_height)
        self.contact_force = self._model.settle(self.height)
        self._publish()

    def _publish(self):
        self.head_height = self._model.head_height
        self.in_contact = self.contact_force > 0.0

    def do_step(self, current_time, step_size):
        """One HHT step to the actuator height of this step; outputs the contact force [N]."""
        self.contact_force = self._model.step(self.height)
        self._publish()
        return True
