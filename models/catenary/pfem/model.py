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

from pantohil.models.catenary.grid import SpanGrid
from pantohil.models.catenary.pfem.operator_file import load_operators
from pantohil.models.errors import InputError
from pantohil.models.hil.droppers import PfemHil

OPERATOR_FILE = "operators.npz"
MAX_DROPPERS = 12  # the dropper outputs the catenary FMU declares


class PfemModel:
    """The periodic finite-element catenary with dropper slackening (Papers C-D)."""

    # every [catenary] key: the operators are built from the catenary file the case fits them from
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
        """operators.npz (copied, or linked to the cache entry)."""
        import shutil

        from .operator_cache import case_operators

        source = Path(case_operators(case, progress=False).path).resolve()
        if link:
            (folder / OPERATOR_FILE).symlink_to(source)
        else:
            shutil.copy2(source, folder / OPERATOR_FILE)
        return [folder / OPERATOR_FILE]

    def iteration(self, grid: SpanGrid, parameters: Mapping[str, object], resources: Path, settings, compensation):
        """PfemHil on the staged operators, which must be of this grid (Paper C eqs. 34-40, Paper D eqs. 11-12)."""
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
        hil = PfemHil(ops, settings, float(parameters["dropper_relaxation"]), bool(parameters["droppers"]),
                      compensation)
        return hil, ops.z0

    def static_compliance_m_N(self, case) -> float:
        """H11(0) of the ASM2 string fitted to the catenary file (Paper A sec. 4), as the run has always set
        the pantograph: the mean force converges to the uplift force up to the fit's static error."""
        from pantohil.models.catenary.asm.string import receptance_direct

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
