"""Two pantographs as FMUs: the catenary FMU with a second contact point, two instances of the pantograph FMU and
the rig FMU, stepped by pantohil's fmpy master (builder/system.py `PAIR_CONNECTIONS`), give the in-process pair
loop's forces (models/hil/pair_loop.py: the same iteration and models, stepped alike)."""
import numpy as np
import pytest

from pantohil.builder.build_fmus import build_case_fmus
from pantohil.builder.fmu_parameters import second_pantograph_parameters
from pantohil.builder.system import PAIR_CONNECTIONS, PAIR_FMU_NAMES
from pantohil.models.case import load_case
from pantohil.models.hil.pair_loop import pair_delay_steps, run_pair_loop
from pantohil.orchestrator.masters import MASTERS

SPANS = 12


@pytest.mark.slow
@pytest.mark.parametrize("position", ["trailing", "leading"])
def test_the_pair_as_fmus_steps_as_the_in_process_pair_loop(position, tmp_path):
    case = load_case(None, ["second_pantograph.spacing_m=90", f'second_pantograph.position="{position}"',
                            "hil.max_frequency_hz=10", f"run.max_spans={SPANS}", "run.convergence_tol=1e-12"])
    n = case.samples_per_span
    first_delay = pair_delay_steps(case)[0]
    fmus = build_case_fmus(case, tmp_path, first_delay)
    fmus["pantograph_2"] = fmus["pantograph"]  # a second instance of the same FMU
    assert set(fmus) == set(PAIR_FMU_NAMES)
    parameters = {"catenary": {"delay_steps": first_delay}, "pantograph_2": second_pantograph_parameters(case)}
    master = MASTERS.get("fmpy").make(fmus, PAIR_CONNECTIONS, parameters, case.dt_s, SPANS * n)
    try:
        for _ in range(SPANS * n):
            master.step()
        last = slice((SPANS - 1) * n, SPANS * n)
        fmu_forces = np.array([master.column("catenary", "force_at_sample", last.start, last.stop),
                               master.column("catenary", "force_at_sample_2", last.start, last.stop)])
        heads = master.column("pantograph_2", "contact_force", last.start, last.stop)
    finally:
        master.close()
    loop = run_pair_loop(case)
    assert loop.spans == SPANS
    # the same operations in the same order: equal but for the last bits of the FFT-built operators
    assert np.max(np.abs(fmu_forces - loop.force_N)) < 1e-9
    assert np.std(heads) > 1.0  # the second pantograph FMU is in contact and moving
