"""The typed result of a HIL run, written to the run folder as summary.json.

The JSON keys are the attribute names; optional sections are left out when they do not apply (no
complete span: no `contact_force`; not a hardware run: no `link`).
"""
from __future__ import annotations

import json
import signal
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

from pantohil.models.errors import ExitCode

EXIT_CONVERGED = int(ExitCode.SUCCESS)
EXIT_NOT_CONVERGED = int(ExitCode.FAILED)
EXIT_LINK_LOST = int(ExitCode.LINK_LOST)

STATUSES = ("converged", "completed", "diverged", "span_limit", "contact_lost", "link_lost", "interrupted")


@dataclass(frozen=True)
class ForceStatistics:
    """Statistics of the contact force over one span [N]."""

    mean_N: float
    std_N: float
    max_N: float
    min_N: float
    stat_max_N: float | None = None  # EN 50367: mean + 3 std
    stat_min_N: float | None = None  # mean - 3 std
    contact_loss_pct: float | None = None  # share of samples with no contact (force <= 0) [%]
    filtered_20hz: ForceStatistics | None = None

    @classmethod
    def from_dict(cls, d: dict) -> ForceStatistics:
        """The statistics as read from summary.json (a summary written before the EN 50367 figures has none)."""
        inner = d.get("filtered_20hz")
        return cls(d["mean_N"], d["std_N"], d["max_N"], d["min_N"], d.get("stat_max_N"), d.get("stat_min_N"),
                   d.get("contact_loss_pct"), cls.from_dict(inner) if inner is not None else None)

    def to_dict(self) -> dict:
        """The statistics as written to summary.json (with `filtered_20hz` if present)."""
        out = {"mean_N": self.mean_N, "std_N": self.std_N, "max_N": self.max_N, "min_N": self.min_N}
        for name in ("stat_max_N", "stat_min_N", "contact_loss_pct"):
            if getattr(self, name) is not None:
                out[name] = getattr(self, name)
        if self.filtered_20hz is not None:
            out["filtered_20hz"] = self.filtered_20hz.to_dict()
        return out


@dataclass(frozen=True)
class Timing:
    """Wall and simulated time of a run; per_step_us: median set+doStep+get of each FMU [us]; cpu_s:
    CPU time of the run's process (all its threads) while it stepped."""

    wall_s: float
    build_s: float
    simulated_s: float
    realtime_factor: float
    per_step_us: dict = field(default_factory=dict)
    cpu_s: float | None = None


@dataclass(frozen=True)
class RunSummary:
    """Everything a run folder's summary.json says, by attribute."""

    case: str
    master: str
    status: str
    message: str
    spans: int
    samples_per_span: int
    dt_s: float
    speed_kmh: float
    catenary: dict
    pantograph: dict
    rig: dict
    hil: dict
    timing: Timing
    topology: str
    fmus: list
    convergence: list
    stop_signal: str | None = None
    operators: dict | None = None
    realtime: dict | None = None
    link: dict | None = None
    live: dict | None = None
    resumed_from_span: int | None = None
    ssp: dict | None = None  # an SSP run: its FMUs are built here; whether the archive's have the same contents
    reported_span: int | None = None  # the span contact_force and steady_span.csv hold (on a rig: measured whole)
    engine: str = "fmu"  # "inprocess": stepped without the FMUs (pantohil run --engine)
    contact_force: ForceStatistics | None = None
    reference: dict | None = None
    droppers: dict | None = None
    # two pantographs: the second's spacing, position, model, force statistics and closed form (contact_force and
    # reference stay the first's)
    second_pantograph: dict | None = None

    @property
    def converged(self) -> bool:
        """Whether the run converged."""
        return self.status == "converged"

    @property
    def diverged(self) -> bool:
        """Whether the run diverged."""
        return self.status == "diverged"

    @property
    def exit_code(self) -> int:
        """0 converged, or completed its planned run.duration_s; 1 diverged, span limit or contact lost; 3 link
        lost; 128 + the signal if interrupted."""
        if self.status == "interrupted":
            return 128 + int(getattr(signal, self.stop_signal or "SIGINT"))
        if self.status == "link_lost":
            return EXIT_LINK_LOST
        return EXIT_CONVERGED if self.status in ("converged", "completed") else EXIT_NOT_CONVERGED

    def to_dict(self) -> dict:
        """The summary as written to summary.json (fields that are None left out)."""
        out = {"case": self.case, "master": self.master, "status": self.status, "message": self.message,
               "converged": self.converged, "diverged": self.diverged}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in out or value is None:
                continue
            if isinstance(value, ForceStatistics):
                value = value.to_dict()
            elif isinstance(value, Timing):
                value = asdict(value)
            out[f.name] = value
        return out

    @classmethod
    def from_dict(cls, d: dict) -> RunSummary:
        """The summary as read from summary.json (unknown keys ignored)."""
        known = {f.name for f in fields(cls)}
        values = {k: v for k, v in d.items() if k in known}
        values["timing"] = Timing(**d["timing"])
        if d.get("contact_force") is not None:
            values["contact_force"] = ForceStatistics.from_dict(d["contact_force"])
        return cls(**values)

    @classmethod
    def read(cls, folder: Path) -> RunSummary:
        """The summary of a run folder."""
        return cls.from_dict(json.loads((Path(folder) / "summary.json").read_text()))
