"""A HIL run of a case, as stages: prepare (the run folder and the FMUs), step span by span (a Jacobi
master, fmpy or libcosim, in real time or as fast as possible, watching convergence), summarise
(summary.json, steady_span.csv, plots). Observers (the MCAP recorder, and whatever else watches a run)
are called per step, per span and at the end.

The request is checked in run_options.py, the system chosen in run_topology.py, the steps taken in
run_stepping.py and the run folder written in run_report.py.

A stop signal (SIGINT, SIGTERM) never interrupts an FMU: it sets a request that the master checks
between steps; the run then ends at a step boundary with status `interrupted` and a complete record.
"""
from __future__ import annotations

import os
import shutil
import tempfile
import time
from contextlib import nullcontext, suppress
from pathlib import Path

from pantohil.builder.build_fmus import build_case_fmus
from pantohil.builder.fmu_parameters import second_pantograph_parameters
from pantohil.builder.system import SECOND_PANTOGRAPH, with_second_pantograph
from pantohil.models.case import Case, CaseError
from pantohil.models.catenary.interface import catenary_model
from pantohil.models.hil.loop import ConvergenceMonitor
from pantohil.models.hil.stop_rules import StopRules

from . import checkpoint
from .inprocess import InProcessMaster
from .masters import MASTERS
from .pacing import Pacer, set_realtime_priority
from .recorder import McapRecorder, McapWriter
from .rig_clock import Percentiles
from .run_folder import claimed_run_folder
from .run_observers import CheckpointObserver, LiveObserver, McapObserver, RunObserver
from .run_options import RunOptions, check_options
from .run_state import PreparedRun, RunState
from .run_stepping import end_observers, step_until_done
from .run_summary import EXIT_LINK_LOST, RunSummary
from .run_topology import VIRTUAL, Topology, delay_plan, run_topology
from .stopping import StopRequest, stop_on_signals

__all__ = ["EXIT_LINK_LOST", "RECORDED_SPANS", "RunInterrupted", "RunObserver", "RunOptions", "RunSummary",
           "run_case"]

RECORDED_SPANS = 12  # spans the master keeps in memory: the last one, the one before and the 10 of the overlay plot


class RunInterrupted(Exception):
    """A stop signal arrived before the run folder was made: nothing was written."""


def run_case(case: Case, out_dir: Path, progress: bool = True, master_kind: str = "fmpy",
             system: dict | None = None, hardware: tuple[str, int] | None = None,
             realtime: bool = False, rt_priority: int | None = 50, live: tuple[str, int] | None = None,
             live_wait: bool = False, checkpoint_info: dict | None = None, resume: dict | None = None, *,
             overwrite: bool = False, observers: tuple = (), stop: StopRequest | None = None,
             engine: str = "fmu", log_writer: str = "process", plots: bool = True) -> RunSummary:
    """Run a case into `out_dir` (new or empty; `overwrite` replaces it whole) and return its summary.
    `live` (host, port) serves the run's channels to Foxglove while it runs (`live_wait`: from a
    viewer's first subscription on); `observers` are called per step, per span and at the end.
    `checkpoint_info` (case file, overrides): save the state every span (virtual HIL, fmpy master, FMUs);
    `resume` (checkpoint.load of an interrupted run in out_dir): continue from its last saved span.
    `engine` "inprocess" steps the same models without the FMUs (virtual HIL only; same result).
    `log_writer` "process" writes run.mcap in a child process, which finishes the file even if this one
    dies; "inline" writes it in this process, at span ends (for a process that may not start children,
    such as a Dask worker). `plots` False leaves the figures out of the run folder.

    Without `stop`, SIGINT and SIGTERM are caught for the duration of the run (main thread only)."""
    options = RunOptions(master_kind, system, hardware, realtime, rt_priority, progress, live, live_wait,
                         checkpoint_info, resume, engine, log_writer, plots)
    check_options(case, options)
    topology = run_topology(case, options)
    plan = delay_plan(case, topology)  # validates before anything is written
    with (stop_on_signals() if stop is None else nullcontext(stop)) as request:
        operators = _catenary_prepared(case, options, request)  # before the run folder: a bad file leaves nothing
        if request.requested:
            raise RunInterrupted("interrupted before the run started: nothing written")
        with claimed_run_folder(out_dir, overwrite, resume=resume is not None) as folder:
            prepared = PreparedRun(case, folder, options, topology, plan, operators)
            live_view = [LiveObserver(live, live_wait)] if live is not None else []
            saver = [CheckpointObserver(checkpoint_info)] if _saves_checkpoints(options, topology) else []
            state = RunState(prepared, request, live_view + saver + list(observers))
            prepare(prepared)
            if request.requested:
                state.status, state.message = "interrupted", "interrupted while the FMUs were built"
            else:
                start(state)
                step_until_done(state)
            return summarise(state)


def _saves_checkpoints(options: RunOptions, topology: Topology) -> bool:
    return (options.checkpoint_info is not None and MASTERS.get(options.master_kind).checkpoints
            and topology.name == VIRTUAL.name
            and options.system is None and options.engine == "fmu")


def _catenary_prepared(case: Case, options: RunOptions, stop: StopRequest) -> dict | None:
    """What the catenary model builds ahead of the FMUs (the PFEM's operators), with its summary."""
    if options.system is not None:
        return None
    try:
        with stop.interruptible():
            return catenary_model(case).prepare(case, options.progress)
    except KeyboardInterrupt:
        return None


def prepare(prepared: PreparedRun) -> None:
    """Stage 1: build the case's FMUs into the run folder (or take the SSP system's)."""
    t_build = time.perf_counter()
    options, plan = prepared.options, prepared.plan
    if options.engine == "inprocess":  # no FMUs: the master creates the models from the case
        prepared.connections = prepared.topology.connections
        prepared.parameters = {"catenary": {"delay_steps": plan["delay_steps"]}}
    elif options.system is None and options.resume is not None:
        prepared.fmus = _resumed_fmus(prepared)
        prepared.connections = prepared.topology.connections
        prepared.parameters = {"catenary": {"delay_steps": plan["delay_steps"]}}
    elif options.system is None and prepared.topology.pantographs == 2:  # the second: an instance of the first's
        names = tuple(n for n in prepared.topology.fmus if n != SECOND_PANTOGRAPH)
        built = build_case_fmus(prepared.case, prepared.out_dir / "fmus", plan["delay_steps"],
                                (*names, "pantograph") if "pantograph" not in names else names,
                                options.hardware or ("127.0.0.1", 47800))
        prepared.fmus = with_second_pantograph({n: built[n] for n in names}, built)
        prepared.connections = prepared.topology.connections
        prepared.parameters = {"catenary": {"delay_steps": plan["delay_steps"]},
                               SECOND_PANTOGRAPH: second_pantograph_parameters(prepared.case)}
    elif options.system is None:
        prepared.fmus = build_case_fmus(prepared.case, prepared.out_dir / "fmus", plan["delay_steps"],
                                        prepared.topology.fmus, options.hardware or ("127.0.0.1", 47800))
        prepared.connections = prepared.topology.connections
        prepared.parameters = {"catenary": {"delay_steps": plan["delay_steps"]}}
    else:  # an SSP file: nothing in it is executed; its system is rebuilt from the case its values make
        prepared.parameters = options.system["parameters"]
        plan["delay_steps"] = prepared.parameters.get("catenary", {}).get("delay_steps", plan["delay_steps"])
        prepared.fmus, prepared.ssp = _ssp_fmus(prepared)
        prepared.connections = prepared.topology.connections
    prepared.build_s = time.perf_counter() - t_build


def _ssp_fmus(prepared: PreparedRun) -> tuple[dict[str, Path], dict]:
    """The FMUs of an SSP run: pantohil's own, built from the case the SSP's values make, never the archive's
    (an input file's code is not run); the SSP must wire them as pantohil's virtual HIL does. Also whether the
    archive's FMUs contain the same (an SSP of this pantohil and case) or not."""
    system, topology = prepared.options.system, prepared.topology
    if set(system["fmus"]) != set(topology.fmus) or set(system["connections"]) != set(topology.connections):
        raise CaseError("SSP file: its components or connections are not those of pantohil's virtual HIL "
                        f"({', '.join(topology.fmus)})")
    built = build_case_fmus(prepared.case, prepared.out_dir / "fmus", prepared.plan["delay_steps"], topology.fmus)
    same = checkpoint.fmu_digests(built) == checkpoint.fmu_digests(system["fmus"])
    return built, {"archive_fmus_run": False, "archive_fmus_same_contents": same}


def _resumed_fmus(prepared: PreparedRun) -> dict[str, Path]:
    """The FMUs of a resumed run: built apart, checked to contain what the checkpoint's did, and only then
    put into the run folder (a refused resume leaves the folder as it was)."""
    with tempfile.TemporaryDirectory(prefix="pantohil_resume_") as tmp:
        built = build_case_fmus(prepared.case, Path(tmp), prepared.plan["delay_steps"], prepared.topology.fmus)
        checkpoint.check_fmus(prepared.options.resume, built)
        folder = prepared.out_dir / "fmus"
        folder.mkdir(exist_ok=True)
        for path in built.values():
            part = folder / f".{path.name}.part"
            shutil.copyfile(path, part)
            os.replace(part, folder / path.name)
        return {name: folder / path.name for name, path in built.items()}


def _log_name(options: RunOptions) -> str:
    """run.mcap, or for a resumed run a log of its own (the first log stays as it was)."""
    if options.resume is None:
        return "run.mcap"
    return f"run_from_span_{options.resume['meta']['span'] + 1:04d}.mcap"


def _recorder(prepared: PreparedRun, groups: dict) -> McapObserver:
    case, options = prepared.case, prepared.options
    writer = McapRecorder if options.log_writer == "process" else McapWriter
    recorder = writer(prepared.out_dir / _log_name(options), groups,
                      {"case": case.name, "dt_s": case.dt_s, "samples_per_span": case.samples_per_span,
                       "master": options.master_kind, "engine": options.engine, "topology": prepared.topology.name,
                       "realtime": options.realtime})
    return McapObserver(recorder, prepared.topology.groups, case.dt_s)


def start(state: RunState) -> None:
    """Stage 2: the MCAP recorder (forked before any FMU is loaded), the master, pacing, observers."""
    prepared, case = state.prepared, state.case
    options = prepared.options
    pacing_group = {"/master": {"lateness_us": "start of the step after its slot start [us]",
                                "duration_us": "wall time of the step [us]"}} if options.realtime else {}
    state.logged_groups = prepared.topology.groups | pacing_group
    mcap = _recorder(prepared, state.logged_groups)
    capacity = min(case.sections.run.max_spans, RECORDED_SPANS) * case.samples_per_span  # bounded rings
    try:
        if options.engine == "inprocess":
            state.master = InProcessMaster(case, prepared.connections, prepared.parameters, case.dt_s, capacity)
        else:
            state.master = MASTERS.get(options.master_kind).make(prepared.fmus, prepared.connections,
                                                                 prepared.parameters, case.dt_s, capacity)
    except BaseException:
        mcap.recorder.close()
        raise
    state.observers.insert(0, mcap)
    state.monitor = ConvergenceMonitor(case.samples_per_span, case.rig_period_spans())
    if case.sections.second_pantograph is not None:
        state.monitor_2 = ConvergenceMonitor(case.samples_per_span)  # virtual: no rig clock
    state.rules = StopRules.of_case(case)
    if options.resume is not None:
        try:
            state.first_span = checkpoint.restore(options.resume, state.master, state.monitor)
        except BaseException:
            mcap.recorder.close()
            state.master.close()
            with suppress(OSError):  # the new log of a resume that did not start holds nothing
                (prepared.out_dir / _log_name(options)).unlink()
            raise
    paced_steps = case.sections.run.max_spans * case.samples_per_span
    state.pacer = Pacer(case.dt_s, paced_steps) if options.realtime else None
    state.master.pacer = state.pacer
    # a rig-paced master sleeps on the rig's samples, so it may take the real-time priority too
    paced = options.realtime or state.rig_paced
    state.scheduling = set_realtime_priority(options.rt_priority) if paced else "normal"
    state.answer_us = Percentiles() if state.rig_paced else None
    state.status = "span_limit"
    state.message = f"not converged within run.max_spans = {case.sections.run.max_spans} spans"
    try:
        for observer in state.observers:
            observer.on_start(state)
    except BaseException:
        try:
            end_observers(state)
        finally:
            state.master.close()
        raise


def summarise(state: RunState) -> RunSummary:
    """Stage 4: the run folder's files and summary.json (written last, atomically)."""
    from .run_report import summarise_run

    return summarise_run(state)
