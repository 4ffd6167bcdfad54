"""The sampling of one span that a periodic catenary model's iteration is built on."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class SpanGrid:
    """The sampling of one span: speed, time step, samples per span N, harmonics kept N_h, span length."""

    speed_m_s: float
    dt_s: float
    samples_per_span: int
    n_harmonics: int
    span_m: float

    @classmethod
    def of_case(cls, case: Any) -> SpanGrid:
        """The case's grid."""
        return cls(case.speed_m_s, case.dt_s, case.samples_per_span, case.n_harmonics, case.span_m)

    def positions_m(self) -> np.ndarray:
        """Position x of the contact point at each of the N samples [m]."""
        return np.arange(self.samples_per_span) * self.speed_m_s * self.dt_s
