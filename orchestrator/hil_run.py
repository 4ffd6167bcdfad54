"""A HIL run of a case: build the FMUs, step them with a Jacobi master (fmpy or libcosim), in real time
or as fast as possible, watch convergence, log to MCAP, and write the run folder (summary.json,
steady_span.csv, run.mcap, plots).

Two topologies: the virtual HIL (catenary -> rig -> pantograph -> rig -> catenary, all FMUs) and the
hardware HIL (catenary <-> adapter FMU <-UDP-> rig controller or the rig emulator).
"""
from __future__ import annotations

import contextlib
import math
import os
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from pantohil.builder.build_fmus import build_case_fmus
from pantohil.builder.system import (CONNECTIONS, FMU_NAMES, HARDWARE_CONNECTIONS, HARDWARE_FMU_NAMES,
                                     loop_latency_steps)
from pantohil.models.case import Case, CaseError
from pantohil.models.catenary.asm.closed_form import one_sided_harmonics, single_pantograph
from pantohil.models.hil.loop import ConvergenceMonitor
from pantohil.models.metrics import force_statistics, lowpass_periodic, rms

from . import checkpoint, report
from .channels import span_force_record
from .master import JacobiMaster
from .pacing import Pacer, set_realtime_priority
from .recorder import McapRecorder
from .stop_signals import StopRequests

MASTERS = ("fmpy", "libcosim")
LINK_FAULT = 2
EXIT_LINK_LOST = 3

_CATENARY_GROUP = {"height_command": "commanded height [m]", "contact_force": "force received (NaN: not measured) [N]",
                   "force_at_sample": "force in use at the sample [N]",
                   "height_at_sample": "converging height at the sample [m]",
                   "profile_at_sample": "static height z0 [m]", "sample_index": "sample label [-]",
                   "span_index": "virtual span [-]"}


@dataclass(frozen=True)
class Topology:
    name: str
    fmus: tuple
    connections: tuple
    groups: dict  # MCAP topic -> {signal: description}; topic "/x" logs FMU x


VIRTUAL = Topology("virtual", FMU_NAMES, CONNECTIONS, {
    "/catenary": _CATENARY_GROUP,
    "/rig": {"actuator_height": "actuator height [m]", "measured_force": "measured force [N]"},
    "/pantograph": {"contact_force": "contact force [N]", "head_height": "head height [m]"},
})
HARDWARE = Topology(
    "hardware",
    HARDWARE_FMU_NAMES,
    HARDWARE_CONNECTIONS,
    {
        "/catenary": _CATENARY_GROUP,
        "/adapter": {
            "command_sent": "height sent, within the actuator limits [m]",
            "measured_force": "force from the rig (NaN: no answer) [N]",
            "actuator_height": "actuator height reported by the rig [m]",
            "link_state": "0 ok, 1 missing, 2 fault",
            "sent": "[-]",
            "received": "[-]",
            "lost": "[-]",
            "late": "[-]",
            "reordered": "[-]",
            "duplicated": "[-]",
            "malformed": "[-]",
            "limited": "[-]",
        },
    },
)
LINK_COUNTERS = ("sent", "received", "lost", "late", "reordered", "duplicated", "malformed", "limited")


class RunResult(dict):
    """The summary, with the exit status the CLI should return."""

    @property
    def exit_code(self) -> int:
        if self["status"] == "link_lost":
            return EXIT_LINK_LOST
        return 0 if self["converged"] else 1


class _Stop(Exception):
    def __init__(self, status: str, message: str):
        super().__init__(message)
        self.status = status


def delay_plan(case: Case, topology: Topology = VIRTUAL) -> dict:
    """D = one step per connection of the loop (+ the adapter's pipeline step) + the rig's latency."""
    loop = loop_latency_steps(topology.connections)
    if topology is HARDWARE:
        loop += case.values["link"]["pipeline_steps"]
    d = case.delay_steps(loop)
    if d >= case.samples_per_span:
        raise CaseError(
            f"rig.delay_steps: the delay advance D = {d} steps (loop {loop} + rig "
            f"{case.rig.latency_steps(case.dt_s)}) must be shorter than a span ({case.samples_per_span} steps)"
        )
    return {"delay_steps": d, "loop_latency_steps": loop, "rig_latency_steps": case.rig.latency_steps(case.dt_s)}


def closed_form_reference(case: Case) -> np.ndarray:
    """The ASM closed-form steady force with the run's harmonic content (Paper A eqs. 38-41)."""
    z0 = case.z0_samples()
    ss = single_pantograph(case.catenary, case.pantograph, case.speed_m_s, case.span_m, one_sided_harmonics(z0),
                           case.pantograph.uplift_force_N, case.n_harmonics)
    return ss.force_series(case.samples_per_span)


def run_case(case: Case, out_dir: Path, progress: bool = True, master_kind: str = "fmpy",
             system: dict | None = None, hardware: tuple[str, int] | None = None,
             realtime: bool = False, rt_priority: int | None = 50, live: tuple[str, int] | None = None,
             live_wait: bool = False, checkpoint_info: dict | None = None, resume: dict | None = None) -> RunResult:
    """Run a case. `system` (fmus, connections, parameters), e.g. from an SSP file, replaces the build;
    `hardware` (host, port) runs against a rig controller through the adapter FMU; `live` (host, port)
    serves the run's channels to Foxglove while it runs (`live_wait`: from a viewer's first subscription on).
    `checkpoint_info` (case file, overrides): save the state every span (virtual HIL, fmpy master);
    `resume` (checkpoint.load of an interrupted run in out_dir): continue from its last saved span."""
    if master_kind not in MASTERS:
        raise CaseError(f"--master: must be one of {', '.join(MASTERS)} (got {master_kind!r})")
    if hardware is not None and (system is not None or master_kind != "fmpy"):
        raise CaseError("--hardware: runs with the fmpy master from a case file only")
    topology = HARDWARE if hardware is not None else VIRTUAL
    if case.model == "pfem" and case.values["pfem"]["droppers"]:  # log the dropper corrections with the catenary
        extra_fields = {f"dropper_correction_{d + 1}": f"correction force of dropper {d + 1} at this step [N]"
                        for d in range(len(case_dropper_positions(case)))}
        extra_fields["slack_droppers"] = "droppers corrected at this step [-]"
        topology = replace(topology, groups={**topology.groups,
                                             "/catenary": {**topology.groups["/catenary"], **extra_fields}})
    plan = delay_plan(case, topology)  # validates before anything is written
    n, dt = case.samples_per_span, case.dt_s
    run = case.values["run"]
    out_dir = Path(out_dir)
    operators = None
    if system is None and case.model == "pfem":  # before the run folder: a bad operator file leaves nothing
        from pantohil.builder.operators import case_operators

        operators = case_operators(case, progress).summary()
    out_dir.mkdir(parents=True, exist_ok=True)
    t_build = time.perf_counter()
    if system is None:
        fmus = build_case_fmus(case, out_dir / "fmus", plan["delay_steps"], topology.fmus,
                               hardware or ("127.0.0.1", 47800))
        connections, parameters = topology.connections, {"catenary": {"delay_steps": plan["delay_steps"]}}
    else:
        fmus, connections, parameters = system["fmus"], system["connections"], system["parameters"]
        plan["delay_steps"] = parameters.get("catenary", {}).get("delay_steps", plan["delay_steps"])
    build_s = time.perf_counter() - t_build
    capacity = run["max_spans"] * n
    pacing_group = {"/master": {"lateness_us": "start of the step after its slot start [us]",
                                "duration_us": "wall time of the step [us]"}} if realtime else {}
    groups = topology.groups | pacing_group
    saving = checkpoint_info is not None and master_kind == "fmpy" and topology is VIRTUAL and system is None
    first_span = 0 if resume is None else resume["meta"]["span"] + 1
    log_name = "run.mcap" if resume is None else f"run_from_span_{first_span:04d}.mcap"  # the first log stays
    recorder = McapRecorder(out_dir / log_name, groups,
                            {"case": case.name, "dt_s": dt, "samples_per_span": n, "master": master_kind,
                             "topology": topology.name, "realtime": realtime})
    try:
        if master_kind == "libcosim":
            from .libcosim_master import LibcosimMaster

            master = LibcosimMaster(fmus, connections, parameters, dt, capacity)
        else:
            master = JacobiMaster(fmus, connections, parameters, dt, capacity)
    except Exception:
        recorder.close()
        raise
    try:
        publisher = _start_live(live, master, groups, topology, dt, case.name) if live is not None else None
    except CaseError:
        recorder.close()
        raise
    monitor = ConvergenceMonitor(n)
    if resume is not None:
        try:
            checkpoint.restore(resume, master, monitor, fmus)
        except Exception:
            recorder.close()
            master.close()
            raise
    info = {**checkpoint_info, "fmu_digests": checkpoint.fmu_digests(fmus)} if saving else None
    pacer = Pacer(dt, capacity) if realtime else None
    master.pacer = pacer
    scheduling = set_realtime_priority(rt_priority) if realtime else "normal"  # after the logger is forked
    status, message = "span_limit", f"not converged within run.max_spans = {run['max_spans']} spans"
    f_lim, z_lim = run["force_limit_N"], run["height_limit_m"]
    cat = master.real_outputs["catenary"]
    i_z, i_f = cat.index("height_command"), cat.index("force_at_sample")
    link_col = master.int_outputs["adapter"].index("link_state") if hardware is not None else None
    bar = tqdm(total=run["max_spans"], initial=first_span, unit="span", disable=None if progress else True, leave=False,
               desc=case.name)
    t_start = time.perf_counter()
    stops = StopRequests()
    try:
        if publisher is not None and live_wait:
            print("live: waiting for a viewer to subscribe (Ctrl-C to stop)", flush=True)
            publisher.wait_for_viewer()
            t_start = time.perf_counter()
        if hardware is not None and _link_state_now(master) == LINK_FAULT:
            raise _Stop("link_lost", f"the rig at {hardware[0]}:{hardware[1]} did not answer the session start")
        if pacer is not None:
            pacer.start()
        stops.__enter__()
        for span in range(first_span, run["max_spans"]):
            for _ in range(n):
                k = master.k
                if pacer is not None:
                    pacer.wait(k)
                master.step()
                if pacer is not None:
                    pacer.done(k)
                if stops.requested is not None:
                    raise KeyboardInterrupt
                out = master.values["catenary"]
                if not (abs(out[i_f]) <= f_lim and abs(out[i_z]) <= z_lim):  # also catches NaN
                    raise _Stop("diverged", f"diverged at t = {master.k * dt:.3f} s (span {span}): force "
                                            f"{out[i_f]:.4g} N, height {out[i_z]:.4g} m beyond run.force_limit_N / "
                                            f"run.height_limit_m")
                if link_col is not None and master.record_int["adapter"][k, link_col] == LINK_FAULT:
                    raise _Stop("link_lost", f"link to the rig lost at t = {master.k * dt:.3f} s: more than "
                                             f"{case.values['link']['tolerated_losses']} consecutive answers missing; "
                                             f"last position held")
            start = span * n
            _log_span(recorder, master, topology, start, start + n, dt)
            force = master.column("catenary", "force_at_sample", start, start + n)
            previous = master.column("catenary", "force_at_sample", start - n, start) if span else None
            rec = monitor.close_span(span, force)
            recorder.write_event("/convergence", (start + n) * dt, rec)
            recorder.write_event("/span_force", (start + n) * dt, span_force_record(span, dt, force, previous))
            if publisher is not None:
                publisher.span_closed((start + n) * dt, rec, force, previous)
            if saving:
                checkpoint.save(out_dir, master, monitor, span, info)
            bar.update(1)
            bar.set_postfix(change=f"{rec['change']:.2e}", mean=f"{rec['mean_N']:.1f}", std=f"{rec['std_N']:.2f}")
            if start >= case.ramp_steps and span >= 2 and rec["change"] <= run["convergence_tol"]:
                status, message = "converged", f"converged after {span + 1} spans"
                break
            median = monitor.diverging(run["divergence_spans"], run["divergence_change"], -(-case.ramp_steps // n) + 1)
            if median is not None:
                status, message = "diverged", (f"diverged at span {span}: the span-to-span change stayed at "
                                               f"{median:.2f} of the std (median of {run['divergence_spans']} spans, "
                                               f"run.divergence_change {run['divergence_change']:g})")
                break
    except _Stop as stop:
        status, message = stop.status, str(stop)
        _log_span(recorder, master, topology, (master.k // n) * n, master.k, dt)
    except KeyboardInterrupt:
        status, message = "interrupted", f"interrupted at t = {master.k * dt:.3f} s"
        _log_span(recorder, master, topology, (master.k // n) * n, master.k, dt)
    finally:
        stops.__exit__()
        wall = time.perf_counter() - t_start
        if pacer is not None:
            pacer.stop()
        bar.close()
        recorder.close()
        if publisher is not None:
            publisher.close()
        per_step = master.per_step_us()
        master.close()
    extra = {"topology": topology.name}
    if resume is not None:
        extra["resumed_from_span"] = first_span
    if publisher is not None:
        extra["live"] = publisher.summary()
    if operators is not None:
        extra["operators"] = operators
    if pacer is not None:
        extra["realtime"] = {**pacer.summary(), "scheduling": scheduling}
        set_realtime_priority(None)
        _back_to_normal()
    if hardware is not None:
        last = max(master.k - 1, 0)
        extra["link"] = {c: int(master.record_int["adapter"][last, master.int_outputs["adapter"].index(c)])
                         for c in LINK_COUNTERS}
        extra["link"]["rig"] = f"{hardware[0]}:{hardware[1]}"
        extra["link"]["rig_latency_steps"] = int(
            master.record_int["adapter"][last, master.int_outputs["adapter"].index("rig_latency_steps")]
        )
    return _finish(case, out_dir, master, monitor, plan, fmus, status, message, wall, build_s, per_step,
                   master_kind, extra)


def _back_to_normal() -> None:
    with contextlib.suppress(OSError, AttributeError):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def _link_state_now(master) -> int:
    """The adapter's link state right after initialisation (before any step)."""
    return int(master.instances["adapter"].get_values(["link_state"])["link_state"])


def _group_block(master, groups: dict, topic: str, start: int, stop: int) -> np.ndarray:
    """Columns of a logged group for steps start..stop-1: an FMU's outputs and inputs, or the pacer's."""
    if topic == "/master":
        pacer = master.pacer
        return np.column_stack([pacer.lateness_ns[start:stop] / 1e3, pacer.duration_ns[start:stop] / 1e3])
    fmu = topic.strip("/")
    cols = []
    for name in groups[topic]:
        if name in master.input_names.get(fmu, []):
            cols.append(master.record_in[fmu][start:stop, master.input_names[fmu].index(name)])
        else:
            cols.append(master.column(fmu, name, start, stop))
    return np.column_stack(cols)


def _log_span(recorder: McapRecorder, master, topology: Topology, start: int, stop: int, dt: float) -> None:
    if stop <= start:
        return
    t = np.arange(start, stop) * dt
    if getattr(master, "pacer", None) is not None:
        recorder.write_block("/master", t, _group_block(master, {}, "/master", start, stop))
    for topic in topology.groups:
        recorder.write_block(topic, t, _group_block(master, topology.groups, topic, start, stop))


def _start_live(endpoint: tuple[str, int], master, groups: dict, topology: Topology, dt: float, name: str):
    """The Foxglove server, after the logger is forked and the FMUs are loaded. A step's records are
    final once the next step has started (the pacer writes a step's duration after it)."""
    from .live import LivePublisher

    try:
        publisher = LivePublisher(endpoint, groups, dt, lambda: max(master.k - 1, 0),
                                  lambda topic, start, stop: _group_block(master, groups, topic, start, stop),
                                  name=f"pantohil {name} ({topology.name})")
    except Exception as exc:  # foxglove-sdk raises its own error types for a port in use or a bad host
        master.close()
        raise CaseError(f"--live: cannot serve on {endpoint[0]}:{endpoint[1]}: {exc}") from None
    print(f"live: Foxglove WebSocket server listening on {publisher.url} "
          f"(per-step channels every {publisher.decimation} steps)", flush=True)
    return publisher


def case_dropper_positions(case: Case) -> list:
    from pantohil.models.catenary.fe.definition import load_definition

    return [float(x) for x in load_definition(case.definition_path).dropper_positions_m]


def _catenary_summary(case: Case) -> dict:
    if case.model == "pfem":
        p = case.values["pfem"]
        s = case.pfem_settings()
        return {"model": "pfem", "span_m": case.span_m, "definition_file": str(case.definition_path),
                "droppers_slacken": p["droppers"], "dropper_relaxation": p["dropper_relaxation"],
                "dropper_harmonics": s.n_harmonics_dropper, "omega_max_rad_s": s.omega_max,
                "grid_resolution": s.resolution, "taper": s.taper}
    return {"model": "asm", "span_m": case.span_m, **asdict(case.catenary)}


def _finish(case, out_dir, master, monitor, plan, fmus, status, message, wall, build_s, per_step,
            master_kind, extra) -> RunResult:
    n, dt = case.samples_per_span, case.dt_s
    spans_done = master.k // n
    summary = {
        "case": case.name, "master": master_kind, "status": status, "message": message,
        "converged": status == "converged", "diverged": status == "diverged",
        "spans": spans_done, "samples_per_span": n, "dt_s": dt, "speed_kmh": case.speed_kmh,
        "catenary": _catenary_summary(case),
        "pantograph": {"model": case.pantograph.model, "masses_kg": list(case.pantograph.masses_kg),
                       "stiffnesses_N_m": list(case.pantograph.stiffnesses_N_m),
                       "dampings_Ns_m": list(case.pantograph.dampings_Ns_m),
                       "contact_stiffness_N_m": case.pantograph.contact_stiffness_N_m,
                       "uplift_force_N": case.pantograph.uplift_force_N,
                       "contact_frequency_hz": case.pantograph.contact_frequency_hz()},
        "rig": asdict(case.rig),
        "hil": {"update": case.hil_update, "relaxation": case.relaxation,
                "max_frequency_hz": case.values["hil"]["max_frequency_hz"], "harmonics": case.n_harmonics,
                "ramp_steps": case.ramp_steps, "delay_compensation": case.delay_compensation, **plan},
        "timing": {"wall_s": wall, "build_s": build_s, "simulated_s": master.k * dt,
                   "realtime_factor": master.k * dt / wall if wall > 0 else math.inf, "per_step_us": per_step},
        **extra,
        "fmus": [str(p) for p in fmus.values()],
        "convergence": monitor.history,
    }
    if spans_done >= 1:
        start, stop = (spans_done - 1) * n, spans_done * n
        f = master.column("catenary", "force_at_sample", start, stop)
        z = master.column("catenary", "height_at_sample", start, stop)
        z0 = master.column("catenary", "profile_at_sample", start, stop)
        labels = master.column("catenary", "sample_index", start, stop)
        assert np.array_equal(labels, np.arange(n)), "catenary sample labels out of step with the master"
        filtered = lowpass_periodic(f, dt, 20.0)
        summary["contact_force"] = {**force_statistics(f), "filtered_20hz": force_statistics(filtered)}
        ref = None
        if case.model == "asm":
            ref = closed_form_reference(case)
            err = rms((f - f.mean()) - (ref - ref.mean()))
            summary["reference"] = {"model": "asm closed form (Paper A eqs. 38-41), same harmonics",
                                    "std_N": float(np.std(ref)), "rms_error_N": err,
                                    "rms_error_rel_std": err / max(float(np.std(ref)), 1e-12)}
        elif case.values["pfem"]["droppers"]:
            names = [v for v in master.real_outputs["catenary"] if v.startswith("dropper_correction_")]
            corr = np.column_stack([master.column("catenary", v, start, stop) for v in names])
            n_d = int(len(case_dropper_positions(case)))
            corr = corr[:, :n_d]
            summary["droppers"] = {"slack_steps": [int(c) for c in np.count_nonzero(corr > 0, axis=0)],
                                   "max_correction_N": [float(c) for c in corr.max(axis=0)],
                                   "positions_m": case_dropper_positions(case)}
            np.savetxt(out_dir / "dropper_corrections.csv", np.column_stack([np.arange(n) * dt, corr]), delimiter=",",
                       header="t_s," + ",".join(f"dropper_{d + 1}_N" for d in range(n_d)), comments="", fmt="%.9g")
            report.plot_dropper_corrections(out_dir / "dropper_corrections.png", dt, corr,
                                            f"{case.name}: dropper correction forces, converged span")
        report.write_steady_span(out_dir / "steady_span.csv", np.arange(n) * dt, z0, z, f)
        overlay = [master.column("catenary", "force_at_sample", s * n, (s + 1) * n)
                   for s in range(max(master.record_start // n, spans_done - 10), spans_done)]
        report.plot_contact_force(out_dir / "contact_force.png", dt, overlay, ref, filtered,
                                  f"{case.name}: {case.speed_kmh:.0f} km/h, {status} after {spans_done} spans")
    if monitor.history:
        report.plot_convergence(
            out_dir / "convergence.png",
            monitor.history,
            case.values["run"]["convergence_tol"],
            f"{case.name}: {case.hil_update}-by-{case.hil_update} updating, mu_c = {case.relaxation}",
        )
    report.write_json_atomic(out_dir / "summary.json", summary)
    return RunResult(summary)
