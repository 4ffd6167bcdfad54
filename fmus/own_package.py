"""An FMU's slave module bound to the FMU's own copy of pantohil, whatever pantohil the process has loaded.

pythonfmu imports an FMU's script (fmus/pantohil_<name>.py) as a top-level module from the FMU's
resources/, where the builder put the FMU's copy of the package (resources/pantohil) and this file. The
process may already hold a `pantohil` in sys.modules: the host's own, another FMU's copy (whose folder the
host may have deleted since) or one of another version. The script therefore imports pantohil inside
`own_package(globals())`, which
- sets aside every `pantohil` and `pantohil.*` entry of sys.modules,
- imports from the FMU's resources/pantohil only (its `pantohil` has that folder as its path, whatever
  sys.path holds),
- keeps the modules so loaded in a table of the slave module's own (`__pantohil_modules__`),
- puts back what was there before, so that the host's pantohil and other FMUs' are untouched.
The FMU's objects reach its modules through the names bound at import, and nothing in an FMU imports a
pantohil module after that (a function-level import would find somebody else's): fmus/state_codec.py
looks classes up in its own package.

pythonfmu runs the script a second time in the module's namespace (its findClass): the binding then takes
the modules it kept the first time, drops the slave module from sys.modules, so that an FMU of the same name
built by another version imports its own script, and takes the FMU's resources/ out of sys.path, where
pythonfmu put it to import the script, so that no later import of the process finds the FMU's files. Each
instance of an FMU so has modules of its own (pythonfmu imports the script anew for it).

In the package itself (the in-process engine imports pantohil.fmus.pantohil_<name>; pythonfmu's builder
imports the script from fmus/) the binding does nothing: the script's imports are the package's. The builder
then runs the script once more from a folder laid out as resources/, which binds it (once: the builder
cleans sys.path up itself).

The script loads this file by its path, not by import, so that it is the FMU's own version too.
"""
from __future__ import annotations

import contextlib
import importlib.machinery
import importlib.util
import os
import sys
from pathlib import Path

PACKAGE = "pantohil"
MODULES = "__pantohil_modules__"  # the slave module's own pantohil modules, by name


def own_package(namespace: dict) -> contextlib.AbstractContextManager:
    """A context in which `import pantohil...` gives the FMU's own copy of the package; `namespace`: the
    script's globals(). Nothing is done for a script that is a module of the package or has no copy beside it."""
    root = Path(namespace["__file__"]).parent / PACKAGE
    if namespace.get("__package__") or not root.is_dir():
        return contextlib.nullcontext()
    return _bound(namespace, root)


@contextlib.contextmanager
def _bound(namespace: dict, root: Path):
    own = namespace.setdefault(MODULES, {})
    again = bool(own)  # pythonfmu's second run of the script
    held = _take_package()
    sys.modules.update(own or {PACKAGE: _package_at(root)})
    try:
        yield
    finally:
        own.update(_take_package())
        sys.modules.update(held)
    if again:
        _drop_module(namespace)
        _leave_sys_path(root.parent)


def _take_package() -> dict:
    """Every pantohil module of sys.modules, by name, taken out of it."""
    names = [name for name in sys.modules if name == PACKAGE or name.startswith(PACKAGE + ".")]
    return {name: sys.modules.pop(name) for name in names}


def _package_at(root: Path):
    """A `pantohil` package whose only folder is `root`: its modules are found there and nowhere else (a
    search of sys.path could find another pantohil first)."""
    spec = importlib.machinery.ModuleSpec(PACKAGE, None, is_package=True)
    spec.submodule_search_locations = [str(root)]
    return importlib.util.module_from_spec(spec)


def _leave_sys_path(folder: Path) -> None:
    """Remove the entry for `folder` that pythonfmu put in sys.path, so that no later import of the process
    finds the FMU's files."""
    for i, entry in enumerate(sys.path):
        if entry and os.path.normpath(entry) == os.path.normpath(folder):
            del sys.path[i]
            return


def _drop_module(namespace: dict) -> None:
    """Take the slave module out of sys.modules (pythonfmu holds it and its class already)."""
    name = namespace.get("__name__")
    module = sys.modules.get(name)
    if module is not None and getattr(module, "__dict__", None) is namespace:
        del sys.modules[name]
