"""The FMU archive as pantohil finishes it: members rewritten reproducibly (the same inputs give the same
bytes), and the loader library put in front of pythonfmu's (builder/loader.py)."""
from __future__ import annotations

import io
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from . import loader

ZIP_TIME = (1980, 1, 1, 0, 0, 0)  # every member's time: the zip's bytes depend on its contents only


def rewrite_zip(path: Path, replace: dict[str, bytes]) -> None:
    """The FMU with members replaced or added, written reproducibly: members in name order, one fixed
    time, each keeping its permission bits."""
    members, modes = {}, {}
    with zipfile.ZipFile(path) as src:
        for item in src.infolist():
            members[item.filename], modes[item.filename] = src.read(item.filename), item.external_attr
    members.update(replace)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as dst:
        for name in sorted(members):
            info = zipfile.ZipInfo(name, ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = modes.get(name, 0o644 << 16)
            info.create_system = 3  # Unix: the permission bits are in external_attr
            dst.writestr(info, members[name])
    path.write_bytes(buf.getvalue())


def loader_members(fmu: Path, xml: bytes, runtime: loader.PythonRuntime, tmp: Path) -> dict[str, bytes]:
    """The zip entries that put the loader library in front of pythonfmu's (see builder/loader.py)."""
    root = ET.fromstring(xml)
    identifier = root.find("CoSimulation").get("modelIdentifier")
    vr = next(int(sv.get("valueReference")) for sv in root.iter("ScalarVariable") if sv.get("name") == "time_step")
    binary = f"binaries/{loader.PLATFORM}/{identifier}.so"
    with zipfile.ZipFile(fmu) as z:
        inner = z.read(binary)
    built = loader.compile_loader(identifier, vr, runtime, tmp / "loader" / f"{identifier}.so")
    return {binary: built.read_bytes(), f"binaries/{loader.PLATFORM}/{identifier}{loader.INNER_SUFFIX}.so": inner}
