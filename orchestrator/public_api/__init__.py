"""pantohil: hardware-in-the-loop testing of railway pantographs against a virtual periodic catenary,
built from FMI 2.0 co-simulation units (Gil et al., Papers A-D).

The public API::

    import pantohil

    case = pantohil.load_case("my_case.toml", ["hil.update=span"])   # a pantohil.Case
    result = pantohil.run_case(case, "runs/my_case")                  # the run folder's summary
    # a bad case raises pantohil.CaseError, one line naming the key

The names are imported when first used, so `import pantohil` stays cheap.
"""
from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("pantohil")
except PackageNotFoundError:  # run from a source tree that was never installed
    __version__ = "0+unknown"

_EXPORTS = {
    "Case": "pantohil.models.case",
    "CaseError": "pantohil.models.case",
    "load_case": "pantohil.models.case",
    "run_case": "pantohil.orchestrator.hil_run",
}

__all__ = ["Case", "CaseError", "__version__", "load_case", "run_case"]


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'pantohil' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
