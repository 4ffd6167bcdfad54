"""The pantograph models' interface and their registry (`PANTOGRAPHS`, entry-point group
`pantohil.pantographs`).

A pantograph model is built from the case's [pantograph] section (`PantographParameters`) and gives a
time-domain model to step (`SteppedPantograph`: settle, step, head height, force), its contact-point
receptance (Paper A eq. 18) and its one-step linear map for the stability maps (Paper D eq. A.3). A test
checks for every registered model that the linear map reproduces the model's own steps in contact.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from pantohil.models.registry import Registry

from .linear import LinearPantograph, chain_linear, rigid_mass_linear
from .lumped import ChainPantograph, PantographParameters, RigidMass, chain_receptance


@runtime_checkable
class SteppedPantograph(Protocol):
    """A pantograph stepped in time against an imposed contact-point height."""

    force: float

    def settle(self, z: float) -> float:
        """Rest at the wire height z; returns the static contact force [N]."""

    def step(self, z_next: float) -> float:
        """Advance one time step to the height z_next at its end; returns the contact force there [N]."""

    @property
    def head_height(self) -> float:
        """Height of the head [m]."""


class PantographModel(Protocol):
    """One kind of pantograph model, registered by name in `PANTOGRAPHS`."""

    fixed_to_actuator: bool  # bolted to the actuator (no contact spring, no contact loss): a rig's test mass

    def build(self, params: PantographParameters, dt_s: float, reference_height_m: float) -> SteppedPantograph:
        """The time-domain model of the parameters, at time step dt_s."""

    def receptance(self, params: PantographParameters, omega_rad_s: np.ndarray) -> np.ndarray:
        """Contact-point receptance H_p(omega) [m/N] (Paper A eq. 18)."""

    def linear(self, params: PantographParameters, dt_s: float) -> LinearPantograph:
        """The homogeneous one-step map of `build`'s model in contact (Paper D eq. A.3)."""


class Chain:
    """The chain of 1-3 lumped masses with penalty contact (Paper A sec. 2, Table A.3)."""

    fixed_to_actuator = False

    def build(self, params, dt_s, reference_height_m):
        """ChainPantograph: HHT with unilateral penalty contact."""
        return ChainPantograph(params, dt_s, reference_height_m)

    def receptance(self, params, omega_rad_s):
        """1/k_c + [K - w^2 M + i w C]^-1_(1,1), Paper A eq. (18)."""
        return chain_receptance(params, omega_rad_s)

    def linear(self, params, dt_s):
        """The HHT step with the contact active."""
        return chain_linear(params, dt_s)


class RigidMassModel:
    """A rigid mass fixed to the actuator (Paper B sec. 5.1): the rig's test mass."""

    fixed_to_actuator = True

    def build(self, params, dt_s, reference_height_m):
        """RigidMass: the Newmark differentiator of the actuator's position."""
        return RigidMass(params, dt_s)

    def receptance(self, params, omega_rad_s):
        """-1/(m w^2), defined for w > 0 only."""
        omega = np.atleast_1d(np.asarray(omega_rad_s, dtype=float))
        with np.errstate(divide="ignore"):
            return -1.0 / (params.masses_kg[0] * omega**2) + 0j

    def linear(self, params, dt_s):
        """The Newmark differentiator f = -m z''."""
        return rigid_mass_linear(params, dt_s)


PANTOGRAPHS: Registry[PantographModel] = Registry("pantograph model", "pantohil.pantographs",
                                                  {"chain": Chain, "rigid_mass": RigidMassModel})
"""Every pantograph model by name; `[pantograph] model` chooses one."""


def pantograph_model(params: PantographParameters) -> PantographModel:
    """The registered model that `params.model` names."""
    return PANTOGRAPHS.get(params.model, "pantograph.model")


def make_pantograph(params: PantographParameters, dt: float, reference_height_m: float = 0.0) -> SteppedPantograph:
    """The time-domain model of a parameter set, from the model its `model` names."""
    return pantograph_model(params).build(params, dt, reference_height_m)


def linear_pantograph(params: PantographParameters, dt: float) -> LinearPantograph:
    """The homogeneous one-step map of the case's pantograph in contact (Paper D eq. A.3)."""
    return pantograph_model(params).linear(params, dt)


def receptance(params: PantographParameters, omega_rad_s) -> np.ndarray:
    """Contact-point receptance H_p(omega) of the case's pantograph [m/N] (Paper A eq. 18)."""
    return pantograph_model(params).receptance(params, omega_rad_s)


def static_compliance_m_N(params: PantographParameters) -> float:
    """Head displacement per unit head force at rest, contact spring in series; 0 for a mass fixed to the
    actuator."""
    if pantograph_model(params).fixed_to_actuator:
        return 0.0
    return float(receptance(params, 0.0)[0].real)
