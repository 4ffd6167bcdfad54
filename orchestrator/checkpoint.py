"""Checkpoints of a run: after every span the fmpy master saves each FMU's serialized state
(fmi2SerializeFMUstate), its own step count and last outputs, the convergence history and the records
of that span into RUN_FOLDER/state/, so that `pantohil run --resume RUN_FOLDER` continues an
interrupted test from the last saved span.

state/checkpoint.npz holds the arrays (numbers only: it is read without pickle, and each FMU state
is state data, fmus/state_codec.py, that cannot run code); state/checkpoint.json says which span it
holds and what the run was (case file, overrides, the FMUs' identities: digests of what the FMUs
contain, not of their zip bytes). Both are replaced atomically: an interruption while saving leaves
the previous checkpoint whole. A checkpoint is read as hostile input: every entry is checked before
anything is written, and a damaged one is one line naming it.
"""
from __future__ import annotations

import hashlib
import json
import os
import zipfile
import zlib
from pathlib import Path

import numpy as np

from pantohil.fmus import state_codec
from pantohil.models.case import CaseError
from pantohil.models.input_files import InputFileError, load_json, read_input_bytes

STATE_DIR = "state"
ARRAYS = "checkpoint.npz"
META = "checkpoint.json"
FORMAT = 2
MAX_META_BYTES = 64 << 20
MAX_ARRAYS_BYTES = 4 << 30
RESUMABLE = ("interrupted",)  # a summary.json with another status is a finished run: nothing to resume


def fmu_identity(path: Path) -> str:
    """SHA-256 of what an FMU contains: each member's name and bytes, in name order (not the zip's own
    bytes, which hold times and layout)."""
    h = hashlib.sha256()
    with zipfile.ZipFile(path) as z:
        for name in sorted(z.namelist()):
            h.update(name.encode() + b"\0" + hashlib.sha256(z.read(name)).digest())
    return h.hexdigest()


def fmu_digests(fmus: dict[str, Path]) -> dict[str, str]:
    """The identity of each FMU (fmu_identity), so that a resumed run uses FMUs with the same contents."""
    return {name: fmu_identity(Path(p)) for name, p in fmus.items()}


def save(out_dir: Path, master, monitor, span: int, run_info: dict) -> None:
    """Save the state after `span` (0-based) closed: master.k is its last step + 1."""
    folder = Path(out_dir) / STATE_DIR
    folder.mkdir(exist_ok=True)
    start, stop = span * monitor.n, master.k
    states = master.serialize_states()
    arrays = {f"fmu_state/{name}": np.frombuffer(data, dtype=np.uint8) for name, data in states.items()}
    for name in master.names:
        arrays[f"values/{name}"] = np.asarray(master.values[name], dtype=float)
        arrays[f"record/{name}"] = master.record[name][master.rows(start, stop)]
        arrays[f"step_ns/{name}"] = master.step_ns[name][master.rows(start, stop)]
        if name in master.record_int:
            arrays[f"record_int/{name}"] = master.record_int[name][master.rows(start, stop)]
        if name in master.record_in:
            arrays[f"record_in/{name}"] = master.record_in[name][master.rows(start, stop)]
    if len(monitor._prev):  # the spans the next change is measured against, oldest first
        arrays["monitor/previous_force"] = np.stack(monitor._prev)
    part = folder / (ARRAYS + ".part")
    with open(part, "wb") as f:
        np.savez(f, **arrays)
    os.replace(part, folder / ARRAYS)
    meta = {"format": FORMAT, "span": span, "k": int(master.k), "history": monitor.history, **run_info}
    part = folder / (META + ".part")
    part.write_text(json.dumps(meta, indent=1, allow_nan=True))
    os.replace(part, folder / META)


def load(run_folder: Path) -> dict:
    """The checkpoint of an interrupted run folder: meta (dict) and arrays (dict of arrays). A finished run,
    a missing, damaged or foreign checkpoint: CaseError with one line."""
    run_folder = Path(run_folder)
    folder = run_folder / STATE_DIR
    if not run_folder.is_dir():
        raise CaseError(f"--resume: {run_folder} is not a run folder")
    _check_not_finished(run_folder)
    if not (folder / META).is_file() or not (folder / ARRAYS).is_file():
        raise CaseError(f"--resume: {run_folder} has no checkpoint ({STATE_DIR}/{META}): the run saved no span")
    meta = _read_meta(folder / META)
    arrays = _read_arrays(folder / ARRAYS)
    for key, data in arrays.items():
        if key.startswith("fmu_state/"):
            try:
                state_codec.decode(data.tobytes(), _AnyConstant())
            except state_codec.StateDataError as exc:
                raise CaseError(f"--resume: {folder / ARRAYS}: {key} is damaged ({exc})") from None
    return {"meta": meta, "arrays": arrays}


class _AnyConstant(dict):
    """Constants for checking a state's data before an FMU exists: every name stands for None."""

    def __contains__(self, name) -> bool:
        return True

    def __getitem__(self, name):
        return None


def _check_not_finished(run_folder: Path) -> None:
    path = run_folder / "summary.json"
    if not path.is_file():
        return  # a run that was killed wrote none
    try:
        status = load_json(path, "--resume: run summary", MAX_META_BYTES).get("status")
    except InputFileError as exc:
        raise CaseError(str(exc)) from None
    if status not in RESUMABLE:
        raise CaseError(f"--resume: {run_folder} holds a finished run (status {status!r}); only an interrupted "
                        "run can be resumed")


def _bounded_bytes(path: Path, limit: int) -> bytes:
    """A regular file's bytes, at most `limit` (a FIFO or a device is refused, never waited on)."""
    try:
        return read_input_bytes(path, "--resume: checkpoint file", limit)
    except InputFileError as exc:
        raise CaseError(str(exc)) from None


_META_TYPES = {"format": int, "span": int, "k": int, "history": list, "fmu_digests": dict, "case_file": str,
               "overrides": list}


def _read_meta(path: Path) -> dict:
    try:
        meta = json.loads(_bounded_bytes(path, MAX_META_BYTES))
    except (ValueError, RecursionError) as exc:
        raise CaseError(f"--resume: {path} is damaged ({type(exc).__name__})") from None
    if not isinstance(meta, dict):
        raise CaseError(f"--resume: {path} is damaged (not a JSON table)")
    if meta.get("format") != FORMAT:
        raise CaseError(f"--resume: {path} has format {meta.get('format')!r}, this pantohil reads {FORMAT}")
    for key, kind in _META_TYPES.items():
        if not isinstance(meta.get(key), kind) or isinstance(meta.get(key), bool):
            raise CaseError(f"--resume: {path} is damaged ({key} is missing or not a {kind.__name__})")
    if meta["span"] < 0 or meta["k"] < 0 or not all(isinstance(h, dict) for h in meta["history"]) \
            or not all(isinstance(o, str) for o in meta["overrides"]):
        raise CaseError(f"--resume: {path} is damaged (span, step count, history or overrides)")
    return meta


def _read_arrays(path: Path) -> dict:
    if path.stat().st_size > MAX_ARRAYS_BYTES or not path.is_file():
        raise CaseError(f"--resume: {path} is not a regular file of at most {MAX_ARRAYS_BYTES} bytes")
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (ValueError, OSError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        raise CaseError(f"--resume: {path} is damaged ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})") \
            from None


def check_fmus(checkpoint: dict, fmus: dict[str, Path]) -> None:
    """The FMUs built now contain what the interrupted run's did; CaseError otherwise."""
    if fmu_digests(fmus) != checkpoint["meta"]["fmu_digests"]:
        raise CaseError("--resume: the FMUs built now differ from the interrupted run's (the case file or "
                        "pantohil changed since); start a new run")


def restore(checkpoint: dict, master, monitor) -> int:
    """Put a checkpoint back into a new master and monitor; the span to run next. A checkpoint that does
    not fit this run's master: CaseError with one line."""
    from fmpy.fmi1 import FMICallException

    try:
        return _restore(checkpoint, master, monitor)
    except (KeyError, ValueError, IndexError, TypeError, FMICallException) as exc:
        raise CaseError(f"--resume: the checkpoint does not fit this run ({type(exc).__name__}: "
                        f"{' '.join(str(exc).split())[:160]})") from None


def _restore(checkpoint: dict, master, monitor) -> int:
    meta, arrays = checkpoint["meta"], checkpoint["arrays"]
    span, k = meta["span"], meta["k"]
    start = span * monitor.n
    if k != start + monitor.n:
        raise ValueError(f"step count {k} is not the end of span {span}")
    master.deserialize_states({name: arrays[f"fmu_state/{name}"].tobytes() for name in master.names})
    master.k = k
    master.record_start = start
    for name in master.names:
        master.values[name] = [float(v) for v in arrays[f"values/{name}"]]
        master.record[name][master.rows(start, k)] = arrays[f"record/{name}"]
        master.step_ns[name][master.rows(start, k)] = arrays[f"step_ns/{name}"]
        if name in master.record_int:
            master.record_int[name][master.rows(start, k)] = arrays[f"record_int/{name}"]
        if name in master.record_in:
            master.record_in[name][master.rows(start, k)] = arrays[f"record_in/{name}"]
    monitor.history = [dict(h) for h in meta["history"]]
    previous = arrays.get("monitor/previous_force")
    monitor._prev = [] if previous is None else [row.copy() for row in np.atleast_2d(previous)]
    return span + 1
