"""Build, cache and locate the PFEM operators of a case (Paper C sec. 3, Paper D sec. 3).

The cache key hashes everything the operators depend on: the catenary file, the model sources that
compute them, the discretisation settings and the file format. A build in progress writes to a
temporary name, so an interrupted build leaves no entry behind.
"""
from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from pantohil.models.progress import progress as progress_bar

from pantohil.models.catenary.fe import definition as catenary_definition
from pantohil.models.catenary.fe import model as fe_model
from pantohil.models.catenary.pfem import blocks as pfem_blocks
from pantohil.models.catenary.pfem import frf as pfem_frf
from pantohil.models.catenary.pfem import lag_transform as pfem_lag_transform
from pantohil.models.catenary.pfem import operator_data, operator_file
from pantohil.models.catenary.pfem import operators as pfem_operators
from pantohil.models.catenary.fe.definition import load_definition
from pantohil.models.catenary.pfem.operator_file import FORMAT_VERSION, load_operators, save_operators
from pantohil.models.catenary.pfem.blocks import periodic_block
from pantohil.models.catenary.pfem.operators import build_operators
from pantohil.models.storage import cache_root

Case = Any  # a validated case (models/case.py), which imports the catenary models


SOURCES = (pfem_frf, pfem_lag_transform, pfem_blocks, pfem_operators, operator_data, fe_model, catenary_definition,
           operator_file)


@dataclass
class OperatorBuild:
    """Where a case's PFEM operators are, whether they came from the cache, and their cost and size."""
    path: Path
    cached: bool
    build_s: float
    n_frequencies: int
    bytes: int
    key: str

    def summary(self) -> dict:
        """The operators' part of summary.json: build time, cached, frequencies, bytes, file, key."""
        return {"build_s": self.build_s, "cached": self.cached, "n_frequencies": self.n_frequencies,
                "bytes": self.bytes, "file": str(self.path), "key": self.key}


def operator_key(case: Case) -> str:
    """Cache key of a case's operators: a hash of the catenary file, the model sources and the settings."""
    h = hashlib.sha256(f"pantohil operators v{FORMAT_VERSION} numerics {pfem_operators.NUMERICS_VERSION}".encode())
    h.update(Path(case.definition_path).read_bytes())
    for module in SOURCES:
        h.update(Path(module.__file__).read_bytes())
    h.update(json.dumps(asdict(case.pfem_settings()), sort_keys=True).encode())
    return h.hexdigest()[:24]


def case_operators(case: Case, progress: bool = True) -> OperatorBuild:
    """The operators of a PFEM case, from the cache or built now (and cached)."""
    key = operator_key(case)
    path = cache_root() / "operators" / f"{key}.npz"
    t0 = time.perf_counter()
    if path.exists():
        ops = load_operators(path, key)  # refuses a corrupt or mismatched entry with one line
        return OperatorBuild(path, True, time.perf_counter() - t0, int(ops.info.get("n_frequencies", 0)),
                             path.stat().st_size, key)
    cb = periodic_block(load_definition(case.definition_path), case.samples_per_span)
    with progress_bar(1, "PFEM operators", "freq", progress) as bar:
        def tick(done, total):
            bar.total = total
            bar.n = done
            bar.refresh()

        ops = build_operators(cb, case.pfem_settings(), progress=tick)
    size = save_operators(ops, path, key)
    return OperatorBuild(path, False, time.perf_counter() - t0, ops.info["n_frequencies"], size, key)


def case_cross_operators(case: Case, offset_m: float, progress: bool = True) -> Path:
    """The cross operators of a two-pantograph PFEM case, the second point `offset_m` from the first
    (offset_operator.py), from the cache or built now (and cached): the path of their file."""
    import os

    from pantohil.models.catenary.pfem import offset_operator as pfem_offset
    from pantohil.models.catenary.pfem.pair_operators import save_cross_operators

    h = hashlib.sha256(operator_key(case).encode())
    h.update(Path(pfem_offset.__file__).read_bytes())
    h.update(repr(round(float(offset_m), 9)).encode())
    path = cache_root() / "operators" / f"{h.hexdigest()[:24]}-pair.npz"
    if path.exists():
        return path
    settings = case.pfem_settings()
    shift = pfem_offset.sample_shift(settings, offset_m)
    cb = periodic_block(load_definition(case.definition_path), case.samples_per_span)
    with progress_bar(1, "PFEM pair operators", "pair", progress) as bar:
        i12, i21 = pfem_offset.pair_cross_operators(cb, settings, offset_m)
        bar.update(1)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.stem}.{os.getpid()}.npz")
    save_cross_operators(partial, i12, i21, offset_m, shift)
    os.replace(partial, path)
    return path
