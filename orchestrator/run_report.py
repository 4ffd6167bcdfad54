"""The summarise stage of a HIL run: steady_span.csv, the dropper corrections, the plots, and the
typed summary written last, atomically, as summary.json."""
from __future__ import annotations

import math
from dataclasses import asdict

import numpy as np
from pantohil.models.case import Case
from pantohil.models.catenary.interface import catenary_model
from pantohil.models.metrics import force_statistics, lowpass_periodic, rms
from pantohil.models.pantograph.interface import pantograph_model

from . import report
from .run_summary import ForceStatistics, RunSummary, Timing

FILTER_HZ = 20.0


def _pantograph_summary(case: Case) -> dict:
    p = case.pantograph
    return {"model": p.model, "masses_kg": list(p.masses_kg), "stiffnesses_N_m": list(p.stiffnesses_N_m),
            "dampings_Ns_m": list(p.dampings_Ns_m), "contact_stiffness_N_m": p.contact_stiffness_N_m,
            "uplift_force_N": p.uplift_force_N, "contact_frequency_hz": p.contact_frequency_hz()}


def _hil_summary(case: Case, plan: dict) -> dict:
    return {"update": case.hil_update, "relaxation": case.relaxation,
            "max_frequency_hz": case.sections.hil.max_frequency_hz, "harmonics": case.n_harmonics,
            "ramp_steps": case.ramp_steps, "delay_compensation": case.delay_compensation, **plan}


def _statistics(f: np.ndarray, filtered: np.ndarray, contact: bool) -> ForceStatistics:
    """EN 50367's statistics, raw and at 20 Hz; no contact-loss share for a rigid mass (bolted to the
    actuator: its force is its inertia, and below zero it still touches)."""
    raw, low = force_statistics(f), force_statistics(filtered)
    if not contact:
        raw["contact_loss_pct"] = low["contact_loss_pct"] = None
    return ForceStatistics(**raw, filtered_20hz=ForceStatistics(**low))


def _reference(case: Case, f: np.ndarray, found=None):
    """The catenary model's reference steady force (ASM: the closed form, Paper A eqs. 38-41; `found`: another
    (name, force) of the model's) and the run's RMS distance to it; (None, None) if the model has none."""
    found = catenary_model(case).reference_force(case) if found is None else found
    if found is None:
        return None, None
    name, ref = found
    err = rms((f - f.mean()) - (ref - ref.mean()))
    f25, r25 = lowpass_periodic(f, case.dt_s, 25.0), lowpass_periodic(ref, case.dt_s, 25.0)  # Paper B sec. 5.1
    err25 = rms((f25 - f25.mean()) - (r25 - r25.mean()))
    return ref, {"model": name, "std_N": float(np.std(ref)),
                 "rms_error_N": err, "rms_error_rel_std": err / max(float(np.std(ref)), 1e-12),
                 "rms_error_rel_std_25hz": err25 / max(float(np.std(r25)), 1e-12)}


def _rig_summary(case: Case) -> dict:
    """The rig: its parameters, or its rig file's chain and low-frequency delays."""
    if case.rig_spec is None:
        return asdict(case.rig)
    from pantohil.models.rig.drive_chain import group_delay_s
    from pantohil.models.rig.rig_file import rig_sections

    r = case.sections.rig
    return {"file": str((case.source.parent / r.file).resolve()), "name": case.rig_spec.name,
            "chain": rig_sections(case.rig_spec), "group_delay_s": group_delay_s(case.rig_spec, case.dt_s),
            "force_offset_N": r.force_offset_N, "noise_std_N": r.noise_std_N, "noise_seed": r.noise_seed}


def _droppers(state, start: int, stop: int, plots: bool) -> dict:
    case, master, out_dir = state.case, state.master, state.prepared.out_dir
    n, dt = case.samples_per_span, case.dt_s
    positions = catenary_model(case).dropper_positions_m(case)
    names = [v for v in master.real_outputs["catenary"] if v.startswith("dropper_correction_")]
    corr = np.column_stack([master.column("catenary", v, start, stop) for v in names])[:, :len(positions)]
    np.savetxt(out_dir / "dropper_corrections.csv", np.column_stack([np.arange(n) * dt, corr]), delimiter=",",
               header="t_s," + ",".join(f"dropper_{d + 1}_N" for d in range(len(positions))), comments="", fmt="%.9g")
    if plots:
        report.plot_dropper_corrections(out_dir / "dropper_corrections.png", dt, corr,
                                        f"{case.title}: dropper correction forces, converged span")
    return {"slack_steps": [int(c) for c in np.count_nonzero(corr > 0, axis=0)],
            "max_correction_N": [float(c) for c in corr.max(axis=0)], "positions_m": positions}


def _last_span(state, spans_done: int, plots) -> dict:
    """steady_span.csv, the statistics of the last complete span, its reference and its plots."""
    case, master, out_dir = state.case, state.master, state.prepared.out_dir
    n, dt = case.samples_per_span, case.dt_s
    start, stop = (spans_done - 1) * n, spans_done * n
    f = master.column("catenary", "force_at_sample", start, stop)
    labels = master.column("catenary", "sample_index", start, stop)
    if not np.array_equal(labels, np.arange(n)):
        raise RuntimeError("catenary sample labels out of step with the master")
    pair = _pair_columns(state, start, stop) if state.monitor_2 is not None else None
    report.write_steady_span(out_dir / "steady_span.csv", np.arange(n) * dt,
                             master.column("catenary", "profile_at_sample", start, stop),
                             master.column("catenary", "height_at_sample", start, stop), f, case.speed_m_s,
                             None if pair is None else (pair["z_m"], pair["f_N"]))
    filtered = lowpass_periodic(f, dt, FILTER_HZ)
    out = {"contact_force": _statistics(f, filtered, not pantograph_model(case.pantograph).fixed_to_actuator)}
    pair_refs = _pair_references(case, pair) if pair is not None else None
    ref, reference = _reference(case, f, None if pair_refs is None else (pair_refs[0], pair_refs[1][0]))
    if pair is not None:
        out["second_pantograph"] = _second_summary(case, pair, pair_refs)
    if reference is not None:
        out["reference"] = reference
    if catenary_model(case).dropper_positions_m(case):
        out["droppers"] = _droppers(state, start, stop, plots())
    if plots():
        overlay = [master.column("catenary", "force_at_sample", s * n, (s + 1) * n)
                   for s in range(max(0, spans_done - 10), spans_done)]
        report.plot_contact_force(out_dir / "contact_force.png", dt, overlay, ref, filtered,
                                  f"{case.title}: {case.speed_kmh:.0f} km/h, {state.status} after {spans_done} spans",
                                  case.speed_m_s)
        if pair is not None:
            second = case.sections.second_pantograph
            report.plot_contact_force(
                out_dir / "contact_force_2.png", dt,
                [master.column("catenary", "force_at_sample_2", s * n, (s + 1) * n)
                 for s in range(max(0, spans_done - 10), spans_done)],
                None if pair_refs is None else pair_refs[1][1], lowpass_periodic(pair["f_N"], dt, FILTER_HZ),
                f"{case.title}: second pantograph, {second.position} {second.spacing_m:g} m, {state.status} after "
                f"{spans_done} spans", case.speed_m_s)
    return out


def _pair_columns(state, start: int, stop: int) -> dict:
    """The second contact point's static and converging heights and force in use over steps start..stop."""
    master = state.master
    return {"z0_m": master.column("catenary", "profile_at_sample_2", start, stop),
            "z_m": master.column("catenary", "height_at_sample_2", start, stop),
            "f_N": master.column("catenary", "force_at_sample_2", start, stop)}


def _pair_references(case: Case, pair: dict) -> tuple | None:
    """(name, forces (2, N)) of the catenary model's closed form of the pair, or None if it has none."""
    model = catenary_model(case)
    if not hasattr(model, "pair_reference_forces"):
        return None
    first_z0 = case.profile.heights(case.sample_positions_m())
    return model.pair_reference_forces(case, np.array([first_z0, pair["z0_m"]]))


def _second_summary(case: Case, pair: dict, pair_refs: tuple | None) -> dict:
    """summary.json's second_pantograph: where it runs, its model, its force statistics (EN 50367) and its
    distance to the pair's closed form."""
    second, f2 = case.sections.second_pantograph, pair["f_N"]
    out = {"spacing_m": second.spacing_m, "position": second.position,
           "coupling_compensation": second.coupling_compensation, "pantograph": _pantograph_summary(case),
           "contact_force": _statistics(f2, lowpass_periodic(f2, case.dt_s, FILTER_HZ),
                                        not pantograph_model(case.pantograph).fixed_to_actuator).to_dict()}
    if pair_refs is not None:
        out["reference"] = _reference(case, f2, (pair_refs[0], pair_refs[1][1]))[1]
    return out


def _final_status(state) -> tuple[str, str, str | None]:
    """A stop requested after the stepping ended still makes the run `interrupted` (its folder was not
    complete when it came)."""
    stop = state.stop
    if not stop.requested:
        return state.status, state.message, None
    if state.status == "interrupted":
        return state.status, state.message, stop.signal_name
    return "interrupted", (f"interrupted ({stop.signal_name}) while writing the run folder; the run had ended: "
                           f"{state.message}"), stop.signal_name


def _reported_span(state, spans_done: int) -> int | None:
    """The span whose force the summary reports: the last one, or on a rig the last one with at least
    link.min_measured_fraction of its forces measured (a span the rig did not answer holds the span before's
    forces: it shows nothing measured; the same share below which the run stops as a link fault), if the
    master still holds it; None if there is none."""
    if spans_done < 1:
        return None
    history = state.monitor.history if state.monitor is not None else []
    if state.prepared.options.hardware is None or not history:
        return spans_done - 1
    n, share = state.case.samples_per_span, state.case.sections.link.min_measured_fraction
    whole = [h["span"] for h in history if h.get("measured", n) >= share * n and h["span"] < spans_done]
    oldest = (state.master.k - state.master.capacity) // n if state.master is not None else 0
    return whole[-1] if whole and whole[-1] >= max(oldest, 0) else None


def summarise_run(state) -> RunSummary:
    """Write the run folder's files, summary.json last and atomically, and return the summary."""
    case, prepared, master = state.case, state.prepared, state.master
    n, dt = case.samples_per_span, case.dt_s
    mark = state.stop.count

    def plots() -> bool:  # a stop during this stage skips the plots still to draw
        return prepared.options.plots and state.stop.count == mark

    k = master.k if master is not None else 0
    spans_done = k // n
    reported = _reported_span(state, spans_done)
    sections = _last_span(state, reported + 1, plots) if reported is not None else {}
    history = state.monitor.history if state.monitor is not None else []
    if history and plots():
        report.plot_convergence(prepared.out_dir / "convergence.png", history, case.sections.run.convergence_tol,
                                f"{case.title}: {case.hil_update}-by-{case.hil_update} updating, "
                                f"mu_c = {case.relaxation}")
    status, message, signal_name = _final_status(state)
    wall = state.wall_s
    timing = Timing(wall_s=wall, build_s=prepared.build_s, simulated_s=k * dt,
                    realtime_factor=k * dt / wall if wall > 0 else math.inf, per_step_us=state.per_step_us,
                    cpu_s=state.cpu_s)
    summary = RunSummary(
        case=case.name, master=prepared.options.master_kind, status=status, message=message, spans=spans_done,
        samples_per_span=n, dt_s=dt, speed_kmh=case.speed_kmh, catenary=catenary_model(case).summary(case),
        pantograph=_pantograph_summary(case), rig=_rig_summary(case), hil=_hil_summary(case, prepared.plan),
        timing=timing, topology=prepared.topology.name, fmus=[str(p) for p in prepared.fmus.values()],
        convergence=history, stop_signal=signal_name, operators=prepared.operators, realtime=state.realtime,
        link=state.link, live=state.live,
        resumed_from_span=state.first_span if prepared.options.resume is not None else None,
        engine=prepared.options.engine, ssp=prepared.ssp, reported_span=reported, **sections)
    report.write_json_atomic(prepared.out_dir / "summary.json", summary.to_dict())
    return summary
