"""Rig FMU: the HIL rig's delay, communication decimation with the drive's ramp, servo, load-cell
filter, force offset and noise (Paper B sec. 4, Paper D secs. 2 and 5.1); with rig_chain = 1, the
chain of the rig file in resources/rig.toml (sub-referenced drive ramp, motion profile, position
loop, Butterworth amplifier filter), the same file the rig emulator runs."""
from __future__ import annotations

import dataclasses
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
    from pantohil.models.rig.chain import Rig, RigParameters
    from pantohil.models.rig.drive_chain import RigChain, latency_steps
    from pantohil.models.rig.rig_file import load_rig_file

RIG_FILE = "rig.toml"

VARIABLES = [
    *case_variables("rig"),
    Var("time_step", "real", "parameter", "s", "Sampling time dt", 0.001, 1e-6),
    Var("rig_chain", "integer", "parameter", "1", "0: the parameters above; 1: the rig file resources/rig.toml "
        "(with force_offset, noise_std, noise_seed)", 0, 0, 1),
    Var("height_command", "real", "input", "m", "Height commanded by the catenary model", 0.0),
    Var("true_force", "real", "input", "N", "Contact force at the pantograph", 0.0),
    Var("actuator_height", "real", "output", "m", "Height reached by the actuator", 0.0,
        initial_inputs=("height_command",)),  # the actuator starts where it is commanded
    Var("measured_force", "real", "output", "N", "Force as measured by the load cell", 0.0),
    Var("latency_steps", "integer", "output", "1", "Rig latency in whole steps, for the delay advance", 0),
]


class PantohilRig(PantohilSlave):
    """The rig FMU: delay, N_com decimation with the drive's ramp, servo, load cell, offset and noise."""
    author = "pantohil"
    description = (
        "HIL rig between model and pantograph: delay, N_com decimation with linear drive ramp, servo, load cell."
    )

    structural = ("time_step", "rig_chain")  # a rig file's chain counts its delays in steps of the built dt

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        register_all(self, VARIABLES)
        self._rig = None

    @property
    def stepped_rig(self):
        """The rig model this FMU steps (Rig or RigChain), for an engine that steps it in process."""
        return self._rig

    def _params(self) -> RigParameters:
        return RigParameters(**{f.name: getattr(self, f.name) for f in dataclasses.fields(RigParameters)})

    def exit_initialization_mode(self):
        """Build the rig at its starting height and force, and output its latency in steps."""
        self.check_parameters()
        if self.rig_chain == 1:
            spec = load_rig_file(Path(self.resources) / RIG_FILE)
            self._rig = RigChain(spec, self.time_step, self.height_command, self.true_force, self.force_offset_N,
                                 self.noise_std_N, int(self.noise_seed))
            self.latency_steps = latency_steps(spec, self.time_step)
            self.actuator_height = self.height_command
            return
        params = self._params()
        self._rig = Rig(params, self.time_step, self.height_command, self.true_force)
        self.latency_steps = params.latency_steps(self.time_step)
        self.actuator_height = self.height_command

    def do_step(self, current_time, step_size):
        """One sample of the rig: the actuator height and the measured force of this step."""
        self.actuator_height, self.measured_force = self._rig.step(self.height_command, self.true_force)
        return True
