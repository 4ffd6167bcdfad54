"""`pantohil compare`'s dropper-correction measures (Paper C eqs. 36-40, Paper D sec. 3.7): the largest
value of a correction that lives a few steps depends on which instants the time grid samples, its
impulse does not."""
from __future__ import annotations

import numpy as np
import pytest

from pantohil.orchestrator.fem_sim import correction_measures

DT = 0.002  # Paper D's step


def _pulse(t_peak: float) -> np.ndarray:
    """A triangular correction of 1000 N, 12 ms wide, on a 0.78 s span sampled at DT; a second dropper taut."""
    t = np.arange(390) * DT
    c = np.maximum(0.0, 1000.0 * (1.0 - np.abs(t - t_peak) / 0.006))
    return np.column_stack([c, np.zeros_like(t)])


def test_the_impulse_of_a_short_correction_does_not_depend_on_the_instants_sampled():
    on = correction_measures(_pulse(0.300), DT)  # a sample on the peak
    off = correction_measures(_pulse(0.301), DT)  # the peak half a step between two samples
    assert on["correction_max_N"][0] == pytest.approx(1000.0)
    assert off["correction_max_N"][0] == pytest.approx(1000.0 * (1.0 - 0.001 / 0.006))  # 16.7 % lower
    assert on["correction_impulse_Ns"][0] == pytest.approx(1000.0 * 0.006, rel=1e-9)  # the area: 6 N s
    assert off["correction_impulse_Ns"][0] == pytest.approx(1000.0 * 0.006, rel=1e-9)
    assert on["slack_steps"] == [5, 0] and off["slack_steps"] == [6, 0]
    assert on["correction_impulse_Ns"][1] == 0.0 and on["correction_max_N"][1] == 0.0
