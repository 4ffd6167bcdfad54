"""The virtual HIL loop of a case through its rig, in process, with the FMU master's semantics.

catenary -> rig -> pantograph -> rig -> catenary with Jacobi stepping: at step k every block gets
the outputs of step k-1 (one step per connection, 4 in the loop), as `orchestrator.master` steps
the three FMUs. It runs the same model classes as the FMUs, so it gives the same iteration without
building them: for studies of rig compensation and for tests.
"""
from __future__ import annotations

import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..case import Case
from ..catenary.grid import SpanGrid
from ..catenary.interface import catenary_model
from ..parameters import fmu_values
from ..pantograph.interface import make_pantograph
from ..rig.chain import Rig
from ..rig.compensation import HarmonicCompensation
from ..rig.drive_chain import RigChain, RigSpec
from .loop import ConvergenceMonitor
from .stop_rules import StopRules

LOOP_CONNECTIONS = 4


@dataclass
class LoopResult:
    """Outcome of a loop run in process: status, spans, the last span's force [N] and the convergence history."""
    status: str  # as a run's: "converged", "completed", "diverged", "contact_lost" or "span_limit"
    spans: int
    force_N: np.ndarray  # the force the catenary uses over the last span (f_N of steady_span.csv)
    history: list


def case_iteration(case: Case, delay_steps: int):
    """The catenary FMU's iteration for the case (models/catenary/interface.py: built from a staged folder as
    the FMU builds it), with the rig's response compensated if the case says so."""
    comp = HarmonicCompensation(case.samples_per_span, *case.rig_response()) if case.compensates_rig_response else None
    model = catenary_model(case)
    with tempfile.TemporaryDirectory(prefix="pantohil-catenary-") as folder:
        model.stage(case, Path(folder), link=True)
        return model.iteration(SpanGrid.of_case(case), fmu_values("catenary", case.values), Path(folder),
                               case.hil_settings(delay_steps), comp)[0]


def case_rig(case: Case, dt_s: float | None = None, spec: RigSpec | None = None):
    """The rig of a case at dt_s (default the case's): the chain of `spec` or else of the case's rig file
    (Paper B sec. 4, Paper D sec. 2), with the case's force offset and noise; else the [rig] section's Rig.
    The in-process loop and `pantohil rig-emulator` both take their rig from here."""
    r = case.sections.rig
    dt = case.dt_s if dt_s is None else dt_s
    spec = case.rig_spec if spec is None else spec
    if spec is not None:
        return RigChain(spec, dt, 0.0, 0.0, r.force_offset_N, r.noise_std_N, r.noise_seed)
    return Rig(case.rig, dt)


def run_loop(case: Case, force_limit_N: float | None = None, rig_lead_steps: int = 0) -> LoopResult:
    """Run the case's loop until it stops by the rules every run follows (models/hil/stop_rules.py: the
    limits after each step, contact loss, convergence, a planned length or a lasting change after each
    span), or run.max_spans; `force_limit_N` replaces run.force_limit_N. `rig_lead_steps`: the rig started
    that many steps before the loop, at rest (the phase of its clocks against the span: through the adapter
    and `pantohil rig-emulator` the loop has one connection fewer and the rig runs 1 step ahead)."""
    n = case.samples_per_span
    rules = StopRules.of_case(case)
    if force_limit_N is not None:
        rules = replace(rules, force_limit_N=force_limit_N)
    hil = case_iteration(case, case.delay_steps(LOOP_CONNECTIONS))
    rig = case_rig(case)
    pan = make_pantograph(case.pantograph, case.dt_s, case.reference_height_m())
    monitor = ConvergenceMonitor(n, case.rig_period_spans())
    cmd, act, meas, f = 0.0, 0.0, 0.0, pan.settle(0.0)
    for _ in range(rig_lead_steps):
        rig.step(0.0, f)
    status, span = "span_limit", 0
    used = np.zeros(n)
    for span in range(case.sections.run.max_spans):
        contact = False
        for i in range(n):
            cmd_new = hil.step(meas)
            used[i] = hil.force_estimate[i]
            act_new, meas_new = rig.step(cmd, f)
            f = pan.step(act)
            cmd, act, meas = cmd_new, act_new, meas_new
            contact = contact or f != 0.0
            if rules.beyond(used[i], cmd):
                return LoopResult("diverged", span, used.copy(), monitor.history)
        outcome = rules.after_span(span, monitor.close_span(span, used), monitor, contact)
        if outcome is not None:
            status = outcome[0]
            break
    return LoopResult(status, span + 1, used.copy(), monitor.history)
