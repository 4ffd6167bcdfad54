"""What the PFEM operators of a catenary are, apart from how they are built (operators.py): their
discretisation (`PfemSettings`) and the operators of one block (`PfemOperators`), which the operator file
stores (operator_file.py) and the HIL iteration steps (models/hil/droppers.py). In a module of their own so
that reading and stepping operators (the catenary FMU, which imports what it steps with itself:
fmus/own_package.py) needs none of what building them imports (scipy.fft, the finite-element model)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class PfemSettings:
    """Discretisation of the operators (Paper C sec. 6: dw = 0.025 rad/s, w_max = 750 rad/s)."""

    speed_m_s: float
    dt_s: float
    samples_per_span: int
    n_harmonics: int  # N_h: harmonics 0..N_h-1 kept in the contact height
    n_harmonics_dropper: int  # N_hd: harmonics kept in the dropper elongations
    omega_max: float = 750.0
    grid: str = "graded"  # "graded": dw = resolution (alpha + beta w^2); "uniform": dw = d_omega
    resolution: float = 0.094
    d_omega: float = 0.025
    max_step_rad_s: float = 0.5
    taper: float = 0.25  # fraction of [0, w_max] over which the transform is tapered to zero


@dataclass
class PfemOperators:
    """Operators stored by the column the HIL step uses, so that each update reads contiguous memory.

    cc[m]          : height at every sample n per unit contact force at sample m (N x N)
    dc[m, d]       : harmonics 0..N_hd-1 (over the window index) of the elongation of dropper d per
                     unit contact force at m (N x N_d x N_hd, complex, rfft convention)
    cd[m, d]       : height at every n per unit correction of dropper d at the instant of phase m
    dd[d, i, e]    : harmonics of the elongation of dropper e per unit correction of dropper d at its
                     window index i (N_d x N x N_d x N_hd, complex)
    """

    settings: PfemSettings
    cc: np.ndarray
    dc: np.ndarray
    cd: np.ndarray
    dd: np.ndarray
    z0: np.ndarray  # static contact-point height at the N samples, unreduced
    window_start: np.ndarray  # first instant of each dropper's window (may be negative)
    dropper_tension_N: np.ndarray
    dropper_stiffness_N_m: np.ndarray
    dropper_x_m: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of contact samples N of the block."""
        return self.cc.shape[0]

    @property
    def n_droppers(self) -> int:
        """Number of droppers of the block."""
        return len(self.dropper_x_m)
