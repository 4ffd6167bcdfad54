"""The stability map of the pair iteration (models/stability/pair_map.py): its spectral radius against the
in-process pair loop (models/hil/pair_loop.py, equal to the pair's FMUs), a converging setting's rate per span
and a diverging one's verdict (issue 33, acceptance 5, for the virtual pair)."""
import pytest
from conftest import pair_rate

from pantohil.models.case import CaseError, load_case
from pantohil.models.hil.pair_loop import run_pair_loop
from pantohil.models.stability.pair_map import pair_spectral_radius

PAIR_10HZ = ["hil.max_frequency_hz=10", "second_pantograph.spacing_m=200"]


@pytest.mark.slow
def test_the_map_gives_the_rate_of_a_converging_pair():
    case = load_case(None, [*PAIR_10HZ, "run.max_spans=150", "run.convergence_tol=1e-12"])
    rho = pair_spectral_radius(case)
    result = run_pair_loop(case)
    assert result.spans == 150 and rho < 1
    # 150 spans: the slow mode (rate 0.986) alone is left, about 0.1 % from the map's (issue 33 asks 10 %)
    assert pair_rate(result) == pytest.approx(rho, rel=0.01)


@pytest.mark.slow
def test_the_map_predicts_the_plain_iteration_diverging_at_a_short_spacing():
    case = load_case(None, ["hil.max_frequency_hz=10", "second_pantograph.spacing_m=30",
                            "second_pantograph.coupling_compensation=false"])
    assert pair_spectral_radius(case) > 1.2
    assert run_pair_loop(case).status == "diverged"


@pytest.mark.slow
def test_the_map_tells_which_update_converges_at_a_spacing():
    """L = 70 m at 250 km/h: step by step the pair diverges even with the coupling compensation (map 1.39);
    span by span (Q exact) it converges at 0.9535 per span, the rate measured over spans 20-80 (0.9534-0.9544:
    the slow mode is alone by then; issue 33 asks 10 %)."""
    overrides = ["hil.max_frequency_hz=10", "second_pantograph.spacing_m=70", "run.max_spans=80",
                 "run.convergence_tol=1e-12"]
    step = load_case(None, overrides)
    assert pair_spectral_radius(step) > 1.2
    assert run_pair_loop(step).status == "diverged"
    span = load_case(None, [*overrides, "hil.update=span", "hil.relaxation=0.3"])
    rho = pair_spectral_radius(span)
    result = run_pair_loop(span)
    assert rho < 1 and result.spans == 80
    assert pair_rate(result, window=60) == pytest.approx(rho, rel=0.01)


def test_the_map_refuses_a_rig_that_is_not_a_pure_delay():
    case = load_case(None, [*PAIR_10HZ, "rig.servo_bandwidth_hz=40"])
    with pytest.raises(CaseError, match="pure delay"):
        pair_spectral_radius(case)
