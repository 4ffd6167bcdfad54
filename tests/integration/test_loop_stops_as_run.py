"""The test loop (`models/hil/rig_loop.run_loop`, used by the rig-chain and stability tests) stops where
`pantohil run --engine inprocess` of the same case stops: the same span, the same status, the same last
span of forces to the bit. Both build the iteration from a staged folder (models/catenary/interface.py),
step the three models in the Jacobi order of the fmpy master, and take one decision
(models/hil/stop_rules.py). The cases are every case and setting a rig-chain or stability test runs."""
from __future__ import annotations

import json

import numpy as np
import pytest

from pantohil.models.case import load_case
from pantohil.models.hil.rig_loop import run_loop
from pantohil.orchestrator.hil_run import run_case

# (case, overrides): tests/unit/test_rig_chain.py, tests/unit/test_rig_stability.py (CONVERGING run to
# their span limit, DIVERGING with the force limit they use) and tests/integration/test_rig_file_emulator.py
TO_THE_END = ["run.convergence_tol=1e-12"]
CASES = [
    ("paper_b_mass_300", []),
    ("paper_b_mass_300", ['hil.rig_compensation="delay"']),
    ("paper_b_pantograph_300", []),
    ("paper_b_pantograph_250", []),
    ("paper_b_pantograph_200", ["run.max_spans=40"]),  # converges slowly: the first 40 spans, then the limit
    ("paper_d_mass_250", []),
    ("paper_b_mass_300", [*TO_THE_END, "run.max_spans=60"]),
    ("paper_b_pantograph_300", [*TO_THE_END, "run.max_spans=70"]),
    ("paper_b_pantograph_300", ['hil.update="span"', "hil.hold_steps=0", "run.max_spans=60",
                                "run.force_limit_N=1e6"]),
    ("paper_b_pantograph_300", ["hil.hold_steps=0", "run.max_spans=60", "run.force_limit_N=1e6"]),
    ("paper_b_pantograph_200", ['hil.update="span"', "hil.hold_steps=0", "run.max_spans=60",
                                "run.force_limit_N=1e6"]),
    ("asm_250", ["rig.delay_steps=8", "run.max_spans=60"]),  # the default case past its barrier: diverges
]


@pytest.mark.slow
@pytest.mark.parametrize("name,overrides", CASES, ids=[f"{n}{o}" for n, o in CASES])
def test_the_test_loop_stops_where_the_in_process_run_stops(tmp_path, name, overrides):
    case = load_case(name, overrides)
    loop = run_loop(case)
    summary = run_case(case, tmp_path / "run", progress=False, engine="inprocess", plots=False)
    saved = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert (loop.status, loop.spans) == (summary.status, saved["spans"]), saved["message"]
    if loop.status != "diverged":  # a diverged run's last span is not complete
        steady = np.loadtxt(tmp_path / "run" / "steady_span.csv", delimiter=",", skiprows=1)
        written = np.array([float(f"{f:.12e}") for f in loop.force_N])  # as steady_span.csv writes f_N
        assert np.array_equal(steady[:, 3], written)
