"""Rig FMU: the HIL rig's delay, communication decimation with the drive's ramp, servo, load-cell
filter, force offset and noise (Paper B sec. 4, Paper D secs. 2 and 5.1)."""
from __future__ import annotations

from pantohil.fmus.fmu_support import PantohilSlave, Var, register_all
from pantohil.models.rig.chain import Rig, RigParameters

VARIABLES = [
    Var("delay_steps", "integer", "parameter", "1", "Pure delay of the height path in steps", 0, 0),
    Var(
        "comm_decimation",
        "integer",
        "parameter",
        "1",
        "N_com: one height of every N_com reaches the drive (1: all)",
        1,
        1,
    ),
    Var("servo_bandwidth", "real", "parameter", "Hz", "Servo natural frequency (0: ideal tracking)", 0.0, 0.0),
    Var("servo_damping", "real", "parameter", "1", "Servo damping ratio", 0.7, 0.0),
    Var("loadcell_cutoff", "real", "parameter", "Hz", "Load-cell low-pass cut-off (0: none)", 0.0, 0.0),
    Var("force_offset", "real", "parameter", "N", "Force added to the measurement", 0.0),
    Var("noise_std", "real", "parameter", "N", "Measurement noise standard deviation", 0.0, 0.0),
    Var("noise_seed", "integer", "parameter", "1", "Seed of the measurement noise", 0, 0),
    Var("time_step", "real", "parameter", "s", "Sampling time dt", 0.001, 1e-6),
    Var("height_command", "real", "input", "m", "Height commanded by the catenary model", 0.0),
    Var("true_force", "real", "input", "N", "Contact force at the pantograph", 0.0),
    Var("actuator_height", "real", "output", "m", "Height reached by the actuator", 0.0),
    Var("measured_force", "real", "output", "N", "Force as measured by the load cell", 0.0),
    Var("latency_steps", "integer", "output", "1", "Rig latency in whole steps, for the delay advance", 0),
]


class PantohilRig(PantohilSlave):
    """The rig FMU: delay, N_com decimation with the drive's ramp, servo, load cell, offset and noise."""
    author = "pantohil"
    description = (
        "HIL rig between model and pantograph: delay, N_com decimation with linear drive ramp, servo, load cell."
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        register_all(self, VARIABLES)
        self._rig = None

    def _params(self) -> RigParameters:
        return RigParameters(int(self.delay_steps), int(self.comm_decimation), self.servo_bandwidth,
                             self.servo_damping, self.loadcell_cutoff, self.force_offset, self.noise_std,
                             int(self.noise_seed))

    def exit_initialization_mode(self):
        """Build the rig at its starting height and force, and output its latency in steps."""
        params = self._params()
        self._rig = Rig(params, self.time_step, self.height_command, self.true_force)
        self.latency_steps = params.latency_steps(self.time_step)
        self.actuator_height = self.height_command

    def do_step(self, current_time, step_size):
        """One sample of the rig: the actuator height and the measured force of this step."""
        self.actuator_height, self.measured_force = self._rig.step(self.height_command, self.true_force)
        return True
