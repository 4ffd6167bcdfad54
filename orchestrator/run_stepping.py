"""Stage 3 of a HIL run: span after span until converged, diverged, contact lost, the link lost, the span
limit or a stop; the limits and the link checked after every step (or block of steps), the convergence
record and the observers after every span, and the master, pacing and observers closed at the end."""
from __future__ import annotations

import gc
import math
import os
import time
from contextlib import suppress

import numpy as np

from pantohil.models.progress import progress

from .link_diagnostics import (
    LINK_FAULT,
    LINK_OK,
    link_fault_reason,
    link_summary,
    session_refused,
    session_start_refusal,
)
from .masters import MASTERS
from .pacing import lock_memory, set_realtime_priority, unlock_memory
from .run_state import RunState


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
            refused = session_start_refusal(state.master, hardware)
            if refused is not None:
                raise _Stop("link_lost", refused)
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


_POINTS = (("force_at_sample", "height_command"), ("force_at_sample_2", "height_command_2"))  # per contact point


def _limits(state: RunState):
    """Where the force in use and the height command of each contact point, and (on a rig) the link state, are
    among the outputs: ([(force index, height index, force name, height name)], link column)."""
    master = state.master
    cat = master.real_outputs["catenary"]
    link_col = (master.int_outputs["adapter"].index("link_state") if state.prepared.options.hardware is not None
                else None)
    points = _POINTS[:2 if state.monitor_2 is not None else 1]
    return [(cat.index(f), cat.index(z), f, z) for f, z in points], link_col


def _diverged_at(state: RunState, k: int, span: int, force_N: float, height_m: float) -> _Stop:
    """The stop after step k (from 1) whose force or height is beyond the limits."""
    return _Stop("diverged", state.rules.diverged_message(k * state.case.dt_s, span, force_N, height_m))


def _steps(state: RunState, span: int) -> str | None:
    """The steps of one span; "interrupted" if a stop was requested before one of them. The limits and
    the link are checked after every `master.steps_per_check` steps (1 but for libcosim, which is read
    back a block of steps at a time)."""
    master, pacer, stop = state.master, state.pacer, state.stop
    limits = _limits(state)
    i_f, i_z = limits[0][0][:2]
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
    points, link_col = limits
    if k1 - k0 == 1:  # one step (the common case of the fmpy master): no arrays
        out = master.values["catenary"]
        for i_f, i_z, _, _ in points:
            if rules.beyond(out[i_f], out[i_z]):
                raise _diverged_at(state, k1, span, out[i_f], out[i_z])
        fault = link_col is not None and master.int_value("adapter", "link_state", k0) == LINK_FAULT
        k = k0
    else:
        for _, _, f_name, z_name in points:
            force = master.column("catenary", f_name, k0, k1)
            height = master.column("catenary", z_name, k0, k1)
            i = rules.first_beyond(force, height)
            if i is not None:
                raise _diverged_at(state, k0 + i + 1, span, force[i], height[i])
        faults = master.column("adapter", "link_state", k0, k1) == LINK_FAULT if link_col is not None else None
        fault = faults is not None and bool(faults.any())
        k = k0 + int(np.argmax(faults)) if fault else k0
    if fault:
        if k == 0 and not master.int_value("adapter", "session_started", 0):
            raise _Stop("link_lost", session_refused(master.int_value("adapter", "rig_refusal", 0),
                                                      state.prepared.options.hardware))
        raise _Stop("link_lost", f"link to the rig lost at t = {(k + 1) * dt:.3f} s: "
                                 f"{link_fault_reason(state.case, state.rig_paced)}; last position held")


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
    if state.monitor_2 is not None:  # two pantographs: the pair converges when both contact points do
        second = state.monitor_2.close_span(span, master.column("catenary", "force_at_sample_2", start, start + n))
        rec["change"] = max(rec["change"], second["change"])
        rec["second"] = {k: second[k] for k in ("change", "mean_N", "std_N", "max_N", "min_N")}
    if not all(master.column(fmu, output, start, start + n).any() for fmu, output in state.topology.contact_forces):
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
        end_observers(state)
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


def end_observers(state: RunState) -> None:
    """Every observer's on_end runs, even when one of them fails; the first failure is raised after."""
    failure = None
    for observer in state.observers:
        try:
            observer.on_end(state)
        except Exception as exc:
            failure = failure or exc
    if failure is not None:
        raise failure


def _back_to_normal() -> None:
    with suppress(OSError, AttributeError):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))




def _link_summary(state: RunState) -> dict:
    return link_summary(state.master, state.case, state.prepared.options.hardware, state.rig_paced,
                        state.scheduling, state.answer_us)
