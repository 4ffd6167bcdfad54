"""A HIL run of a case, as stages: prepare (the run folder and the FMUs), step span by span (a Jacobi
master, fmpy or libcosim, in real time or as fast as possible, watching convergence), summarise
(summary.json, steady_span.csv, plots). Observers (the MCAP recorder, and whatever else watches a run)
are called per step, per span and at the end.

Two topologies: the virtual HIL (catenary -> rig -> pantograph -> rig -> catenary, all FMUs) and the
hardware HIL (catenary <-> adapter FMU <-UDP-> rig controller or the rig emulator).

A stop signal (SIGINT, SIGTERM) never interrupts an FMU: it sets a request that the master checks
between steps; the run then ends at a step boundary with status `interrupted` and a complete record.
"""
from __future__ import annotations

import gc
import math
import os
import shutil
import tempfile
import time
from contextlib import nullcontext, suppress
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from pantohil.builder.build_fmus import build_case_fmus
from pantohil.fmus import link_client
from pantohil.builder.system import (
    CONNECTIONS,
    FMU_NAMES,
    HARDWARE_CONNECTIONS,
    HARDWARE_FMU_NAMES,
    HORIZON_OUTPUTS,
    loop_latency_steps,
)
from pantohil.models.case import Case, CaseError
from pantohil.models.catenary.interface import catenary_model
from pantohil.models.hil.loop import ConvergenceMonitor
from pantohil.models.hil.stop_rules import StopRules
from pantohil.models.progress import progress

from . import checkpoint
from .inprocess import ENGINES, InProcessMaster
from .masters import MASTERS
from .pacing import Pacer, lock_memory, set_realtime_priority, unlock_memory
from .recorder import McapRecorder, McapWriter
from .rig_clock import Percentiles
from .run_folder import claimed_run_folder
from .run_observers import CheckpointObserver, LiveObserver, McapObserver, RunObserver
from .run_summary import EXIT_LINK_LOST, RunSummary
from .stopping import StopRequest, stop_on_signals

LOG_WRITERS = ("process", "inline")
LINK_OK, LINK_FAULT = link_client.LINK_OK, link_client.LINK_FAULT
__all__ = ["EXIT_LINK_LOST", "RunInterrupted", "RunObserver", "RunOptions", "RunSummary", "delay_plan", "run_case"]

_CATENARY_GROUP = {"height_command": "commanded height [m]", "contact_force": "force received (NaN: not measured) [N]",
                   "force_at_sample": "force in use at the sample [N]",
                   "height_at_sample": "converging height at the sample [m]",
                   "profile_at_sample": "static height z0 [m]", "sample_index": "sample label [-]",
                   "span_index": "virtual span [-]"}


@dataclass(frozen=True)
class Topology:
    """A co-simulation system: its FMUs, connections and the MCAP groups logged."""
    name: str
    fmus: tuple
    connections: tuple
    groups: dict  # MCAP topic -> {signal: description}; topic "/x" logs FMU x
    contact_force: tuple  # (FMU, output) of the contact force: a span of zeros is a lost contact


VIRTUAL = Topology("virtual", FMU_NAMES, CONNECTIONS, {
    "/catenary": _CATENARY_GROUP,
    "/rig": {"actuator_height": "actuator height [m]", "measured_force": "measured force [N]"},
    "/pantograph": {"contact_force": "contact force [N]", "head_height": "head height [m]"},
}, ("pantograph", "contact_force"))
HARDWARE = Topology("hardware", HARDWARE_FMU_NAMES, HARDWARE_CONNECTIONS, {
    "/catenary": _CATENARY_GROUP,
    "/adapter": {"command_sent": "height sent, within the actuator limits [m]",
                 "measured_force": "force from the rig (NaN: no answer) [N]",
                 "actuator_height": "actuator height reported by the rig [m]",
                 "link_state": "0 ok, 1 missing, 2 fault", **{c: "[-]" for c in link_client.COUNTERS},
                 **{c: f"{text} [-]" for c, text in link_client.TICK_COUNTS.items()}},
}, ("adapter", "measured_force"))
RIG_PACED_FIELDS = {"answer_time": "rig-paced: from the sample reaching the socket to the answer [s]",
                    **{c: f"{text} [-]" for c, text in link_client.RIG_PACED_COUNTERS.items()}}
LINK_COUNTERS = (*link_client.COUNTERS, *link_client.TICK_COUNTS)
RIG_PACED_COUNTERS = tuple(link_client.RIG_PACED_COUNTERS)
REFUSALS = {1: "it speaks another protocol version", 2: "it refused the session start (bad HELLO)",
            4: "it is busy with another session", 8: "it does not run that pacing (link.paced_by)",
            16: "it does not take a horizon of link.horizon_steps heights",
            link_client.REFUSED_LATENCY: "its STATUS reported a latency outside 0..100000 steps",
            link_client.REFUSED_HORIZON: "its STATUS granted no horizon, or more than link.horizon_steps"}
RECORDED_SPANS = 12  # spans the master keeps in memory: the last one, the one before and the 10 of the overlay plot


class RunInterrupted(Exception):
    """A stop signal arrived before the run folder was made: nothing was written."""


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


def is_rig_paced(case: Case, options: RunOptions) -> bool:
    """Whether the run goes through the adapter with the rig owning the clock (link.paced_by = "rig")."""
    return options.hardware is not None and case.sections.link.paced_by == "rig"


def delay_plan(case: Case, topology: Topology = VIRTUAL) -> dict:
    """D = one step per connection of the loop (+ the adapter's pipeline step) + the rig's latency
    (Paper D sec. 3.4: the advance that makes the converged result independent of the loop latency)."""
    loop = loop_latency_steps(topology.connections)
    if topology.name == HARDWARE.name:
        loop += case.sections.link.pipeline_steps
    d = case.delay_steps(loop)
    if d >= case.samples_per_span:
        raise CaseError(_delay_refusal(case, loop, d, topology.name == HARDWARE.name))
    return {"delay_steps": d, "loop_latency_steps": loop, "rig_latency_steps": case.rig_latency_steps(),
            "rig_compensation": "response" if case.compensates_rig_response else "delay",
            "steady_state_period_spans": case.rig_period_spans()}


def _delay_refusal(case: Case, loop: int, d: int, hardware: bool) -> str:
    """Why the advance D does not fit in a span, blamed on the key that adds the most to it."""
    rig = 0 if case.compensates_rig_response or not case.delay_compensation else case.rig_latency_steps()
    hold = case.hold_steps if case.delay_compensation else 0
    rig_key = "rig.file" if case.rig_spec is not None else "rig.delay_steps"
    terms = {"link.pipeline_steps" if hardware else "the loop": loop, "hil.hold_steps": hold, rig_key: rig}
    key = max(terms, key=terms.get)
    return (f"{key}: the delay advance D = {d} steps (loop {loop} + hold {hold} + rig {rig}) must be shorter "
            f"than a span ({case.samples_per_span} steps)")


def run_topology(case: Case, options: RunOptions) -> Topology:
    """The loop of the run, with the dropper corrections logged beside the catenary for a slackening PFEM."""
    master = MASTERS.get(options.master_kind, "master")
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
    topology = HARDWARE if options.hardware is not None else VIRTUAL
    if options.hardware is not None:  # only the horizon's H - 1 heights are connected (and read each step)
        ahead = set(HORIZON_OUTPUTS[case.horizon_steps - 1:])
        topology = replace(topology, connections=tuple(c for c in topology.connections if c[1] not in ahead))
    if rig_paced:
        topology = replace(topology, groups={**topology.groups, "/adapter": {**topology.groups["/adapter"],
                                                                             **RIG_PACED_FIELDS}})
    droppers = catenary_model(case).dropper_positions_m(case)
    if droppers:
        extra = {f"dropper_correction_{d + 1}": f"correction force of dropper {d + 1} at this step [N]"
                 for d in range(len(droppers))}
        extra["slack_droppers"] = "droppers corrected at this step [-]"
        topology = replace(topology, groups={**topology.groups, "/catenary": {**topology.groups["/catenary"], **extra}})
    return topology


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
    _check_master_installed(options.master_kind)
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


def _check_master_installed(master_kind: str) -> None:
    """A master whose package is missing: one line naming the extra to install, before anything is written."""
    import importlib

    requires = MASTERS.get(master_kind, "master").requires
    if requires is not None:
        module, extra = requires
        try:
            importlib.import_module(module)
        except ImportError:
            raise CaseError(f"--master {master_kind}: needs {module}, which is not installed "
                            f"(pip install \"pantohil[{extra}]\")") from None


def _saves_checkpoints(options: RunOptions, topology: Topology) -> bool:
    return (options.checkpoint_info is not None and MASTERS.get(options.master_kind).checkpoints
            and topology.name == VIRTUAL.name
            and options.system is None and options.engine == "fmu")


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
            _end_observers(state)
        finally:
            state.master.close()
        raise


class _Stop(Exception):
    def __init__(self, status: str, message: str):
        super().__init__(message)
        self.status = status


def step_until_done(state: RunState) -> None:
    """Stage 3: span after span until converged, diverged, contact lost, the span limit, or a stop."""
    case = state.case
    hardware = state.prepared.options.hardware
    state.bar = progress(case.sections.run.max_spans, case.name, "span", state.prepared.options.progress,
                         initial=state.first_span)
    t_start, cpu_start = time.perf_counter(), time.process_time()
    try:
        if hardware is not None and MASTERS.get(state.prepared.options.master_kind).model_paced_hardware:
            _check_session_start(state.master, hardware)
        if state.pacer is not None:
            state.pacer.start()
        elif state.rig_paced:  # no pacer: keep collection pauses and page faults out of the rig's deadlines
            gc.collect()
            gc.freeze()  # what exists now is never scanned again
            gc.disable()
            state.scheduling = f"{state.scheduling}, {lock_memory()}"
        for span in range(state.first_span, case.sections.run.max_spans):
            outcome = step_span(state, span)
            if outcome is not None:
                state.status, state.message = outcome
                break
    except _Stop as stop:
        state.status, state.message = stop.status, str(stop)
    finally:
        if state.rig_paced and state.pacer is None:
            gc.unfreeze()
            gc.enable()
            unlock_memory()
        state.wall_s, state.cpu_s = time.perf_counter() - t_start, time.process_time() - cpu_start
        end_stepping(state)


def _limits(state: RunState):
    """Where the force in use, the height command and (on a rig) the link state are among the outputs."""
    master = state.master
    cat = master.real_outputs["catenary"]
    link_col = (master.int_outputs["adapter"].index("link_state") if state.prepared.options.hardware is not None
                else None)
    return cat.index("force_at_sample"), cat.index("height_command"), link_col


def _diverged_at(state: RunState, k: int, span: int, force_N: float, height_m: float) -> _Stop:
    """The stop after step k (from 1) whose force or height is beyond the limits."""
    return _Stop("diverged", state.rules.diverged_message(k * state.case.dt_s, span, force_N, height_m))


def _steps(state: RunState, span: int) -> str | None:
    """The steps of one span; "interrupted" if a stop was requested before one of them. The limits and
    the link are checked after every `master.steps_per_check` steps (1 but for libcosim, which is read
    back a block of steps at a time)."""
    master, pacer, stop = state.master, state.pacer, state.stop
    limits = _limits(state)
    i_f, i_z, _ = limits
    step_observers = [o for o in state.observers if o.wants_steps]
    end = (span + 1) * state.case.samples_per_span
    if pacer is None and not step_observers and master.steps_a_span_at_once:  # the in-process engine
        outcome = master.run_steps(end - master.k, stop, state.rules.force_limit_N, state.rules.height_limit_m)
        if outcome == "diverged":
            out = master.values["catenary"]
            raise _diverged_at(state, master.k, span, out[i_f], out[i_z])
        return outcome
    block = 1 if step_observers else master.steps_per_check
    while master.k < end:
        if stop.requested:
            return "interrupted"
        k0 = master.k
        count = min(block, end - k0)
        if pacer is None:
            master.step_block(count)
        else:
            for k in range(k0, k0 + count):
                pacer.wait(k)
                master.step()
                pacer.done(k)
        _check_steps(state, span, k0, master.k, limits)
        for observer in step_observers:
            observer.on_step(state, k0)
    return None


def _check_steps(state: RunState, span: int, k0: int, k1: int, limits: tuple) -> None:
    """Stop the run if a step of k0..k1-1 left run.force_limit_N or run.height_limit_m (or went NaN), or
    the link is in fault after it."""
    master, dt, rules = state.master, state.case.dt_s, state.rules
    i_f, i_z, link_col = limits
    if k1 - k0 == 1:  # one step (the common case of the fmpy master): no arrays
        out = master.values["catenary"]
        if rules.beyond(out[i_f], out[i_z]):
            raise _diverged_at(state, k1, span, out[i_f], out[i_z])
        fault = link_col is not None and master.int_value("adapter", "link_state", k0) == LINK_FAULT
        k = k0
    else:
        force = master.column("catenary", "force_at_sample", k0, k1)
        height = master.column("catenary", "height_command", k0, k1)
        i = rules.first_beyond(force, height)
        if i is not None:
            raise _diverged_at(state, k0 + i + 1, span, force[i], height[i])
        faults = master.column("adapter", "link_state", k0, k1) == LINK_FAULT if link_col is not None else None
        fault = faults is not None and bool(faults.any())
        k = k0 + int(np.argmax(faults)) if fault else k0
    if fault:
        if k == 0 and not master.int_value("adapter", "session_started", 0):
            raise _Stop("link_lost", _session_refused(master.int_value("adapter", "rig_refusal", 0),
                                                      state.prepared.options.hardware))
        raise _Stop("link_lost", f"link to the rig lost at t = {(k + 1) * dt:.3f} s: "
                                 f"{_link_fault_reason(state.case, state.rig_paced)}; last position held")


def step_span(state: RunState, span: int) -> tuple[str, str] | None:
    """One span of steps, then its convergence record; (status, message) if the run ends with it."""
    case, master = state.case, state.master
    n, dt = case.samples_per_span, case.dt_s
    if _steps(state, span) == "interrupted":
        return "interrupted", f"interrupted at t = {master.k * dt:.3f} s ({state.stop.signal_name}), in span {span}"
    start = span * n
    if state.answer_us is not None:
        for seconds in master.column("adapter", "answer_time", start, start + n):
            if not math.isnan(seconds):  # NaN: no sample for that step
                state.answer_us.add(seconds * 1e6)
    measured = _measured(state, start, start + n)
    rec = state.monitor.close_span(span, master.column("catenary", "force_at_sample", start, start + n), measured)
    for observer in state.observers:
        observer.on_span(state, span, rec)
    state.bar.update(1)
    state.bar.set_postfix(change=f"{rec['change']:.2e}", mean=f"{rec['mean_N']:.1f}", std=f"{rec['std_N']:.2f}")
    fmu, output = state.topology.contact_force
    if not master.column(fmu, output, start, start + n).any():
        return state.rules.after_span(span, rec, state.monitor, contact=False)
    if measured is not None:
        data_failed = _data_failed(state, span, rec["measured"])
        if data_failed is not None:
            return "link_lost", data_failed
    return state.rules.after_span(span, rec, state.monitor, contact=True,
                                  answered=measured is None or _link_ok_at(state, start + n - 1))


def _measured(state: RunState, start: int, stop: int) -> np.ndarray | None:
    """On a rig, which forces the catenary received over steps start..stop were measured (not NaN: an
    answer came); None for a virtual run, where every one is."""
    if state.prepared.options.hardware is None:
        return None
    return ~np.isnan(state.master.input_column("catenary", "adapter", "measured_force", start, stop))


def _data_failed(state: RunState, span: int, measured: int) -> str | None:
    """Why a span with too few measured forces ends the run (link.min_measured_fraction), or None."""
    n, share = state.case.samples_per_span, state.case.sections.link.min_measured_fraction
    if measured >= share * n:
        return None
    return (f"the rig's data failed: only {measured} of the {n} forces of span {span} were measured "
            f"(link.min_measured_fraction = {share:g}); the last position is held")


def _link_ok_at(state: RunState, k: int) -> bool:
    """Whether the link was ok (the latest answer came) after step k: a run does not converge on a span
    whose end the rig did not answer."""
    return state.master.int_value("adapter", "link_state", k) == LINK_OK


def end_stepping(state: RunState) -> None:
    """Close the pacing, the progress bar, the observers (the MCAP file is finished here) and the master."""
    master = state.master
    hardware = state.prepared.options.hardware
    closed = False
    try:
        if state.pacer is not None:
            state.pacer.stop()
        state.bar.close()
        if hardware is not None:  # the rig's session ends (BYE) with the last step, not after the log is written
            state.per_step_us = master.per_step_us()
            state.link = _link_summary(state)
            closed = True
            master.close()
        _end_observers(state)
    finally:
        if not closed:
            state.per_step_us = master.per_step_us()
            if hardware is not None:
                state.link = _link_summary(state)
            master.close()
        if state.pacer is not None:
            state.realtime = {**state.pacer.summary(), "scheduling": state.scheduling}
        if state.pacer is not None or state.rig_paced:
            set_realtime_priority(None)
            _back_to_normal()


def _end_observers(state: RunState) -> None:
    """Every observer's on_end runs, even when one of them fails; the first failure is raised after."""
    failure = None
    for observer in state.observers:
        try:
            observer.on_end(state)
        except Exception as exc:
            failure = failure or exc
    if failure is not None:
        raise failure


def _link_summary(state: RunState) -> dict:
    master, hardware = state.master, state.prepared.options.hardware
    last = max(master.k - 1, 0)
    counters = LINK_COUNTERS + (RIG_PACED_COUNTERS if state.rig_paced else ())
    link = {c: master.int_value("adapter", c, last) for c in counters}
    link["paced_by"] = state.case.sections.link.paced_by
    if state.rig_paced:
        link["scheduling"] = state.scheduling
        link["answer_us"] = {q: state.answer_us.summary()[q] for q in ("p50", "p99", "max")}
    link["rig"] = f"{hardware[0]}:{hardware[1]}"
    link["rig_latency_steps"] = master.int_value("adapter", "rig_latency_steps", last)
    return link


def _link_fault_reason(case: Case, rig_paced: bool) -> str:
    link = case.sections.link
    if rig_paced:
        return (f"no sample from the rig for link.sample_timeout_s = {link.sample_timeout_s:g} s, or more than "
                f"{link.tolerated_losses} consecutive samples missing")
    return f"more than {link.tolerated_losses} consecutive answers missing"


def _session_refused(refusal: int, hardware: tuple) -> str:
    why = "; ".join(text for bit, text in REFUSALS.items() if refusal & bit) or "it did not answer"
    return f"the rig at {hardware[0]}:{hardware[1]} did not accept the session start: {why}"


def _check_session_start(master, hardware: tuple) -> None:
    """After initialisation (masters that can be asked before stepping): a session the rig did not
    accept stops the run, saying why."""
    values = master.instances["adapter"].get_values(["link_state", "session_started", "rig_refusal"])
    if values["link_state"] == LINK_FAULT and not values["session_started"]:
        raise _Stop("link_lost", _session_refused(int(values["rig_refusal"]), hardware))


def _back_to_normal() -> None:
    with suppress(OSError, AttributeError):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def summarise(state: RunState) -> RunSummary:
    """Stage 4: the run folder's files and summary.json (written last, atomically)."""
    from .run_report import summarise_run

    return summarise_run(state)
