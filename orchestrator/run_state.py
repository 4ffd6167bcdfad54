"""What a HIL run holds while it runs: the prepared run folder and system (`PreparedRun`) and the
stepping run that observers read (`RunState`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from pantohil.models.case import Case
from pantohil.models.hil.loop import ConvergenceMonitor
from pantohil.models.hil.stop_rules import StopRules

from .pacing import Pacer
from .rig_clock import Percentiles
from .run_options import RunOptions, is_rig_paced
from .run_topology import Topology
from .stopping import StopRequest


@dataclass
class PreparedRun:
    """What the prepare stage made: the run folder, the delay plan and the FMUs with their wiring."""

    case: Case
    out_dir: Path
    options: RunOptions
    topology: Topology
    plan: dict
    operators: dict | None
    fmus: dict = field(default_factory=dict)
    connections: tuple = ()
    ssp: dict | None = None  # an SSP run: whether the archive's FMUs contain what the ones built here do
    parameters: dict = field(default_factory=dict)
    build_s: float = 0.0


@dataclass
class RunState:
    """The run while it steps; observers read it."""

    prepared: PreparedRun
    stop: StopRequest
    observers: list
    master: object = None
    monitor: ConvergenceMonitor | None = None
    monitor_2: ConvergenceMonitor | None = None  # two pantographs: the second contact point's
    rules: StopRules | None = None  # when the run stops (models/hil/stop_rules.py)
    pacer: Pacer | None = None
    bar: object = None
    scheduling: str = "normal"
    status: str = "span_limit"
    message: str = ""
    wall_s: float = 0.0
    cpu_s: float = 0.0  # CPU time of the process (all threads) while stepping
    per_step_us: dict = field(default_factory=dict)
    realtime: dict | None = None
    link: dict | None = None
    answer_us: Percentiles | None = None  # rig-paced: the answer times, streamed (memory bounded)
    live: dict | None = None
    first_span: int = 0  # a resumed run starts after its checkpoint's span
    logged_groups: dict = field(default_factory=dict)  # what run.mcap logs per step (with /master if paced)

    @property
    def case(self) -> Case:
        """The case being run."""
        return self.prepared.case

    @property
    def topology(self) -> Topology:
        """The system being stepped."""
        return self.prepared.topology

    @property
    def rig_paced(self) -> bool:
        """A hardware run whose rig owns the clock."""
        return is_rig_paced(self.case, self.prepared.options)
