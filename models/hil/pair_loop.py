"""The virtual HIL of two pantographs on one periodic catenary, in process (the pair's iteration,
models/hil/pair.py), with the FMU master's Jacobi semantics: the first pantograph through the case's rig
(catenary -> rig -> pantograph -> rig -> catenary, 4 connections), the second virtual behind the master's
connections (catenary -> pantograph -> catenary, 2). Each point's advance D is its own loop's latency (Paper
D sec. 3.4). The run stops by the rules of every run (models/hil/stop_rules.py), applied to each pantograph:
it converges when both have."""
from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..case import Case, CaseError
from ..catenary.asm.pair import PairSpec, pair_static_compliance_m_N, second_offset_m
from ..catenary.grid import SpanGrid
from ..catenary.interface import catenary_model
from ..parameters import fmu_values
from ..pantograph.interface import make_pantograph
from .loop import ConvergenceMonitor
from .pair import PairedHil
from .rig_loop import LOOP_CONNECTIONS, case_rig
from .stop_rules import StopRules

VIRTUAL_CONNECTIONS = 2  # catenary -> pantograph -> catenary: the second pantograph's loop


@dataclass
class PairLoopResult:
    """Outcome of a two-pantograph loop: status, message, spans, each pantograph's force in use over the last
    span [N] (first, second) and each one's convergence history."""
    status: str
    message: str
    spans: int
    force_N: np.ndarray  # shape (2, N)
    history: tuple[list, list]


def check_pair_case(case: Case) -> None:
    """A two-pantograph case this loop runs: ASM2 or the PFEM (what its `check_pair` allows), the rig's latency
    compensated in whole steps."""
    second = case.sections.second_pantograph
    if second is None:
        raise CaseError("second_pantograph: the case has no [second_pantograph] section", key="second_pantograph")
    model = catenary_model(case)
    if not hasattr(model, "pair_iteration"):
        raise CaseError(f"second_pantograph: two pantographs run on catenary.model = \"asm\" or \"pfem\" (not "
                        f"{case.model!r})", key="second_pantograph")
    if hasattr(model, "check_pair"):
        model.check_pair(case)
    if case.compensates_rig_response:
        raise CaseError("second_pantograph: with a rig file, set hil.rig_compensation = \"delay\" (the rig's "
                        "response is not compensated for two pantographs)", key="hil.rig_compensation")


def pair_delay_steps(case: Case) -> tuple[int, int]:
    """(D of the first pantograph, through the rig; D of the second, virtual): each its loop's latency plus
    the extra delay E (and the rig's latency for the first), Paper D sec. 3.4."""
    second = VIRTUAL_CONNECTIONS + (case.hold_steps if case.delay_compensation else 0)
    return case.delay_steps(LOOP_CONNECTIONS), second


def pair_profiles(case: Case) -> np.ndarray:
    """The static height at the N samples of each point, shape (2, N) [m]: z0(x_n) and z0(x_n -/+ L)."""
    second = case.sections.second_pantograph
    x = case.sample_positions_m()
    return np.array([case.profile.heights(x),
                     case.profile.heights(x + second_offset_m(second.spacing_m, second.position))])


def pair_reference_heights_m(case: Case) -> tuple[float, float]:
    """Each pantograph's reference height: its point's mean converged height z0_mean + (H_ii(0) + H_ij(0)) F_m,
    so that each converged mean force is the uplift force."""
    second = case.sections.second_pantograph
    z0 = pair_profiles(case)
    comp = pair_static_compliance_m_N(case.catenary, case.speed_m_s, second.spacing_m, second.position)
    f_m = case.pantograph.uplift_force_N
    return float(np.mean(z0[0]) + comp[0] * f_m), float(np.mean(z0[1]) + comp[1] * f_m)


def pair_spec(case: Case) -> PairSpec:
    """The case's second contact point."""
    second = case.sections.second_pantograph
    return PairSpec(second.spacing_m, second.position, second.coupling_compensation)


def pair_iteration(case: Case, delay_steps: tuple[int, int]) -> PairedHil:
    """The catenary FMU's pair iteration for the case (built from a staged folder as the FMU builds it:
    models/catenary/asm/pair_iteration.py) with the case's HIL settings, and the coupling compensation from the
    case's pantograph model unless [second_pantograph] coupling_compensation is false."""
    check_pair_case(case)
    model = catenary_model(case)
    with tempfile.TemporaryDirectory(prefix="pantohil-catenary-") as folder:
        model.stage(case, Path(folder), link=True)
        return model.pair_iteration(SpanGrid.of_case(case), fmu_values("catenary", case.values), Path(folder),
                                    case.hil_settings(delay_steps[0]), delay_steps, pair_spec(case))[0]


def pair_outcome(outcomes: list) -> tuple[str, str] | None:
    """The pair's end from each pantograph's (StopRules.after_span): the first that ends the run otherwise
    than converged, else converged when both are."""
    names = ("first", "second")
    for name, outcome in zip(names, outcomes, strict=True):
        if outcome is not None and outcome[0] != "converged":
            return outcome[0], f"{name} pantograph: {outcome[1]}"
    if all(o is not None for o in outcomes):
        return outcomes[0]
    return None


def run_pair_loop(case: Case) -> PairLoopResult:
    """Run the case's two-pantograph loop until it stops, or run.max_spans."""
    n = case.samples_per_span
    rules = StopRules.of_case(case)
    hil = pair_iteration(case, pair_delay_steps(case))
    rig = case_rig(case)
    pans = [make_pantograph(case.pantograph, case.dt_s, h) for h in pair_reference_heights_m(case)]
    monitors = (ConvergenceMonitor(n, case.rig_period_spans()), ConvergenceMonitor(n))
    cmd, act, meas = 0.0, 0.0, 0.0
    f1, f2, cmd2 = pans[0].settle(0.0), pans[1].settle(0.0), 0.0
    used = np.zeros((2, n))
    status, message, span = "span_limit", f"not converged within run.max_spans = {case.sections.run.max_spans}", 0
    for span in range(case.sections.run.max_spans):
        contact = [False, False]
        for i in range(n):
            cmd_new, cmd2_new = hil.step((meas, f2))
            used[:, i] = hil.force_estimate[:, i]
            act_new, meas_new = rig.step(cmd, f1)
            f1, f2 = pans[0].step(act), pans[1].step(cmd2)
            cmd, act, meas, cmd2 = cmd_new, act_new, meas_new, cmd2_new
            contact = [contact[0] or f1 != 0.0, contact[1] or f2 != 0.0]
            for point, command in enumerate((cmd, cmd2)):
                if rules.beyond(used[point, i], command):
                    message = rules.diverged_message((span * n + i + 1) * case.dt_s, span, used[point, i], command)
                    return PairLoopResult("diverged", message, span + 1, used.copy(),
                                          (monitors[0].history, monitors[1].history))
        outcome = pair_outcome([rules.after_span(span, m.close_span(span, used[p]), m, contact[p])
                                for p, m in enumerate(monitors)])
        if outcome is not None:
            status, message = outcome
            break
    return PairLoopResult(status, message, span + 1, used.copy(), (monitors[0].history, monitors[1].history))
