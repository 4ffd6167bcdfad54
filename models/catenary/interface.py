"""The periodic catenary models' interface and their registry (`CATENARIES`, entry-point group
`pantohil.catenaries`).

A catenary model gives the HIL iteration of one span (Paper D sec. 3). It checks a case it is to run,
stages into a folder the resources its operator is built from (the catenary FMU carries them in
resources/), builds the iteration from such a folder and the catenary FMU's parameter values, and gives
its operator at a number of harmonics for the stability maps, its part of summary.json and, where it has
one, a reference steady force. The catenary FMU, the in-process engine (which initialises the FMU's
class) and the test loop (`case_iteration`) all build the iteration through `iteration` from a staged
folder, so that they step the same operator to the bit.

The iteration has the interface of `PeriodicHil` (models/hil/loop.py): `step(force) -> command`, `n`,
`k`, `z`, `force_estimate`, `command_at`, `ahead`, `CONSTANT_ATTRIBUTES`; one with slackening droppers
also has `nd > 0`, `current_correction` and `correction_at` (models/hil/droppers.py).
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from pantohil.models.registry import Registry

from .asm.model import AsmModel
from .grid import SpanGrid
from .pfem.model import PfemModel

if TYPE_CHECKING:
    from pantohil.models.hil.loop import HilSettings
    from pantohil.models.rig.compensation import HarmonicCompensation

Case = Any  # a validated case (models/case.py `Case`), which imports this module for its choices


class CatenaryModel(Protocol):
    """One kind of periodic catenary model, registered by name in `CATENARIES`; `[catenary] model` chooses."""

    structural_keys: tuple[str, ...]  # catenary FMU parameters (besides the grid) its staged resources fix
    pair_stability_map: bool  # its pair iteration gives the pair's span map (models/stability/pair_map.py)

    def check(self, case: Case) -> None:
        """Refuse a case this model cannot run: an InputError naming the key."""

    def prepare(self, case: Case, progress: bool) -> dict | None:
        """Build ahead what staging needs (with a progress bar); its part of summary.json, or None."""

    def stage(self, case: Case, folder: Path, link: bool = False) -> list[Path]:
        """Write into `folder` the resources `iteration` builds from; `link`: large files as symbolic links."""

    def iteration(self, grid: SpanGrid, parameters: Mapping[str, object], resources: Path, settings: HilSettings,
                  compensation: HarmonicCompensation | None):
        """(the HIL iteration, the static height z0 at the N samples [m]) from a staged folder and the catenary
        FMU's parameter values by name (models/parameters.py's naming rule)."""

    def static_compliance_m_N(self, case: Case) -> float:
        """The contact point's mean height per unit contact force at rest, H(0) [m/N] (where the pantograph
        is set so that its converged mean force is the uplift force)."""

    def stability_operator(self, case: Case, n_harmonics: int) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The operator at n_harmonics for the stability maps: (circulant kernel, None) or (None, I_cc)."""

    def summary(self, case: Case) -> dict:
        """Its part of summary.json's `catenary` (with `model` and `span_m`)."""

    def dropper_positions_m(self, case: Case) -> list[float]:
        """Positions in the span of the droppers whose slackening the iteration corrects [m]; [] for none."""

    def reference_force(self, case: Case) -> tuple[str, np.ndarray] | None:
        """(its name, the steady force at the N samples [N]) that a run is compared with, or None."""


CATENARIES: Registry[CatenaryModel] = Registry("catenary model", "pantohil.catenaries",
                                               {"asm": AsmModel, "pfem": PfemModel})
"""Every periodic catenary model by name; `[catenary] model` chooses one."""


def catenary_model(case: Case) -> CatenaryModel:
    """The registered model that the case's `catenary.model` names."""
    return CATENARIES.get(case.model, "catenary.model")
