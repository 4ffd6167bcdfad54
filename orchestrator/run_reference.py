"""What a run's report compares against, from the case alone: the ASM closed-form steady force and the
dropper positions of the case's catenary file (used by the run and by its report)."""
from __future__ import annotations

from pantohil.models.case import Case
from pantohil.models.catenary.asm.closed_form import (
    one_sided_harmonics,
    single_pantograph,
)


def closed_form_reference(case: Case):
    """The ASM closed-form steady force with the run's harmonic content (Paper A eqs. 38-41)."""
    z0 = case.z0_samples()
    ss = single_pantograph(case.catenary, case.pantograph, case.speed_m_s, case.span_m, one_sided_harmonics(z0),
                           case.pantograph.uplift_force_N, case.n_harmonics)
    return ss.force_series(case.samples_per_span)


def case_dropper_positions(case: Case) -> list:
    """Dropper positions of the case's catenary file within a span [m]."""
    from pantohil.models.catenary.fe.definition import load_definition

    return [float(x) for x in load_definition(case.definition_path).dropper_positions_m]
