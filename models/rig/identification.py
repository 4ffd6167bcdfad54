"""Identification of a rig's frequency response at the kept harmonics, with a rigid mass mounted.

A Schroeder multisine at the harmonics k < N_h of the span (those the catenary keeps, Paper D eqs.
4-8) commands the actuator, faded in over a settling span; the actuator height and the load cell's
force are recorded over whole periods of the rig's clocks (Paper B sec. 4: N_com and the drive's
sub-references). The mass on the actuator (Paper B sec. 5.1's validation test) makes the true force
its inertia, computed from the recorded height with the rigid-mass model the virtual runs and the
rig emulator use (`models/pantograph/lumped.py`, Newmark differentiation). The gains command ->
height and true -> measured force per harmonic are the ratios of the spectra, the estimator of
`drive_chain.frequency_response`, so that a rig identified through its own chain reproduces the
model's response. The result is the `[response]` table of a rig file (`rig_file.py`), with which
a case compensates the rig (Paper D sec. 3.4 generalised, `compensation.py`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import PantohilError
from ..pantograph.interface import make_pantograph, pantograph_model
from ..pantograph.lumped import PantographParameters
from .drive_chain import MeasuredResponse, RigChain, RigSpec, harmonic_gains, multisine, record_spans


class IdentificationError(PantohilError, ValueError):
    """An identification whose record cannot give a response (a lost sample, a gain of zero)."""


@dataclass(frozen=True)
class Excitation:
    """The multisine of an identification: N samples per span, N_h kept harmonics, `settle_spans` spans
    not recorded (the first faded in), then `record_spans` whole spans recorded."""

    samples_per_span: int
    n_harmonics: int
    dt_s: float
    record_spans: int
    amplitude_m: float = 1e-3
    settle_spans: int = 3  # the drive's motion profile settles 2 spans after the fade-in (measured)

    @property
    def total_steps(self) -> int:
        """Steps of the excitation: settling and recorded spans [-]."""
        return (self.settle_spans + self.record_spans) * self.samples_per_span

    @property
    def record(self) -> slice:
        """The recorded steps (after the settling spans)."""
        return slice(self.settle_spans * self.samples_per_span, self.total_steps)

    def heights(self, steps: int | None = None) -> np.ndarray:
        """The commanded heights [m] (`steps` of them, default the excitation's): the multisine times
        `amplitude_m`, faded in with a raised cosine over the first span so that the actuator starts at
        rest at 0; span-periodic after it."""
        n = self.samples_per_span
        steps = self.total_steps if steps is None else steps
        shape = multisine(n, self.n_harmonics, steps, self.dt_s)
        fade = np.ones(steps)
        fade[:n] = 0.5 * (1 - np.cos(np.pi * np.arange(n) / n))
        return self.amplitude_m * shape * fade

    def frequencies_hz(self) -> np.ndarray:
        """The kept harmonics k = 1..N_h-1 of the span [Hz]."""
        return np.arange(1, self.n_harmonics) / (self.samples_per_span * self.dt_s)


def excitation(spec: RigSpec | None, dt_s: float, samples_per_span: int, n_harmonics: int,
               amplitude_m: float = 1e-3, spans: int | None = None) -> Excitation:
    """The excitation for a rig: recorded over whole periods of its clocks (`record_spans`), or over
    `spans` spans if given; a rig of unknown clocks (no rig file) over 8 spans."""
    if spans is None:
        spans = record_spans(spec, dt_s, samples_per_span) if spec is not None else 8
    return Excitation(samples_per_span, n_harmonics, dt_s, spans, amplitude_m)


def mass_force(mass: PantographParameters, dt_s: float, heights: np.ndarray) -> np.ndarray:
    """The true force of a rigid mass that follows `heights` from rest at 0 (Paper B sec. 5.1: the load
    cell reads -m (g + z''), z'' by the Newmark relations of `RigidMass`) [N]."""
    pan = make_pantograph(mass, dt_s)
    pan.settle(0.0)
    return np.array([pan.step(float(z)) for z in heights])


def estimate(exc: Excitation, command: np.ndarray, height: np.ndarray, true_force: np.ndarray,
             measured_force: np.ndarray) -> MeasuredResponse:
    """The rig's gains at the kept harmonics from aligned records of the whole excitation: command ->
    actuator height and true -> measured force (ratios of the spectra over the recorded spans)."""
    rec = exc.record
    records = {"command": command, "actuator height": height, "true force": true_force,
               "measured force": measured_force}
    for name, x in records.items():
        if len(x) != exc.total_steps:
            raise IdentificationError(f"{name}: {len(x)} samples for an excitation of {exc.total_steps}")
        bad = np.flatnonzero(~np.isfinite(x[rec]))
        if len(bad):
            raise IdentificationError(f"{name}: {len(bad)} samples of the record not measured (the first at step "
                                      f"{rec.start + bad[0]}); nothing identified")
    gz = harmonic_gains(command[rec], height[rec], exc.record_spans, exc.n_harmonics)[1:]
    gf = harmonic_gains(true_force[rec], measured_force[rec], exc.record_spans, exc.n_harmonics)[1:]
    for name, g in (("command -> height", gz), ("true -> measured force", gf)):
        weak = np.flatnonzero(~np.isfinite(g) | (np.abs(g) < 1e-6))
        if len(weak):
            raise IdentificationError(f"{name}: no response at {exc.frequencies_hz()[weak[0]]:.4g} Hz (a gain of zero "
                                      f"or an input without that harmonic)")
    return MeasuredResponse(tuple(float(f) for f in exc.frequencies_hz()), tuple(complex(g) for g in gz),
                            tuple(complex(g) for g in gf))


def identify_chain(spec: RigSpec, exc: Excitation, mass: PantographParameters, force_offset_N: float = 0.0,
                   noise_std_N: float = 0.0, noise_seed: int = 0) -> MeasuredResponse:
    """Identify a rig file's chain in process (Paper B sec. 4, Paper D sec. 2): the multisine through
    `RigChain` with the mass on the actuator, in the order the rig emulator steps them (height, the
    mass's force, the load cell)."""
    chain = RigChain(spec, exc.dt_s, 0.0, 0.0, force_offset_N, noise_std_N, noise_seed)
    pan = make_pantograph(mass, exc.dt_s)
    pan.settle(0.0)
    command = exc.heights()
    out = np.empty((len(command), 3))
    for i, z in enumerate(command):
        height = chain.height(float(z))
        true = pan.step(height)
        out[i] = height, true, chain.force(true)
    return estimate(exc, command, out[:, 0], out[:, 1], out[:, 2])


def response_errors(measured: MeasuredResponse, height: np.ndarray, force: np.ndarray) -> dict:
    """Per harmonic, the identified gains against reference gains (the model's `frequency_response` at
    k = 1..N_h-1): relative magnitude errors [-] and phase errors [deg], and their maxima."""
    out = {}
    for name, got, ref in (("height", measured.height, height), ("force", measured.force, force)):
        ratio = np.asarray(got, complex) / np.asarray(ref, complex)
        mag = np.abs(np.abs(ratio) - 1)
        deg = np.abs(np.degrees(np.angle(ratio)))
        out[name] = {"magnitude_error": mag.tolist(), "phase_error_deg": deg.tolist(),
                     "max_magnitude_error": float(mag.max(initial=0.0)),
                     "max_phase_error_deg": float(deg.max(initial=0.0))}
    return out


def is_mass(params: PantographParameters) -> bool:
    """Whether a case's pantograph is a rigid mass on the actuator (what an identification mounts)."""
    return (pantograph_model(params).fixed_to_actuator and math.isfinite(params.masses_kg[0])
            and params.masses_kg[0] > 0)
