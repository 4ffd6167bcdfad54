"""PFEM operator files: one .npz with a format version, the hash of everything the operators depend on,
and the arrays (float32 / complex64 where the precision allows: relative 6e-8, far below the method's
own discretisation error). Written atomically; any corrupt, truncated or mismatched file is refused
with one line."""
from __future__ import annotations

import json
import zipfile
from dataclasses import asdict
from pathlib import Path

import numpy as np

from pantohil.models.catenary.pfem.operators import PfemOperators, PfemSettings
from pantohil.models.storage import atomic_path

FORMAT_VERSION = 1
_ARRAYS = {"cc": np.float32, "dc": np.complex64, "cd": np.float32, "dd": np.complex64, "z0": np.float64,
           "window_start": np.int64, "dropper_tension_N": np.float64, "dropper_stiffness_N_m": np.float64,
           "dropper_x_m": np.float64}


class OperatorFileError(ValueError):
    """An operator file that cannot be used; the message is one line."""


def save_operators(ops: PfemOperators, path: Path, key: str) -> int:
    """Write the operators to `path` atomically (a partial file never carries the final name). Returns bytes."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {"format_version": FORMAT_VERSION, "key": key, "settings": asdict(ops.settings), "info": ops.info}
    with atomic_path(path) as part, open(part, "wb") as fh:
        np.savez(fh, meta=np.array(json.dumps(meta)),
                 **{name: np.asarray(getattr(ops, name)).astype(t) for name, t in _ARRAYS.items()})
    return path.stat().st_size


def load_operators(path: Path, key: str | None = None) -> PfemOperators:
    """Read an operator file; with `key`, also require that it was built from the same inputs."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            names = set(z.files)
            missing = sorted({"meta", *_ARRAYS} - names)
            if missing:
                raise OperatorFileError(
                    f"operator file {path}: missing {', '.join(missing)} (not a pantohil operator file?)"
                )
            meta = json.loads(str(z["meta"]))
            arrays = {name: z[name] for name in _ARRAYS}
    except OperatorFileError:
        raise
    except FileNotFoundError:
        raise OperatorFileError(f"operator file {path} does not exist") from None
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError, json.JSONDecodeError) as exc:
        raise OperatorFileError(f"operator file {path} is corrupt or truncated ({type(exc).__name__})") from None
    if meta.get("format_version") != FORMAT_VERSION:
        raise OperatorFileError(f"operator file {path}: format version {meta.get('format_version')!r}, this pantohil "
                                f"reads {FORMAT_VERSION}: rebuild it with `pantohil build`")
    if key is not None and meta.get("key") != key:
        raise OperatorFileError(f"operator file {path}: built for other inputs (hash {str(meta.get('key'))[:12]}, "
                                f"expected {key[:12]}): rebuild it with `pantohil build`")
    try:
        settings = PfemSettings(**meta["settings"])
    except TypeError:
        raise OperatorFileError(f"operator file {path}: unreadable settings {meta.get('settings')!r}") from None
    n, nd, jd = settings.samples_per_span, len(arrays["dropper_x_m"]), settings.n_harmonics_dropper
    shapes = {"cc": (n, n), "dc": (n, nd, jd), "cd": (n, nd, n), "dd": (nd, n, nd, jd), "z0": (n,),
              "window_start": (nd,), "dropper_tension_N": (nd,), "dropper_stiffness_N_m": (nd,)}
    for name, shape in shapes.items():
        if arrays[name].shape != shape:
            raise OperatorFileError(f"operator file {path}: {name} has shape {arrays[name].shape}, expected {shape} "
                                    f"for N = {n}, {nd} droppers, N_hd = {jd}")
    if not all(np.all(np.isfinite(arrays[k])) for k in ("cc", "dc", "cd", "dd", "z0")):
        raise OperatorFileError(f"operator file {path}: non-finite values")
    return PfemOperators(
        settings,
        np.ascontiguousarray(arrays["cc"], dtype=float),
        arrays["dc"].astype(complex),
        np.ascontiguousarray(arrays["cd"], dtype=float),
        arrays["dd"].astype(complex),
        arrays["z0"],
        arrays["window_start"].astype(int),
        arrays["dropper_tension_N"],
        arrays["dropper_stiffness_N_m"],
        arrays["dropper_x_m"],
        {**meta.get("info", {}), "key": meta["key"]},
    )
