"""When a periodic HIL run stops: the one decision every loop takes (the run of `pantohil run` on FMUs, on
libcosim or in process, on a rig or virtual, and the test loop `models/hil/rig_loop.run_loop`).

After every step: a force in use or a height command beyond `run.force_limit_N` / `run.height_limit_m`
(or not a number) is divergence. After every span: no contact force for the whole span is contact loss;
a span-to-span change at or below `run.convergence_tol` after the ramp, from the third span on, is
convergence (Paper D sec. 3.5); a planned length (`run.duration_s`) ends the run at its last span,
converged or only completed; a median change that stays above `run.divergence_change` is divergence (a
limit cycle that contact loss bounds, `ConvergenceMonitor.diverging`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FIRST_CONVERGED_SPAN = 2  # the change of a span needs the span before, and the first span is the ramp's


@dataclass(frozen=True)
class StopRules:
    """The [run] limits of one case, on its sampling."""

    samples_per_span: int
    dt_s: float
    ramp_steps: int
    convergence_tol: float
    force_limit_N: float
    height_limit_m: float
    divergence_change: float
    divergence_spans: int
    duration_s: float  # run.duration_s: 0 stops at convergence

    @property
    def duration_spans(self) -> int:
        """The whole spans of run.duration_s (0: none planned)."""
        return -(-round(self.duration_s / self.dt_s) // self.samples_per_span)

    @classmethod
    def of_case(cls, case) -> StopRules:
        """The rules of a case (models/case.py `Case`)."""
        run = case.sections.run
        n, dt = case.samples_per_span, case.dt_s
        return cls(n, dt, case.ramp_steps, run.convergence_tol, run.force_limit_N, run.height_limit_m,
                   run.divergence_change, run.divergence_spans, run.duration_s)

    def first_beyond(self, force_N: np.ndarray, height_m: np.ndarray) -> int | None:
        """Index of the first step whose force in use or height command is beyond the limits (or NaN)."""
        bad = ~((np.abs(force_N) <= self.force_limit_N) & (np.abs(height_m) <= self.height_limit_m))
        return int(np.argmax(bad)) if bad.any() else None

    def beyond(self, force_N: float, height_m: float) -> bool:
        """Whether one step's force or height is beyond the limits (or NaN)."""
        return not (abs(force_N) <= self.force_limit_N and abs(height_m) <= self.height_limit_m)

    def diverged_message(self, t_s: float, span: int, force_N: float, height_m: float) -> str:
        """The message of a step beyond the limits."""
        return (f"diverged at t = {t_s:.3f} s (span {span}): force {force_N:.4g} N, height {height_m:.4g} m "
                "beyond run.force_limit_N / run.height_limit_m")

    def after_span(self, span: int, record: dict, monitor, contact: bool, answered: bool = True
                   ) -> tuple[str, str] | None:
        """(status, message) if the run ends with span `span` (its ConvergenceMonitor `record`), else None.
        `contact`: the pantograph's force was not 0 throughout; `answered`: on a rig, the span's end was
        answered (a run does not converge on a span the rig did not answer)."""
        n, dt = self.samples_per_span, self.dt_s
        start = span * n
        if not contact:
            return "contact_lost", (f"contact lost: the contact force was 0 N for the whole span {span} "
                                    f"(t = {start * dt:.3f}-{(start + n) * dt:.3f} s)")
        settled = (start >= self.ramp_steps and span >= FIRST_CONVERGED_SPAN
                   and record["change"] <= self.convergence_tol and answered)
        if self.duration_spans and span + 1 >= self.duration_spans:
            if settled:
                return "converged", f"converged; ran {span + 1} spans (run.duration_s)"
            return "completed", (f"completed the planned run.duration_s = {self.duration_s:g} s "
                                 f"({span + 1} spans); not converged: the last span's change {record['change']:.3g} "
                                 f"is above run.convergence_tol = {self.convergence_tol:g}")
        if settled and not self.duration_spans:
            return "converged", f"converged after {span + 1} spans"
        median = monitor.diverging(self.divergence_spans, self.divergence_change, -(-self.ramp_steps // n) + 1)
        if median is not None:
            return "diverged", (f"diverged at span {span}: the span-to-span change stayed at {median:.2f} of the std "
                                f"(median of {self.divergence_spans} spans, run.divergence_change "
                                f"{self.divergence_change:g})")
        return None
