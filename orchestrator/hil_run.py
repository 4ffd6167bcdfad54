"""A virtual HIL run of a case: build the FMUs, step them with the Jacobi master, watch convergence,
log to MCAP, and write the run folder (summary.json, steady_span.csv, run.mcap, plots)."""
from __future__ import annotations

import math
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from pantohil.builder.build_fmus import build_case_fmus
from pantohil.builder.system import CONNECTIONS, loop_latency_steps
from pantohil.models.case import Case, CaseError
from pantohil.models.closed_form import one_sided_harmonics, single_pantograph
from pantohil.models.hil import ConvergenceMonitor
from pantohil.models.metrics import force_statistics, lowpass_periodic, rms

from . import report
from .master import JacobiMaster
from .recorder import McapRecorder

MCAP_GROUPS = {
    "/catenary": {"height_command": "commanded height [m]", "contact_force": "force received [N]",
                  "height_at_sample": "converging height at the sample [m]",
                  "profile_at_sample": "static height z0 [m]", "sample_index": "sample label [-]",
                  "span_index": "virtual span [-]"},
    "/rig": {"actuator_height": "actuator height [m]", "measured_force": "measured force [N]"},
    "/pantograph": {"contact_force": "contact force [N]", "head_height": "head height [m]"},
}


class RunResult(dict):
    """The summary, with the exit status the CLI should return."""

    @property
    def exit_code(self) -> int:
        return 0 if self["converged"] else 1


def delay_plan(case: Case) -> dict:
    loop = loop_latency_steps(CONNECTIONS)
    d = case.delay_steps(loop)
    if d >= case.samples_per_span:
        raise CaseError(f"rig.delay_steps: the delay advance D = {d} steps (loop {loop} + rig "
                        f"{case.rig.latency_steps(case.dt_s)}) must be shorter than a span ({case.samples_per_span} steps)")
    return {"delay_steps": d, "loop_latency_steps": loop, "rig_latency_steps": case.rig.latency_steps(case.dt_s)}


def closed_form_reference(case: Case) -> np.ndarray:
    """The ASM closed-form steady force with the run's harmonic content (Paper A eqs. 38-41)."""
    z0 = case.z0_samples()
    ss = single_pantograph(case.catenary, case.pantograph, case.speed_m_s, case.span_m, one_sided_harmonics(z0),
                           case.pantograph.uplift_force_N, case.n_harmonics)
    return ss.force_series(case.samples_per_span)


MASTERS = ("fmpy", "libcosim")


def run_case(case: Case, out_dir: Path, progress: bool = True, master_kind: str = "fmpy",
             system: dict | None = None) -> RunResult:
    """Run a case. `system` (fmus, connections, parameters), e.g. from an SSP file, replaces the build."""
    if master_kind not in MASTERS:
        raise CaseError(f"--master: must be one of {', '.join(MASTERS)} (got {master_kind!r})")
    plan = delay_plan(case)  # validates before anything is written
    n, dt = case.samples_per_span, case.dt_s
    run = case.values["run"]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t_build = time.perf_counter()
    if system is None:
        fmus = build_case_fmus(case, out_dir / "fmus", plan["delay_steps"])
        connections, parameters = CONNECTIONS, {"catenary": {"delay_steps": plan["delay_steps"]}}
    else:
        fmus, connections, parameters = system["fmus"], system["connections"], system["parameters"]
        plan["delay_steps"] = parameters.get("catenary", {}).get("delay_steps", plan["delay_steps"])
    build_s = time.perf_counter() - t_build
    capacity = run["max_spans"] * n
    recorder = McapRecorder(out_dir / "run.mcap", MCAP_GROUPS | {"/convergence": {}},
                            {"case": case.name, "dt_s": dt, "samples_per_span": n, "master": master_kind})
    try:
        if master_kind == "libcosim":
            from .libcosim_master import LibcosimMaster

            master = LibcosimMaster(fmus, connections, parameters, dt, capacity)
        else:
            master = JacobiMaster(fmus, connections, parameters, dt, capacity)
    except Exception:
        recorder.close()
        raise
    monitor = ConvergenceMonitor(n)
    status, message = "span_limit", f"not converged within run.max_spans = {run['max_spans']} spans"
    f_lim, z_lim = run["force_limit_N"], run["height_limit_m"]
    cat_z = master.real_outputs["catenary"].index("height_command")
    rig_f = master.real_outputs["rig"].index("measured_force")
    bar = tqdm(total=run["max_spans"], unit="span", disable=None if progress else True, leave=False, desc=case.name)
    t_start = time.perf_counter()
    try:
        for span in range(run["max_spans"]):
            for _ in range(n):
                master.step()
                f = master.values["rig"][rig_f]
                z = master.values["catenary"][cat_z]
                if not (abs(f) <= f_lim and abs(z) <= z_lim):  # also catches NaN
                    raise _Diverged(f"diverged at t = {master.k * dt:.3f} s (span {span}): force {f:.4g} N, "
                                    f"height {z:.4g} m beyond run.force_limit_N / run.height_limit_m")
            start = span * n
            _log_span(recorder, master, start, start + n, dt)
            rec = monitor.close_span(span, master.input_column("catenary", "rig", "measured_force", start, start + n))
            recorder.write_event("/convergence", (start + n) * dt, rec)
            bar.update(1)
            bar.set_postfix(change=f"{rec['change']:.2e}", std=f"{rec['std_N']:.2f}")
            if start >= case.ramp_steps and span >= 2 and rec["change"] <= run["convergence_tol"]:
                status, message = "converged", f"converged after {span + 1} spans"
                break
    except _Diverged as exc:
        status, message = "diverged", str(exc)
        done = (master.k // n) * n
        _log_span(recorder, master, done, master.k, dt)
    except KeyboardInterrupt:
        status, message = "interrupted", f"interrupted at t = {master.k * dt:.3f} s"
        _log_span(recorder, master, (master.k // n) * n, master.k, dt)
    finally:
        wall = time.perf_counter() - t_start
        bar.close()
        recorder.close()
        per_step = master.per_step_us()
        master.close()
    return _finish(case, out_dir, master, monitor, plan, fmus, status, message, wall, build_s, per_step, master_kind)


class _Diverged(Exception):
    pass


def _log_span(recorder: McapRecorder, master: JacobiMaster, start: int, stop: int, dt: float) -> None:
    if stop <= start:
        return
    t = np.arange(start, stop) * dt
    for topic, fields in MCAP_GROUPS.items():
        fmu = topic.strip("/")
        cols = []
        for name in fields:
            if fmu == "catenary" and name == "contact_force":
                cols.append(master.input_column("catenary", "rig", "measured_force", start, stop))
            else:
                cols.append(master.column(fmu, name, start, stop))
        recorder.write_block(topic, t, np.column_stack(cols))


def _finish(case, out_dir, master, monitor, plan, fmus, status, message, wall, build_s, per_step,
            master_kind) -> RunResult:
    n, dt = case.samples_per_span, case.dt_s
    spans_done = master.k // n
    summary = {
        "case": case.name, "master": master_kind, "status": status, "message": message,
        "converged": status == "converged", "diverged": status == "diverged",
        "spans": spans_done, "samples_per_span": n, "dt_s": dt, "speed_kmh": case.speed_kmh,
        "catenary": {"model": "asm", "span_m": case.span_m, **asdict(case.catenary)},
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
        "fmus": [str(p) for p in fmus.values()],
        "convergence": monitor.history,
    }
    if spans_done >= 1:
        last = slice((spans_done - 1) * n, spans_done * n)
        f = master.input_column("catenary", "rig", "measured_force", last.start, last.stop)
        z = master.column("catenary", "height_at_sample", last.start, last.stop)
        z0 = master.column("catenary", "profile_at_sample", last.start, last.stop)
        labels = master.column("catenary", "sample_index", last.start, last.stop)
        assert np.array_equal(labels, np.arange(n)), "catenary sample labels out of step with the master"
        filtered = lowpass_periodic(f, dt, 20.0)
        summary["contact_force"] = {**force_statistics(f), "filtered_20hz": force_statistics(filtered)}
        ref = closed_form_reference(case)
        err = rms((f - f.mean()) - (ref - ref.mean()))
        summary["reference"] = {"model": "asm closed form (Paper A eqs. 38-41), same harmonics",
                                "std_N": float(np.std(ref)), "rms_error_N": err,
                                "rms_error_rel_std": err / max(float(np.std(ref)), 1e-12)}
        report.write_steady_span(out_dir / "steady_span.csv", np.arange(n) * dt, z0, z, f)
        overlay = [master.input_column("catenary", "rig", "measured_force", s * n, (s + 1) * n)
                   for s in range(max(0, spans_done - 10), spans_done)]
        report.plot_contact_force(out_dir / "contact_force.png", dt, overlay, ref, filtered,
                                  f"{case.name}: {case.speed_kmh:.0f} km/h, {status} after {spans_done} spans")
    if monitor.history:
        report.plot_convergence(out_dir / "convergence.png", monitor.history, case.values["run"]["convergence_tol"],
                                f"{case.name}: {case.hil_update}-by-{case.hil_update} updating, mu_c = {case.relaxation}")
    report.write_json_atomic(out_dir / "summary.json", summary)
    return RunResult(summary)
