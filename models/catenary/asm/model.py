"""ASM2 as a registered catenary model (`[catenary] model = "asm"`, Papers A-B): the circulant operator of
the analytical string (Paper B eqs. 6-11) built from the [catenary] string data, the static height from the
profile staged as profile.csv, and the closed-form steady force as the run's reference (Paper A eqs. 38-41)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, fields
from pathlib import Path

import numpy as np

from pantohil.models.catenary.asm.closed_form import one_sided_harmonics, pair_forces, single_pantograph
from pantohil.models.catenary.asm.pair import (
    PairSpec,
    pair_static_compliance_m_N,
    read_receptance_csv,
    second_offset_m,
    write_receptance_csv,
)
from pantohil.models.catenary.asm.pair_iteration import pair_iteration as asm_pair_iteration
from pantohil.models.catenary.asm.string import AsmParameters, receptance_direct
from pantohil.models.catenary.grid import SpanGrid
from pantohil.models.catenary.profile import read_profile_csv, write_profile_csv
from pantohil.models.catenary.receptance import CirculantOperator, asm_operator, reduce_harmonics
from pantohil.models.hil.loop import PeriodicHil
from pantohil.models.pantograph.interface import receptance

PROFILE_FILE = "profile.csv"
ASM_FIELDS = tuple(f.name for f in fields(AsmParameters))  # case keys of [catenary] = FMU parameters


def staged_profile(grid: SpanGrid, resources: Path) -> np.ndarray:
    """The static height z0 at the grid's samples, from a staged profile.csv [m]."""
    return read_profile_csv(Path(resources) / PROFILE_FILE, grid.span_m).heights(grid.positions_m())


def staged_pair_profiles(grid: SpanGrid, resources: Path, pair: PairSpec) -> np.ndarray:
    """The static height at the grid's samples of both contact points, (2, N) [m], from a staged profile.csv."""
    profile = read_profile_csv(Path(resources) / PROFILE_FILE, grid.span_m)
    x = grid.positions_m()
    return np.array([profile.heights(x), profile.heights(x + second_offset_m(pair.spacing_m, pair.position))])


def stage_profile(case, folder: Path) -> list[Path]:
    """Write the case's static profile as profile.csv."""
    write_profile_csv(folder / PROFILE_FILE, case.profile)
    return [folder / PROFILE_FILE]


def closed_form_reference(case) -> np.ndarray:
    """The ASM closed-form steady force with the run's harmonic content (Paper A eqs. 38-41) [N]."""
    z0 = case.z0_samples()
    ss = single_pantograph(case.catenary, case.pantograph, case.speed_m_s, case.span_m, one_sided_harmonics(z0),
                           case.pantograph.uplift_force_N, case.n_harmonics)
    return ss.force_series(case.samples_per_span)


class AsmModel:
    """The ASM2 string (Papers A-B)."""

    pair_stability_map = True  # the pair's span map (models/stability/pair_map.py)
    structural_keys: tuple[str, ...] = ()  # the operator is built from the parameters at initialisation

    def check(self, case) -> None:
        """Every case the case schema accepts runs (the speed is checked below the wave speed there)."""

    def prepare(self, case, progress: bool) -> dict | None:
        """Nothing to build ahead."""
        return None

    def stage(self, case, folder: Path, link: bool = False) -> list[Path]:
        """profile.csv; with a compensated second pantograph also the pantograph's receptance at the kept
        harmonics (pantograph_receptance.csv, the pair's coupling compensation)."""
        files = stage_profile(case, folder)
        second = case.sections.second_pantograph
        if second is not None and second.coupling_compensation:
            omega = 2 * np.pi * np.arange(case.n_harmonics) / (case.samples_per_span * case.dt_s)
            files.append(write_receptance_csv(folder, receptance(case.pantograph, omega)))
        return files

    def iteration(self, grid: SpanGrid, parameters: Mapping[str, object], resources: Path, settings, compensation):
        """PeriodicHil on I_cc of ASM2 (compensated: I B, Paper D eq. 10)."""
        cat = AsmParameters(**{f: float(parameters[f]) for f in ASM_FIELDS})
        z0 = staged_profile(grid, resources)
        op = asm_operator(cat, grid.speed_m_s, grid.samples_per_span, grid.dt_s, grid.n_harmonics)
        if compensation is not None:
            op = CirculantOperator(compensation.compensate_kernel(op.kernel))
        return PeriodicHil(op, reduce_harmonics(z0, grid.n_harmonics), settings, compensation), z0

    def pair_iteration(self, grid: SpanGrid, parameters: Mapping[str, object], resources: Path, settings,
                       delay_steps: tuple[int, int], pair: PairSpec):
        """The iteration of two contact points (models/catenary/asm/pair_iteration.py) from a staged folder, and
        the static heights of both (2, N)."""
        cat = AsmParameters(**{f: float(parameters[f]) for f in ASM_FIELDS})
        z0 = staged_pair_profiles(grid, resources, pair)
        hp = read_receptance_csv(Path(resources), grid.n_harmonics) if pair.compensated else None
        return asm_pair_iteration(cat, grid, z0, settings, delay_steps, pair, hp), z0

    def static_compliance_m_N(self, case) -> float:
        """H11(0) of the string (Paper A eq. 14); with a second pantograph, the first point's mean height per unit
        mean force of both, H11(0) + H12(0) or H21(0) (models/catenary/asm/pair.py), so that the first's converged
        mean force is the uplift force wherever it runs (virtual, on the rig, in the rig emulator)."""
        second = case.sections.second_pantograph
        if second is not None:
            return pair_static_compliance_m_N(case.catenary, case.speed_m_s, second.spacing_m, second.position)[0]
        return float(np.real(receptance_direct(case.catenary, 0.0, case.speed_m_s)))

    def stability_operator(self, case, n_harmonics: int):
        """The circulant kernel at n_harmonics."""
        return asm_operator(case.catenary, case.speed_m_s, case.samples_per_span, case.dt_s, n_harmonics).kernel, None

    def summary(self, case) -> dict:
        """The string data."""
        return {"model": case.model, "span_m": case.span_m, **asdict(case.catenary)}

    def dropper_positions_m(self, case) -> list[float]:
        """None: the string has no droppers."""
        return []

    def reference_force(self, case):
        """The closed form (Paper A eqs. 38-41)."""
        return "asm closed form (Paper A eqs. 38-41), same harmonics", closed_form_reference(case)

    def pair_reference_forces(self, case, z0_pair: np.ndarray):
        """The closed form of two pantographs (Paper A eqs. 24-25) at each point's samples, shape (2, N)."""
        second = case.sections.second_pantograph
        forces = pair_forces(case.catenary, case.pantograph, case.speed_m_s, case.dt_s, z0_pair,
                             case.pantograph.uplift_force_N, case.n_harmonics, second.spacing_m,
                             second.position == "leading")
        return "asm closed form of two pantographs (Paper A eqs. 24-25), same harmonics", forces
