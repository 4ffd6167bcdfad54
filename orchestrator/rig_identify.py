"""`pantohil rig-identify`: measure a rig's frequency response at a case's kept harmonics and write it
into a rig file that a case compensates with (Paper D sec. 3.4 generalised; Paper B sec. 5.1's mass).

The rig is excited with the multisine of `models/rig/identification.py` with the case's rigid mass
mounted, either in process through a rig file's chain (`--rig FILE`) or on a rig controller (or
`pantohil rig-emulator`) through the same adapter FMU and UDP link a hardware run uses
(`--hardware HOST:PORT`). The adapter's answer to a command comes `pipeline_steps` steps later
(rig-paced: one), so the records are aligned by that shift; a lost answer, or a rig-paced tick that
held an old height (no answer covered it), spoils the record and nothing is written. Every input is checked first: a bad
one is one line, exit code 2, and nothing written.
"""
from __future__ import annotations

import contextlib
import datetime
import gc
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pantohil.models.case import Case, CaseError
from pantohil.models.errors import LinkError
from pantohil.models.rig.drive_chain import MeasuredResponse, RigSpec, frequency_response, record_spans
from pantohil.models.rig.identification import (Excitation, IdentificationError, excitation, identify_chain,
                                                is_mass, mass_force, estimate, response_errors)
from pantohil.models.rig.rig_file import rig_to_toml, with_measured
from pantohil.models.storage import write_text_atomic

from pantohil.builder.system import HORIZON_OUTPUTS

from .stopping import shielded

LINK_FAULT = 2
MAX_UNCOVERED = 0.01  # rig-paced: uncovered ticks a record may hold (their figures are printed)
LOCKSTEP_ANSWER_WAIT_S = 1.0  # model-paced: the longest wait for each answer (link.receive_timeout_s if longer)


class LinkLost(LinkError):
    """The rig did not accept the session, or the link faulted during the excitation."""


@dataclass(frozen=True)
class IdentifyRequest:
    """What to identify: the case (its mass, span and kept harmonics), the rig (a rig file's chain,
    or a rig controller at `hardware`) and the excitation's amplitude and record length."""

    case: Case
    out: Path
    rig: RigSpec | None = None  # --rig: identify this chain in process
    hardware: tuple | None = None  # --hardware: (host, port) of the rig controller
    amplitude_m: float = 1e-3
    spans: int | None = None
    overwrite: bool = False
    rt_priority: int | None = 50  # rig-paced: SCHED_FIFO while stepping, as a run


def check_request(req: IdentifyRequest) -> RigSpec:
    """Refuse a bad request before anything runs (CaseError, one line); returns the rig file the result
    extends: the --rig file, the case's rig file, or a bare one at the case's dt."""
    case = req.case
    if not is_mass(case.pantograph):
        raise CaseError(f"--case: rig-identify mounts the case's rigid mass; {case.name} has a "
                        f"\"{case.pantograph.model}\" pantograph (pantograph.model = \"rigid_mass\", e.g. "
                        f"paper_b_mass_300.toml)")
    if case.n_harmonics < 2:
        raise CaseError("--case: the case keeps no harmonic above DC (hil.max_frequency_hz): nothing to identify")
    spec = req.rig if req.rig is not None else case.rig_spec
    if req.rig is not None and abs(spec.model_step_s - case.dt_s) > 1e-6 * case.dt_s:
        raise CaseError(f"--rig: the rig runs at dt = {spec.model_step_s:g} s; the case's step is {case.dt_s:.6g} s")
    if spec is not None and req.spans is not None:
        period = record_spans(spec, case.dt_s, case.samples_per_span, minimum=1)
        if req.spans % period:
            raise CaseError(f"--spans: the rig's clocks repeat every {period} spans against this span: record a "
                            f"multiple of {period} (got {req.spans})")
    out = Path(req.out)
    if out.is_dir():
        raise CaseError(f"--out: {out} is a directory, not a rig file")
    if not out.parent.is_dir():
        raise CaseError(f"--out: the folder {out.parent} does not exist")
    if out.exists() and not req.overwrite:
        raise CaseError(f"--out: {out} exists (--overwrite to replace it)")
    return spec if spec is not None else RigSpec("identified", case.dt_s, description="identified rig (no rig file)")


def identify(req: IdentifyRequest, announce=print) -> dict:
    """Excite the rig, estimate its response, write the rig file with it; returns the response, the
    errors against the rig file's own model (if it describes a chain) and the file written."""
    base = check_request(req)
    case = req.case
    chain_known = req.rig is not None or case.rig_spec is not None
    exc = excitation(base if chain_known else None, case.dt_s, case.samples_per_span, case.n_harmonics,
                     req.amplitude_m, req.spans)
    source = f"rig file {base.name} in process" if req.hardware is None else f"{req.hardware[0]}:{req.hardware[1]}"
    announce(f"identifying {source}: {case.n_harmonics - 1} harmonics, {exc.frequencies_hz()[0]:.4g}-"
             f"{exc.frequencies_hz()[-1]:.4g} Hz, {req.amplitude_m * 1e3:g} mm, {exc.record_spans} spans recorded "
             f"after {exc.settle_spans} settling ({exc.total_steps} steps), mass {case.pantograph.masses_kg[0]:g} kg")
    uncovered = 0
    if req.hardware is None:
        r = case.sections.rig
        measured = identify_chain(base, exc, case.pantograph, r.force_offset_N, r.noise_std_N, r.noise_seed)
    else:
        measured, uncovered = _identify_hardware(case, req.hardware, exc, req.rt_priority)
        if uncovered:
            announce(f"the record holds {uncovered} uncovered rig ticks (no answer covered them: the actuator held)")
    errors = None
    if chain_known:
        gz, gf = frequency_response(base, case.dt_s, case.samples_per_span, case.n_harmonics)
        errors = response_errors(measured, gz[1:], gf[1:])
    header = _header(case, exc, source + (f" ({uncovered} uncovered ticks in the record)" if uncovered else ""),
                     errors)
    write_text_atomic(Path(req.out), rig_to_toml(with_measured(base, measured), header))
    for line in _report(measured, errors):
        announce(line)
    announce(f"rig file written: {req.out}")
    return {"measured": measured, "errors": errors, "excitation": exc, "uncovered": uncovered}


@dataclass
class CleanWindow:
    """The first window of `length` aligned steps from `first` on with no uncovered rig tick (one that held an
    old height) in it nor in the `margin` steps before it (the chain's memory); rig-paced records only."""

    first: int
    length: int
    margin: int
    shift: int
    uncovered: int = 0
    last_reuse: int = -1
    start: int | None = None

    def update(self, k: int, uncovered: int) -> bool:
        """Row k taken with the rig's uncovered count: True once a clean window is complete."""
        if uncovered > self.uncovered:
            self.uncovered, self.last_reuse = uncovered, k - self.shift
        begin = max(self.first, self.last_reuse + 1 + self.margin)
        if k - self.shift + 1 >= begin + self.length:
            self.start = begin
            return True
        return False


def _identify_hardware(case: Case, hardware: tuple, exc: Excitation,
                       rt_priority: int | None) -> tuple[MeasuredResponse, int]:
    """The excitation through the adapter FMU and the UDP link, records aligned by the answer's shift;
    returns the response and the uncovered ticks in the record. Rig-paced, an uncovered tick (the actuator
    held an old height) disturbs the record: the excitation (periodic after the settling spans) goes on for up to 3 more
    records until a window of whole spans has none, else the window with the fewest is taken if they are
    at most MAX_UNCOVERED of its ticks (an uncovered tick matters only where the drive takes a reference)."""
    rig_paced = case.sections.link.paced_by == "rig"
    shift = 1 if rig_paced else int(case.sections.link.pipeline_steps)
    n, length = exc.samples_per_span, exc.record.stop - exc.record.start
    window = CleanWindow(exc.record.start, length, 2 * n, shift)  # margin: the motion profile settles in 2 spans
    heights = exc.heights(exc.total_steps + (3 * length if rig_paced else 0))
    with tempfile.TemporaryDirectory(prefix="pantohil_identify_") as tmp:
        rows = _adapter_rows(case, hardware, heights, shift, Path(tmp), rt_priority if rig_paced else None, window)
    uncovered = 0
    if window.start is None:
        window.start, uncovered = _least_uncovered(rows[shift:, 3], window)
        if uncovered > MAX_UNCOVERED * length:
            raise IdentificationError(f"the rig held an old height (no answer covered the tick) at {uncovered} of "
                                      f"{length} ticks of the best record (at most {MAX_UNCOVERED:.0%} taken): "
                                      f"nothing identified")
    command, height, measured = rows[:len(rows) - shift, 0], rows[shift:, 1], rows[shift:, 2]
    true = mass_force(case.pantograph, case.dt_s, height)
    a = slice(window.start - exc.record.start, window.start - exc.record.start + exc.total_steps)
    return estimate(exc, command[a], height[a], true[a], measured[a]), uncovered


def _least_uncovered(counts: np.ndarray, window: CleanWindow) -> tuple[int, int]:
    """The window start with the fewest uncovered ticks in it and its margin, and that number."""
    ticks = np.concatenate([[0], np.diff(counts) > 0]).cumsum()  # uncovered ticks up to each aligned step
    starts = np.arange(window.first, len(counts) - window.length + 1)
    inside = ticks[starts + window.length - 1] - ticks[starts - window.margin]
    best = int(np.argmin(inside))
    return int(starts[best]), int(inside[best])


def _adapter_rows(case: Case, hardware: tuple, heights: np.ndarray, extra: int, tmp: Path,
                  rt_priority: int | None, window: CleanWindow) -> np.ndarray:
    """Step the adapter FMU over the heights (then `extra` steps holding the last one) until `window` is
    complete: per step the command sent, the actuator height and force of the answer taken, and the rig's
    uncovered count. A rig-paced session steps at SCHED_FIFO `rt_priority` (if permitted) with the collector
    paused, as a run."""
    from pantohil.builder.build_fmus import build_case_fmus

    from .fmu_runtime import FmuInstance
    from .pacing import set_realtime_priority

    fmu = build_case_fmus(case, tmp / "fmus", 0, ("adapter",), hardware)["adapter"]
    inst = FmuInstance("adapter", fmu)
    link = case.sections.link
    # lockstep: nothing paces the excitation and the record needs every answer, so each is waited for
    patient = {} if link.paced_by == "rig" else {"receive_timeout_s": max(link.receive_timeout_s,
                                                                              LOCKSTEP_ANSWER_WAIT_S)}
    try:
        inst.setup(0.0, patient)  # the excitation starts at 0, the adapter's starting height
        _check_session(inst, hardware)
        set_realtime_priority(rt_priority)
        gc.collect()
        gc.disable()
        return _step_adapter(inst, heights, extra, case.dt_s, window)
    finally:
        gc.enable()
        with contextlib.suppress(OSError, AttributeError):
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        inst.close()


def _check_session(inst, hardware: tuple) -> None:
    from .link_diagnostics import REFUSALS

    start = inst.get_values(["link_state", "session_started", "rig_refusal"])
    if start["link_state"] == LINK_FAULT and not start["session_started"]:
        why = "; ".join(t for bit, t in REFUSALS.items() if int(start["rig_refusal"]) & bit) or "it did not answer"
        raise LinkLost(f"the rig at {hardware[0]}:{hardware[1]} did not accept the session start: {why}")


def _step_adapter(inst, heights: np.ndarray, extra: int, dt: float, window: CleanWindow) -> np.ndarray:
    """Step the adapter through the excitation; the horizon it sends is the excitation's next heights
    (known in advance), so a late answer costs the rig nothing but an uncovered tick costs the record."""
    ahead = int(inst.get_values(["horizon_steps"])["horizon_steps"]) - 1
    command = inst.port(["height_command", *HORIZON_OUTPUTS[:ahead]])
    reals = inst.port(["command_sent", "actuator_height", "measured_force"])
    ints = inst.port(["uncovered", "link_state"])
    rows = np.empty((len(heights) + extra, 4))
    last = len(heights) - 1
    for k in range(len(rows)):
        with shielded():  # a stop signal interrupts between steps, never inside the FMU
            command.write([float(heights[min(j, last)]) for j in range(k, k + ahead + 1)])
            inst.do_step(k * dt, dt)
            uncovered, link = ints.read()
        if link == LINK_FAULT:
            raise LinkLost(f"link to the rig lost at step {k} of the excitation: nothing identified")
        rows[k, :3] = reals.read()
        rows[k, 3] = uncovered
        if window.update(k, uncovered):
            return rows[:k + 1]
    return rows


def _header(case: Case, exc: Excitation, source: str, errors: dict | None) -> str:
    when = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = [f"Identified by pantohil rig-identify ({when}): {source}, case {case.name}, mass "
             f"{case.pantograph.masses_kg[0]:g} kg,",
             f"a multisine of {exc.amplitude_m * 1e3:g} mm at the {case.n_harmonics - 1} kept harmonics "
             f"({exc.frequencies_hz()[0]:.4g}-{exc.frequencies_hz()[-1]:.4g} Hz), {exc.record_spans} spans recorded.",
             "[response] holds the measured gains a case compensates with (hil.rig_compensation = \"response\");",
             "the other sections describe the rig's chain for the virtual runs, the latency and the steady state's "
             "period."]
    if errors is not None:
        lines.append(f"Against the chain's model (frequency_response): height {_worst(errors['height'])}; force "
                     f"{_worst(errors['force'])}.")
    return "\n".join(lines)


def _worst(e: dict) -> str:
    return f"magnitude max {100 * e['max_magnitude_error']:.3g} %, phase max {e['max_phase_error_deg']:.3g} deg"


def _report(measured: MeasuredResponse, errors: dict | None) -> list[str]:
    lines = ["harmonic  f [Hz]   |G_z|    arg G_z [deg]   |G_f|    arg G_f [deg]"]
    for i, f in enumerate(measured.frequencies_hz):
        gz, gf = measured.height[i], measured.force[i]
        lines.append(f"{i + 1:8d} {f:8.3f} {abs(gz):8.4f} {np.degrees(np.angle(gz)):13.2f} {abs(gf):8.4f} "
                     f"{np.degrees(np.angle(gf)):13.2f}")
    if errors is not None:
        lines.append(f"against the rig file's model: height {_worst(errors['height'])}; "
                     f"force {_worst(errors['force'])}")
    return lines
