"""The co-simulation masters a run can use, by name: pantohil's fmpy master, OSP's libcosim, and those other
packages declare under the entry-point group `pantohil.masters` (a `MasterKind`, or a class that makes
one). The command line's `--master` choices and every decision on what a master can do come from here.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from pantohil.models.registry import Registry

if TYPE_CHECKING:
    import numpy as np


class Master(Protocol):
    """What a run reads of a master (orchestrator/master.py `RecordingMaster` provides the records): the
    FMUs' names, outputs and inputs, the step count `k`, each FMU's real outputs after the latest step
    (`values`), and rings of the last `capacity` steps read through `column`, `input_column`, `int_value`."""

    names: list[str]
    real_outputs: dict[str, list[str]]
    int_outputs: dict[str, list[str]]
    input_names: dict[str, list[str]]
    k: int
    capacity: int
    steps_a_span_at_once: bool
    steps_per_check: int

    @property
    def values(self) -> dict[str, list[float]]:
        """Each FMU's real outputs after the latest step."""

    def step(self) -> None:
        """One communication step of dt (Jacobi: every FMU gets the outputs of the step before)."""

    def step_block(self, count: int) -> None:
        """`count` steps."""

    def sync(self) -> None:
        """Bring the records up to date."""

    def column(self, fmu: str, output: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """An output's recorded values over steps start..stop."""

    def int_value(self, fmu: str, output: str, k: int) -> int:
        """An integer output after step k."""

    def per_step_us(self) -> dict[str, float]:
        """Median wall time per step, by FMU or for the whole step."""

    def close(self) -> None:
        """Release the FMUs."""


MakeMaster = Callable[[dict[str, Path], tuple, dict[str, dict], float, int], Master]


@dataclass(frozen=True)
class MasterKind:
    """A master: how to make one over built FMUs (fmus, connections, start values, dt, record capacity)
    and what it can do.

    `requires`: (module, pantohil extra) it needs installed; `checkpoints`: it can take and put back the
    FMUs' states (`serialize_states`, `deserialize_states`: run checkpoints and --resume);
    `model_paced_hardware`: it may drive a rig in lockstep, reading the adapter's session before the first
    step (`initial_values`); `replaced_by_inprocess`: `--engine inprocess` stands in for it."""

    make: MakeMaster
    requires: tuple[str, str] | None = None
    checkpoints: bool = False
    model_paced_hardware: bool = False
    replaced_by_inprocess: bool = False


def _fmpy() -> MasterKind:
    from .master import JacobiMaster

    return MasterKind(JacobiMaster, checkpoints=True, model_paced_hardware=True,
                      replaced_by_inprocess=True)


def _libcosim() -> MasterKind:
    def make(fmus, connections, parameters, dt, capacity):
        from .libcosim_master import LibcosimMaster

        return LibcosimMaster(fmus, connections, parameters, dt, capacity)

    return MasterKind(make, requires=("libcosimpy", "libcosim"))


MASTERS: Registry[MasterKind] = Registry("master", "pantohil.masters", {"fmpy": _fmpy, "libcosim": _libcosim})
DEFAULT_MASTER = "fmpy"
