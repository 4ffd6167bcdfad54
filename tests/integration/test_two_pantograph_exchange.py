"""Two pantographs for exchange: `pantohil build --ssp` of a case with a [second_pantograph] writes the pair's system
(the catenary, the rig, two instances of the pantograph FMU, six connections; builder/system.py
`PAIR_CONNECTIONS`), whose OSP system structure libcosim runs to the same forces as pantohil's fmpy master runs
the SSP (issue 33, acceptance 6), and which `pantohil run` refuses in one line (it runs one pantograph)."""
import numpy as np
import pytest
from fmpy.ssp.ssd import read_ssd

from conftest import pantohil
from pantohil.builder.ssp import read_ssp
from pantohil.builder.system import PAIR_CONNECTIONS
from pantohil.orchestrator.masters import MASTERS

STEPS = 3000  # past the ramp and into the iteration of both contact points (N = 936 at 250 km/h)
PAIR = ("--set", "second_pantograph.spacing_m=90", "--set", 'second_pantograph.position="leading"')


@pytest.fixture(scope="module")
def pair_ssp(tmp_path_factory):
    path = tmp_path_factory.mktemp("pair") / "pair.ssp"
    done = pantohil("build", *PAIR, "--ssp", str(path))
    assert done.returncode == 0, done.stdout + done.stderr
    assert "pantograph_2 a second instance of pantograph" in done.stdout
    return path


def _libcosim_forces(osp_dir) -> np.ndarray:
    """Both contact points' forces in use, step by step, from libcosim running the OSP system structure."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.WARNING)
    ex = CosimExecution.from_osp_config_file(str(osp_dir))
    observer = CosimObserver.create_last_value()
    ex.add_observer(observer)
    index = ex.slave_index_from_instance_name("catenary")
    refs = {v.name.decode(): v.reference for v in ex.slave_variables(index)}
    wanted = [refs["force_at_sample"], refs["force_at_sample_2"]]
    got = []
    for _ in range(STEPS):
        assert ex.step()
        got.append(observer.last_real_values(index, wanted))
    return np.array(got).T


@pytest.mark.slow
def test_the_pair_ssp_runs_in_libcosim_as_in_the_fmpy_master(pair_ssp, tmp_path):
    system = read_ssd(str(pair_ssp)).system  # validates against the SSP 1.0 schema
    assert [e.name for e in system.elements] == ["catenary", "rig", "pantograph", "pantograph_2"]
    assert {e.source for e in system.elements if e.name.startswith("pantograph")} == {"resources/pantograph.fmu"}
    unpacked = read_ssp(pair_ssp, tmp_path / "ssp")
    assert unpacked["connections"] == PAIR_CONNECTIONS
    first, second = unpacked["parameters"]["pantograph"], unpacked["parameters"]["pantograph_2"]
    assert first["reference_height"] != second["reference_height"]  # each pantograph's own mean force
    assert {k: v for k, v in first.items() if k != "reference_height"} == {
        k: v for k, v in second.items() if k != "reference_height"}
    case_dt = unpacked["parameters"]["catenary"]["time_step"]
    master = MASTERS.get("fmpy").make(unpacked["fmus"], unpacked["connections"], unpacked["parameters"], case_dt,
                                      STEPS)
    try:
        for _ in range(STEPS):
            master.step()
        fmpy_forces = np.array([master.column("catenary", name, 0, STEPS)
                                for name in ("force_at_sample", "force_at_sample_2")])
    finally:
        master.close()
    assert np.std(fmpy_forces[1, -936:]) > 1.0  # the second contact point is loaded and moving
    cosim_forces = _libcosim_forces(pair_ssp.parent / "pair_osp")
    # the same FMUs, the same Jacobi order and the same arithmetic: equal to the rounding of the last bits
    assert np.max(np.abs(cosim_forces - fmpy_forces)) < 1e-9


def test_pantohil_run_refuses_the_pair_ssp_in_one_line(pair_ssp, tmp_path):
    out = tmp_path / "out"
    done = pantohil("run", str(pair_ssp), "--out", str(out))
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "runs one pantograph" in lines[0], done.stderr
    assert not out.exists()
