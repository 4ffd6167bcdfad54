"""The four FMUs: clean fmpy validation, units and descriptions on every variable, a clean process exit;
the libcosim run is in test_exchange.py."""
import os
import re
import shutil
import subprocess
import sys
import zipfile
import xml.etree.ElementTree as ET

import pytest
from fmpy.validation import validate_fmu



@pytest.fixture(scope="module")
def built(default_fmus):
    return {p.stem: p for p in default_fmus.glob("*.fmu")}


@pytest.mark.slow
def test_every_fmu_validates_clean(built):
    assert set(built) == {"catenary", "rig", "pantograph", "adapter"}
    for path in built.values():
        assert validate_fmu(str(path)) == []


@pytest.mark.slow
def test_every_real_variable_has_a_unit_and_a_description(built):
    for path in built.values():
        with zipfile.ZipFile(path) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
            assert "documentation/index.html" in z.namelist()
        units = {u.get("name") for u in root.iter("Unit")}
        for sv in root.iter("ScalarVariable"):
            assert sv.get("description")
            real = sv.find("Real")
            if real is not None:
                assert real.get("unit") in units, sv.get("name")


@pytest.mark.slow
def test_model_descriptions_state_step_state_and_dependencies(built):
    for name, path in built.items():
        with zipfile.ZipFile(path) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
        cs = root.find("CoSimulation")
        assert cs.get("canHandleVariableCommunicationStepSize") == "false", name
        assert cs.get("canGetAndSetFMUstate") == "true" and cs.get("canSerializeFMUstate") == "true", name
        experiment = root.find("DefaultExperiment")
        assert float(experiment.get("stepSize")) == 0.001 and float(experiment.get("stopTime")) == 0.5, name
        variables = list(root.iter("ScalarVariable"))
        outputs = [str(i + 1) for i, sv in enumerate(variables) if sv.get("causality") == "output"]
        assert [u.get("index") for u in root.iterfind("ModelStructure/Outputs/Unknown")] == outputs
        assert all(u.get("dependencies") == "" for u in root.iterfind("ModelStructure/Outputs/Unknown"))
        assert [u.get("index") for u in root.iterfind("ModelStructure/InitialUnknowns/Unknown")] == outputs
        # at initialisation: every parameter, and only the inputs the output declares (the rig and the pantograph
        # settle on the height they are given): the virtual HIL has no algebraic loop at initialisation
        parameters = {str(i + 1) for i, sv in enumerate(variables) if sv.get("causality") == "parameter"}
        for unknown in root.iterfind("ModelStructure/InitialUnknowns/Unknown"):
            known = set(unknown.get("dependencies").split())
            assert parameters <= known, name
            inputs = sorted(variables[int(i) - 1].get("name") for i in known - parameters)
            declared = {("rig", "actuator_height"): ["height_command"], ("pantograph", "contact_force"): ["height"],
                        ("pantograph", "head_height"): ["height"], ("pantograph", "in_contact"): ["height"]}
            output = variables[int(unknown.get("index")) - 1].get("name")
            if name != "adapter":  # the adapter: every input (a rig may answer during initialisation)
                assert inputs == declared.get((name, output), []), (name, output)
        assert all(variables[int(i) - 1].get("initial") == "calculated" for i in outputs)
        assert all(sv.get("name") != "model" and sv.get("name").replace("_", "").isalnum() for sv in variables)


# instantiate, initialise, free and exit: what every run's process does with each FMU
_ONE_FMU = """
import sys
from pathlib import Path
from pantohil.orchestrator.fmu_runtime import FmuInstance
inst = FmuInstance("fmu", Path(sys.argv[1]))
inst.setup(0.0, {})
inst.close()
"""


def _exit_errors(log: str) -> list[str]:
    """valgrind's invalid reads and writes whose stack runs through the process's exit."""
    blocks = re.split(r"\n==\d+== \n", log)
    return [b for b in blocks
            if re.search(r"Invalid (read|write)", b) and re.search(r"_dl_fini|__run_exit_handlers", b)]


@pytest.mark.slow
def test_a_process_that_loaded_an_fmu_exits_without_touching_freed_memory(built, tmp_path):
    # pythonfmu's library destroys its interpreter state twice at exit (a static destructor, then its ELF
    # destructor) unless the loader releases it first; the write into freed memory now and then aborts the
    # exit ("free(): corrupted unsorted chunks"), and valgrind reports it at every exit
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        pytest.skip("no valgrind")
    log = tmp_path / "valgrind.txt"
    proc = subprocess.run([valgrind, f"--log-file={log}", "--num-callers=30", sys.executable, "-c", _ONE_FMU,
                           str(built["pantograph"])], capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONMALLOC": "malloc"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    text = log.read_text()
    assert "ERROR SUMMARY" in text, text[-2000:]  # valgrind ran the interpreter itself, not a launcher script
    assert _exit_errors(text) == []
