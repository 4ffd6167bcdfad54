"""The case as the FMUs' parameter values: every case key that reaches an FMU under its declared name, and
the quantities the FMUs take derived from the case (speed, step, delay advance D, rig address)."""
from __future__ import annotations

from pantohil.fmus.pantohil_catenary import one_pantograph_parameters
from pantohil.models.case import Case
from pantohil.models.hil.pair_loop import check_pair_case, pair_delay_steps, pair_reference_heights_m
from pantohil.models.parameters import fmu_values

from .system import loop_latency_steps


def fmu_parameters(case: Case, delay_steps: int,
                   rig_address: tuple[str, int] = ("127.0.0.1", 47800)) -> dict[str, dict]:
    """The case as FMU parameter values, by FMU: every case key that reaches an FMU under its declared
    name (models/parameters.py), and the quantities the FMUs take derived from the case."""
    pan = case.pantograph
    resolved = {"hil.delay_steps": delay_steps, "pantograph.uplift_force_N": pan.uplift_force_N,
                "pantograph.masses_kg": pan.masses_kg, "pantograph.stiffnesses_N_m": pan.stiffnesses_N_m,
                "pantograph.dampings_Ns_m": pan.dampings_Ns_m}
    derived = {
        "catenary": {"speed": case.speed_m_s, "time_step": case.dt_s, "samples_per_span": case.samples_per_span,
                     "rig_compensation": int(case.compensates_rig_response), "horizon_steps": case.horizon_steps},
        "pantograph": {"n_masses": pan.n, "reference_height": case.reference_height_m(), "time_step": case.dt_s},
        "rig": {"time_step": case.dt_s, "rig_chain": int(case.rig_spec is not None)},
        "adapter": {"rig_host": rig_address[0], "rig_port": rig_address[1], "time_step": case.dt_s,
                    "local_host": case.sections.link.local_host, "key_file": case.sections.link.key_file,
                    "horizon_steps": case.horizon_steps},
    }
    if case.sections.second_pantograph is not None:
        derived["catenary"].update(pair_parameters(case))
    else:
        derived["catenary"].update(one_pantograph_parameters())
    values = {name: {**fmu_values(name, case.values, resolved), **extra} for name, extra in derived.items()}
    if case.sections.second_pantograph is not None:  # the second instance of the pantograph FMU
        values["pantograph_2"] = {**values["pantograph"], **second_pantograph_parameters(case)}
    return values


def pair_parameters(case: Case) -> dict:
    """The catenary FMU's parameters of a second contact point (models/hil/pair.py), the second pantograph virtual
    behind the master's two connections."""
    check_pair_case(case)
    second = case.sections.second_pantograph
    return {"second_pantograph": 1, "second_spacing_m": second.spacing_m,
            "second_position": ("trailing", "leading").index(second.position),
            "coupling_compensation": int(second.coupling_compensation), "delay_steps_2": pair_delay_steps(case)[1]}


def second_pantograph_parameters(case: Case) -> dict:
    """The parameters the second pantograph's instance of the pantograph FMU takes beside the first's: its
    reference height (each pantograph's mean force is the uplift force)."""
    return {"reference_height": pair_reference_heights_m(case)[1]}


def default_delay_steps(case: Case) -> int:
    """D for the standard topology: its loop latency plus the rig's (Paper D sec. 3.4)."""
    return case.delay_steps(loop_latency_steps())
