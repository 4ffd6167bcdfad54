"""How a HIL run is asked for (`RunOptions`) and the checks of a request before anything is written: the
master and its package, the engine, the log writer, a hardware run's pacing, the run's length."""
from __future__ import annotations

import importlib
from dataclasses import dataclass

from pantohil.models.case import Case, CaseError
from pantohil.models.hil.pair_loop import check_pair_case
from pantohil.models.hil.stop_rules import StopRules

from .inprocess import ENGINES
from .masters import MASTERS

LOG_WRITERS = ("process", "inline")


@dataclass(frozen=True)
class RunOptions:
    """How to run a case. `system` (fmus, connections, parameters), e.g. from an SSP file, replaces
    the build; `hardware` (host, port) runs against a rig controller through the adapter FMU."""

    master_kind: str = "fmpy"
    system: dict | None = None
    hardware: tuple | None = None
    realtime: bool = False
    rt_priority: int | None = 50
    progress: bool = True
    live: tuple | None = None
    live_wait: bool = False
    checkpoint_info: dict | None = None
    resume: dict | None = None
    engine: str = "fmu"  # "inprocess": the models stepped in this process (orchestrator/inprocess.py)
    log_writer: str = "process"  # run.mcap written by a child process, or "inline" by this one (a Dask worker)
    plots: bool = True  # the run's figures (convergence, contact force, dropper corrections)


def is_rig_paced(case: Case, options: RunOptions) -> bool:
    """Whether the run goes through the adapter with the rig owning the clock (link.paced_by = "rig")."""
    return options.hardware is not None and case.sections.link.paced_by == "rig"


def check_options(case: Case, options: RunOptions) -> None:
    """A request that cannot run: one CaseError naming the option or key, before anything is written."""
    master = MASTERS.get(options.master_kind, "master")
    _check_pair(case, options)
    check_master_installed(options.master_kind)
    _check_engine(options)
    if options.log_writer not in LOG_WRITERS:
        raise CaseError(f"log_writer: must be one of {', '.join(LOG_WRITERS)} (got {options.log_writer!r})")
    rig_paced = is_rig_paced(case, options)
    if options.hardware is not None and (options.system is not None or
                                         (not master.model_paced_hardware and not rig_paced)):
        raise CaseError(f"hardware: a hardware run uses a case file, and a master that may drive a rig in lockstep "
                        f"(not {options.master_kind}) unless it is rig-paced")
    if rig_paced and options.realtime:
        raise CaseError("--realtime: a rig-paced run goes at the rig's pace; drop --realtime")
    run, duration_spans = case.sections.run, StopRules.of_case(case).duration_spans
    if duration_spans > run.max_spans:
        raise CaseError(f"run.duration_s: {run.duration_s:g} s is {duration_spans} spans, more than "
                        f"run.max_spans = {run.max_spans}")


def _check_pair(case: Case, options: RunOptions) -> None:
    """Two pantographs run as FMUs from their start (models/hil/pair_loop.py's checks), the first virtual or on a
    rig, the second virtual: not in the in-process engine, not resumed."""
    if case.sections.second_pantograph is None:
        return
    for clash, given in (("--engine inprocess", options.engine != "fmu"), ("--resume", options.resume is not None)):
        if given:
            case.refuse_second_pantograph(f"pantohil run {clash}")
    check_pair_case(case)


def check_master_installed(master_kind: str) -> None:
    """A master whose package is missing: one line naming the extra to install, before anything is written."""
    requires = MASTERS.get(master_kind, "master").requires
    if requires is not None:
        module, extra = requires
        try:
            importlib.import_module(module)
        except ImportError:
            raise CaseError(f"--master {master_kind}: needs {module}, which is not installed "
                            f"(pip install \"pantohil[{extra}]\")") from None


def _check_engine(options: RunOptions) -> None:
    """The in-process engine runs the virtual HIL of a case file, from its start, in place of the fmpy master."""
    if options.engine not in ENGINES:
        raise CaseError(f"--engine: must be one of {', '.join(ENGINES)} (got {options.engine!r})")
    if options.engine == "fmu":
        return
    replaced = MASTERS.get(options.master_kind, "master").replaced_by_inprocess
    clash = ("--hardware" if options.hardware is not None else f"--master {options.master_kind}" if not replaced
             else "an SSP file" if options.system is not None else "--resume" if options.resume is not None else None)
    if clash is not None:
        raise CaseError(f"--engine inprocess: not with {clash} (the in-process engine runs the virtual HIL of a "
                        "case from its start; use --engine fmu)")
