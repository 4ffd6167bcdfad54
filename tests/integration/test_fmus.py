"""The four FMUs: clean fmpy validation, units and descriptions on every variable;
the libcosim run is in test_exchange.py."""
import zipfile
import xml.etree.ElementTree as ET

import pytest
from fmpy.validation import validate_fmu

from conftest import pantohil


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmus")
    proc = pantohil("build", "--out", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return {p.stem: p for p in out.glob("*.fmu")}


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
