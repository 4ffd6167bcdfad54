"""The PFEM as a registered catenary model (`[catenary] model = "pfem"`, Papers C-D): one span of the case's
catenary file with periodic boundaries, its operators built once and cached (operator_cache.py), staged as
operators.npz, and the HIL iteration with dropper slackening on them (models/hil/droppers.py).

What the iteration needs is imported with this module, not where the iteration is built: the catenary FMU builds
it after its import, when a function-level import would find whatever pantohil the process holds, not the FMU's
own (fmus/own_package.py). What only a case's checks, staging and stability maps need is imported where used."""
from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

from pantohil.models.catenary.asm.pair import second_offset_m
from pantohil.models.catenary.grid import SpanGrid
from pantohil.models.catenary.pfem.operator_file import load_operators
from pantohil.models.catenary.pfem.pair_operators import PAIR_FILE, load_cross_operators, pair_operators, sample_shift
from pantohil.models.errors import InputError
from pantohil.models.hil.droppers import PfemHil
from pantohil.models.hil.pfem_pair import PfemPairHil

OPERATOR_FILE = "operators.npz"
MAX_DROPPERS = 12  # the dropper outputs the catenary FMU declares


class PfemModel:
    """The periodic finite-element catenary with dropper slackening (Papers C-D)."""

    # every [catenary] key: the operators are built from the catenary file the case fits them from
    pair_stability_map = True  # the pair's span map (models/stability/pair_map.py) on the dense operators
    structural_keys = ("tension_N", "density_kg_m", "support_stiffness_N_m2", "alpha_1_s", "beta_s")

    def check(self, case) -> None:
        """A catenary file that form-finds, and a transform within the Nyquist frequency."""
        from pantohil.models.catenary.fe.analysis import cached_analysis
        from pantohil.models.catenary.fe.definition import CatenaryError

        p = case.sections.pfem
        if case.definition_path is None:
            raise InputError("catenary.definition_file: required when catenary.model = \"pfem\" (the span to model)",
                             key="catenary.definition_file")
        try:
            cached_analysis(case.definition_path)
        except CatenaryError as exc:
            raise InputError(f"catenary.definition_file: {exc}", key="catenary.definition_file") from None
        if p.omega_max_rad_s > math.pi / case.dt_s:
            raise InputError(f"pfem.omega_max_rad_s: {p.omega_max_rad_s:g} rad/s is above the Nyquist frequency "
                             f"pi/dt = {math.pi / case.dt_s:.1f} rad/s", key="pfem.omega_max_rad_s")

    def prepare(self, case, progress: bool) -> dict | None:
        """The operators, from the cache or built now; their build summary."""
        from .operator_cache import case_operators

        return case_operators(case, progress).summary()

    def stage(self, case, folder: Path, link: bool = False) -> list[Path]:
        """operators.npz (copied, or linked to the cache entry); with a second pantograph also the pair's cross
        operators (pair_operators.npz)."""
        import shutil

        from .operator_cache import case_cross_operators, case_operators

        sources = {OPERATOR_FILE: Path(case_operators(case, progress=False).path).resolve()}
        second = case.sections.second_pantograph
        if second is not None:
            offset = second_offset_m(second.spacing_m, second.position)
            sources[PAIR_FILE] = case_cross_operators(case, offset, progress=False).resolve()
        for name, source in sources.items():
            if link:
                (folder / name).symlink_to(source)
            else:
                shutil.copy2(source, folder / name)
        return [folder / name for name in sources]

    def iteration(self, grid: SpanGrid, parameters: Mapping[str, object], resources: Path, settings, compensation):
        """PfemHil on the staged operators, which must be of this grid (Paper C eqs. 34-40, Paper D eqs. 11-12)."""
        ops = self._staged_operators(grid, resources)
        hil = PfemHil(ops, settings, float(parameters["dropper_relaxation"]), bool(parameters["droppers"]),
                      compensation)
        return hil, ops.z0

    @staticmethod
    def _staged_operators(grid: SpanGrid, resources: Path):
        """The staged operators.npz, which must be of this grid."""
        ops = load_operators(Path(resources) / OPERATOR_FILE)
        s = ops.settings
        if (s.samples_per_span != grid.samples_per_span or abs(s.dt_s - grid.dt_s) > 1e-12
                or s.n_harmonics != grid.n_harmonics):
            raise ValueError(f"{OPERATOR_FILE} was built for N = {s.samples_per_span}, dt = {s.dt_s}, N_h = "
                             f"{s.n_harmonics}; the parameters give N = {grid.samples_per_span}, dt = {grid.dt_s}, "
                             f"N_h = {grid.n_harmonics}")
        if ops.n_droppers > MAX_DROPPERS:
            raise ValueError(f"the PFEM block has {ops.n_droppers} droppers; the catenary FMU reports at most "
                             f"{MAX_DROPPERS}")
        return ops

    def check_pair(self, case, hardware: bool = False) -> None:
        """What the PFEM pair runs (models/hil/pfem_pair.py): virtual, linear droppers, no coupling compensation.
        A dropper slackened by one pantograph is not coupled to the other pantograph's point and droppers
        (measured: the trailing pantograph 9 % above `pantohil fem-sim` in std), so slackening is refused."""
        second = case.sections.second_pantograph
        if case.sections.pfem.droppers:
            raise InputError("pfem.droppers: two pantographs on the PFEM run with droppers that do not slacken (a "
                             "dropper one pantograph slackens is not coupled to the other's); set pfem.droppers = "
                             "false, or run the pair with slackening in `pantohil fem-sim`", key="pfem.droppers")
        if second.coupling_compensation:
            raise InputError("second_pantograph.coupling_compensation: not on the PFEM (its operators are not "
                             "circulant); set it to false", key="second_pantograph.coupling_compensation")
        if hardware:
            raise InputError("second_pantograph: two pantographs on the PFEM run virtually (a pair with one on the rig "
                             "runs on catenary.model = \"asm\")", key="second_pantograph")
        try:
            sample_shift(case.pfem_settings(), second_offset_m(second.spacing_m, second.position))
        except ValueError as exc:
            raise InputError(f"second_pantograph.spacing_m: {exc}", key="second_pantograph.spacing_m") from None

    def pair_iteration(self, grid: SpanGrid, parameters: Mapping[str, object], resources: Path, settings,
                       delay_steps: tuple[int, int], pair):
        """PfemPairHil on the staged operators and cross operators (models/hil/pfem_pair.py), and the static
        heights of both points (2, N). The coupling compensation needs circulant operators: refused here."""
        if pair.compensated:
            raise ValueError("second_pantograph.coupling_compensation: not on the PFEM (its operators are not "
                             "circulant); set it to false")
        ops = self._staged_operators(grid, resources)
        offset = second_offset_m(pair.spacing_m, pair.position)
        i12, i21, shift = load_cross_operators(Path(resources) / PAIR_FILE, ops.n, offset)
        if shift != sample_shift(ops.settings, offset):
            raise ValueError(f"{PAIR_FILE}: built for a shift of {shift} samples, not this offset's")
        operators = pair_operators(ops, i12, i21, shift)
        hil = PfemPairHil(operators, settings, delay_steps, float(parameters["dropper_relaxation"]),
                          bool(parameters["droppers"]))
        return hil, operators.z0

    def static_compliance_m_N(self, case) -> float:
        """H11(0) of the ASM2 string fitted to the catenary file (Paper A sec. 4), as the run has always set
        the pantograph: the mean force converges to the uplift force up to the fit's static error; with a
        second pantograph the fitted string's H11(0) + H12(0) or H21(0), as for ASM2."""
        from pantohil.models.catenary.asm.pair import pair_static_compliance_m_N
        from pantohil.models.catenary.asm.string import receptance_direct

        second = case.sections.second_pantograph
        if second is not None:
            return pair_static_compliance_m_N(case.catenary, case.speed_m_s, second.spacing_m, second.position)[0]
        return float(receptance_direct(case.catenary, 0.0, case.speed_m_s).real)

    def stability_operator(self, case, n_harmonics: int):
        """I_cc reduced to n_harmonics on its observed index (W~); the case's operators keep at most N_h."""
        import numpy as np

        from pantohil.models.catenary.receptance import reduce_harmonics

        from .operator_cache import case_operators

        if n_harmonics > case.n_harmonics:
            raise InputError(f"f_max: {n_harmonics} harmonics needed; this PFEM case's operators keep "
                             f"{case.n_harmonics} (raise hil.max_frequency_hz)", key="hil.max_frequency_hz")
        ops = load_operators(case_operators(case, progress=False).path)
        i_cc = np.asarray(ops.cc, dtype=float).T  # ops.cc[m] is column m: the heights per unit force at sample m
        return None, np.apply_along_axis(reduce_harmonics, 0, i_cc, n_harmonics)

    def summary(self, case) -> dict:
        """The catenary file and the discretisation of its operators."""
        p, s = case.sections.pfem, case.pfem_settings()
        return {"model": case.model, "span_m": case.span_m, "definition_file": str(case.definition_path),
                "droppers_slacken": p.droppers, "dropper_relaxation": p.dropper_relaxation,
                "dropper_harmonics": s.n_harmonics_dropper, "omega_max_rad_s": s.omega_max,
                "grid_resolution": s.resolution, "taper": s.taper}

    def dropper_positions_m(self, case) -> list[float]:
        """The catenary file's dropper positions within the span, if they slacken."""
        from pantohil.models.catenary.fe.definition import load_definition

        if not case.sections.pfem.droppers:
            return []
        return [float(x) for x in load_definition(case.definition_path).dropper_positions_m]

    def reference_force(self, case):
        """None here: the reference of a PFEM case is `pantohil fem-sim`."""
        return None
