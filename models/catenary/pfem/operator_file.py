"""PFEM operator files: one .npz with a format version, the hash of everything the operators depend on,
and the arrays (float32 / complex64 where the precision allows: relative 6e-8, far below the method's
own discretisation error). Written atomically; any corrupt, truncated or mismatched file is refused
with one line."""
from __future__ import annotations

import json
import math
import os
import zipfile
from dataclasses import asdict
from pathlib import Path

import numpy as np

from pantohil.models.catenary.pfem.operator_data import PfemOperators, PfemSettings
from pantohil.models.errors import InputError
from pantohil.models.input_files import InputFileError, open_regular
from pantohil.models.storage import atomic_path, cache_folder

FORMAT_VERSION = 1
MAX_META_BYTES = 1 << 20  # the meta record: settings and build info, a few kB
_ARRAYS = {"cc": np.float32, "dc": np.complex64, "cd": np.float32, "dd": np.complex64, "z0": np.float64,
           "window_start": np.int64, "dropper_tension_N": np.float64, "dropper_stiffness_N_m": np.float64,
           "dropper_x_m": np.float64}


class OperatorFileError(InputError):
    """An operator file that cannot be used; the message is one line."""


def save_operators(ops: PfemOperators, path: Path, key: str) -> int:
    """Write the operators to `path` atomically (a partial file never carries the final name). Returns bytes."""
    path = Path(path)
    cache_folder(path.parent)
    meta = {"format_version": FORMAT_VERSION, "key": key, "settings": asdict(ops.settings), "info": ops.info}
    with atomic_path(path) as part, open(part, "wb") as fh:
        np.savez(fh, meta=np.array(json.dumps(meta)),
                 **{name: np.asarray(getattr(ops, name)).astype(t) for name, t in _ARRAYS.items()})
    return path.stat().st_size


def _npy_header(zf: zipfile.ZipFile, name: str) -> tuple[tuple, np.dtype]:
    """Shape and dtype of a stored .npy member, checked to describe exactly the bytes the member holds (so a
    header claiming a huge shape is refused before anything is allocated)."""
    info = zf.getinfo(f"{name}.npy")
    if info.compress_type != zipfile.ZIP_STORED or info.file_size != info.compress_size:
        raise ValueError(f"{name} is compressed (pantohil writes its arrays stored)")
    with zf.open(info) as fh:
        version = np.lib.format.read_magic(fh)
        read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, _fortran, dtype = read(fh)
        header = fh.tell()
    if dtype.hasobject or header + math.prod(shape) * dtype.itemsize != info.file_size:
        raise ValueError(f"{name}: its header ({shape}, {dtype}) does not match its {info.file_size} bytes")
    return shape, dtype


def _read_member(zf: zipfile.ZipFile, name: str) -> np.ndarray:
    with zf.open(f"{name}.npy") as fh:
        return np.lib.format.read_array(fh, allow_pickle=False)


def _read_meta(zf: zipfile.ZipFile, path: Path) -> dict:
    """The meta record (JSON) and the headers of every array, checked before any array is read."""
    missing = sorted({"meta", *_ARRAYS} - {n.removesuffix(".npy") for n in zf.namelist()})
    if missing:
        raise OperatorFileError(f"operator file {path}: missing {', '.join(missing)} (not a pantohil operator file?)")
    shape, dtype = _npy_header(zf, "meta")
    if shape != () or dtype.kind != "U" or dtype.itemsize > MAX_META_BYTES:
        raise ValueError("meta is not a short text")
    meta = json.loads(str(_read_member(zf, "meta")))
    if not isinstance(meta, dict):
        raise ValueError("meta is not a JSON object")
    return meta


def _settings(meta: dict, path: Path, key: str | None) -> PfemSettings:
    if meta.get("format_version") != FORMAT_VERSION:
        raise OperatorFileError(f"operator file {path}: format version {meta.get('format_version')!r}, this pantohil "
                                f"reads {FORMAT_VERSION}: rebuild it with `pantohil build`")
    if key is not None and meta.get("key") != key:
        raise OperatorFileError(f"operator file {path}: built for other inputs (hash {str(meta.get('key'))[:12]}, "
                                f"expected {key[:12]}): rebuild it with `pantohil build`")
    try:
        return PfemSettings(**meta["settings"])
    except (TypeError, KeyError):
        raise OperatorFileError(f"operator file {path}: unreadable settings {meta.get('settings')!r}") from None


def _check_shapes(zf: zipfile.ZipFile, settings: PfemSettings, path: Path) -> None:
    """Every array's header against the shape the settings give, before any array is read."""
    headers = {name: _npy_header(zf, name)[0] for name in _ARRAYS}
    if len(headers["dropper_x_m"]) != 1:
        raise OperatorFileError(f"operator file {path}: dropper_x_m has shape {headers['dropper_x_m']}")
    n, nd, jd = settings.samples_per_span, headers["dropper_x_m"][0], settings.n_harmonics_dropper
    shapes = {"cc": (n, n), "dc": (n, nd, jd), "cd": (n, nd, n), "dd": (nd, n, nd, jd), "z0": (n,),
              "window_start": (nd,), "dropper_tension_N": (nd,), "dropper_stiffness_N_m": (nd,)}
    for name, shape in shapes.items():
        if headers[name] != shape:
            raise OperatorFileError(f"operator file {path}: {name} has shape {headers[name]}, expected {shape} "
                                    f"for N = {n}, {nd} droppers, N_hd = {jd}")


def _read_checked(path: Path, key: str | None) -> tuple[dict, PfemSettings, dict]:
    """meta, settings and arrays of an operator file whose headers and shapes were checked first."""
    fd = open_regular(path, "operator file")  # not a FIFO or a device
    with os.fdopen(fd, "rb") as fh, zipfile.ZipFile(fh) as zf:
        meta = _read_meta(zf, path)
        settings = _settings(meta, path, key)
        _check_shapes(zf, settings, path)
        return meta, settings, {name: _read_member(zf, name) for name in _ARRAYS}


def load_operators(path: Path, key: str | None = None) -> PfemOperators:
    """Read an operator file; with `key`, also require that it was built from the same inputs."""
    path = Path(path)
    try:
        meta, settings, arrays = _read_checked(path, key)
    except OperatorFileError:
        raise
    except InputFileError as exc:
        raise OperatorFileError(str(exc)) from None
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError) as exc:
        detail = " ".join(str(exc).split())[:160]
        raise OperatorFileError(f"operator file {path} is corrupt or truncated ({type(exc).__name__}"
                                f"{': ' + detail if detail else ''})") from None
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
        {**(meta.get("info") if isinstance(meta.get("info"), dict) else {}), "key": meta.get("key")},
    )
