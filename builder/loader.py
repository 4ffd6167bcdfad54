"""The FMUs' loader library (loader/fmu_loader.c), compiled with the system C compiler for each FMU.

It lets a host with no Python of its own load a pythonfmu FMU: it opens libpython with global symbols
(from PANTOHIL_LIBPYTHON, or the path recorded here at build time), points PYTHONHOME/PYTHONPATH at
the interpreter and the site-packages holding numpy and scipy, then loads pythonfmu's library and
forwards the FMI calls to it, rejecting any communication step other than the FMU's time_step.
"""
from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from dataclasses import dataclass
from pathlib import Path

import fmpy

from pantohil.models.errors import SetupError

SOURCE = Path(__file__).parent / "loader" / "fmu_loader.c"
FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"
PLATFORM = "linux64"  # the loader is built for the platform pantohil builds on
INNER_SUFFIX = "_pythonfmu"  # pythonfmu's library becomes binaries/linux64/<modelIdentifier>_pythonfmu.so


class LoaderError(SetupError):
    """The loader library could not be built; one line."""


@dataclass(frozen=True)
class PythonRuntime:
    """What an FMU's embedded Python needs, as found in the Python that builds it."""
    libpython: str  # "" when this Python has no shared libpython
    home: str
    path: str  # os.pathsep-joined site-packages of numpy and scipy
    minor: int

    def key(self) -> str:
        """The runtime as a string for the FMU cache key."""
        return f"{self.libpython}|{self.home}|{self.path}|{self.minor}"


def python_runtime() -> PythonRuntime:
    """This interpreter's libpython, home and the site-packages holding numpy and scipy, for the loader."""
    libdir, soname = sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("INSTSONAME")
    lib = Path(libdir or "", soname or "")
    libpython = str(lib) if sysconfig.get_config_var("Py_ENABLE_SHARED") and lib.is_file() else ""
    sites = []
    for module in ("numpy", "scipy"):
        spec = importlib.util.find_spec(module)
        if spec is not None and spec.origin:
            site = str(Path(spec.origin).parent.parent)
            if site not in sites:
                sites.append(site)
    return PythonRuntime(libpython, sys.base_prefix, os.pathsep.join(sites), sys.version_info.minor)


def compiler() -> str:
    """The C compiler to build the loader with: $CC or cc on PATH (LoaderError if there is none)."""
    cc = os.environ.get("CC", "cc")
    found = shutil.which(cc)
    if found is None:
        raise LoaderError(f"no C compiler {cc!r} on PATH: pantohil build compiles each FMU's loader library "
                          "with it (install gcc or set CC)")
    return found


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def compile_loader(model_identifier: str, time_step_vr: int, runtime: PythonRuntime, out: Path) -> Path:
    """Compile the loader for one FMU into `out` (the FMU's binaries/linux64/<modelIdentifier>.so)."""
    defines = {"PANTOHIL_LIBPYTHON": _c_string(runtime.libpython), "PANTOHIL_PYTHONHOME": _c_string(runtime.home),
               "PANTOHIL_PYTHONPATH": _c_string(runtime.path), "PANTOHIL_PY_MINOR": _c_string(str(runtime.minor)),
               "PANTOHIL_INNER": _c_string(f"{model_identifier}{INNER_SUFFIX}.so"),
               "PANTOHIL_TIME_STEP_VR": str(int(time_step_vr))}
    with tempfile.TemporaryDirectory(prefix="pantohil_loader_") as tmp:
        target = Path(tmp) / f"{model_identifier}.so"
        cmd = [compiler(), "-shared", "-fPIC", "-O2", "-std=c99", "-Wall", f"-I{FMI_HEADERS}",
               *(f"-D{k}={v}" for k, v in defines.items()), "-o", str(target), str(SOURCE), "-ldl", "-lm"]
        # a session of its own: a Ctrl-C to the run's process group does not kill the build under the run
        proc = subprocess.run(cmd, capture_output=True, text=True, start_new_session=True)
        if proc.returncode != 0:
            first = (proc.stderr.strip().splitlines() or ["(no message)"])[0]
            raise LoaderError(f"compiling the FMU loader failed: {first}")
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(target, out)
    return out
