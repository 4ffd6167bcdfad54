"""Two pantographs with one on the rig (issue 33, acceptance 4): the first pantograph through the adapter FMU and
the rig emulator (model-paced, lockstep), the second virtual, an instance of the pantograph FMU at the catenary's
second contact point; the first trailing the virtual one, then leading it. Each converges to the all-virtual pair
(the in-process pair loop, equal to the virtual pair's FMUs to 1e-9 N: test_two_pantograph_fmus.py) within 0.5 %
of the std for both pantographs: the converged result does not depend on the loop's latency (Paper D sec. 3.4),
which differs between the rig's loop and the virtual one. The rig-paced link: tests/benchmarks/bench_pair_rig.py."""
import json

import numpy as np
import pytest

from conftest import PATIENT_LINK, pantohil
from pantohil.models.case import load_case
from pantohil.models.hil.pair_loop import pair_delay_steps, run_pair_loop
from pantohil.models.stability.pair_map import pair_loop_latency_steps, pair_spectral_radius
from test_hardware import Emulator, rel_rms

pytestmark = pytest.mark.network


@pytest.mark.slow
# the virtual one's place: the rig's is the other
@pytest.mark.parametrize("position", ["leading", pytest.param("trailing", marks=pytest.mark.extended)])
def test_a_pair_with_one_pantograph_on_the_rig_converges_to_the_all_virtual_pair(position, tmp_path):
    overrides = ["second_pantograph.spacing_m=90", f'second_pantograph.position="{position}"',
                 "hil.max_frequency_hz=10", PATIENT_LINK]
    sets = [a for o in overrides for a in ("--set", o)]
    emulator = Emulator(tmp_path, *sets)
    try:
        out = tmp_path / "run"
        done = pantohil("run", "--hardware", emulator.address, *sets, "--out", str(out), "--quiet", timeout=1800)
    finally:
        stats = emulator.stop()
    assert done.returncode == 0, done.stdout + done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "converged" and summary["topology"] == "hardware_pair"
    assert summary["second_pantograph"]["position"] == position
    assert stats["commands"] == summary["link"]["sent"] > 0  # every step went through the rig
    table = np.genfromtxt(out / "steady_span.csv", delimiter=",", names=True)
    virtual = run_pair_loop(load_case(None, overrides))
    assert virtual.status == "converged"
    for got, want in ((table["f_N"], virtual.force_N[0]), (table["f2_N"], virtual.force_N[1])):
        assert rel_rms(got, want) < 5e-3
        assert got.mean() == pytest.approx(want.mean(), rel=1e-3)  # the rig's pantograph set as the pair's first
    # the pair's stability map with the rig's loop (the link's latency and the run's advance D) gives the run's
    # rate per span (issue 33 asks 10 %; 0.4-0.6 % measured at the run's last 20 spans, still in its transient)
    case, hil = load_case(None, overrides), summary["hil"]
    second_delay, second_latency = pair_delay_steps(case)[1], pair_loop_latency_steps(case)[1]
    rho = pair_spectral_radius(case, (hil["delay_steps"], second_delay),
                               (hil["loop_latency_steps"] + hil["rig_latency_steps"] + case.hold_steps, second_latency))
    change = np.array([h["change"] for h in summary["convergence"]])
    assert (change[-1] / change[-21]) ** (1 / 20) == pytest.approx(rho, rel=0.02)
