"""Checkpoints of a run: after every span the fmpy master saves each FMU's serialized state
(fmi2SerializeFMUstate), its own step count and last outputs, the convergence history and the records
of that span into RUN_FOLDER/state/, so that `pantohil run --resume RUN_FOLDER` continues an
interrupted test from the last saved span.

state/checkpoint.npz holds the arrays; state/checkpoint.json says which span it holds and what the
run was (case file, overrides, the FMUs' digests). Both are replaced atomically: an interruption
while saving leaves the previous checkpoint whole.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from pantohil.models.case import CaseError

STATE_DIR = "state"
ARRAYS = "checkpoint.npz"
META = "checkpoint.json"
FORMAT = 1


def fmu_digests(fmus: dict[str, Path]) -> dict[str, str]:
    """SHA-256 of each FMU file, so that a resumed run uses the same FMUs."""
    return {name: hashlib.sha256(Path(p).read_bytes()).hexdigest() for name, p in fmus.items()}


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
    """The checkpoint of a run folder: meta (dict) and arrays (dict of arrays). One-line errors."""
    folder = Path(run_folder) / STATE_DIR
    if not Path(run_folder).is_dir():
        raise CaseError(f"--resume: {run_folder} is not a run folder")
    if not (folder / META).is_file() or not (folder / ARRAYS).is_file():
        raise CaseError(f"--resume: {run_folder} has no checkpoint ({STATE_DIR}/{META}): the run saved no span")
    try:
        meta = json.loads((folder / META).read_text())
        with np.load(folder / ARRAYS) as z:
            arrays = {k: z[k] for k in z.files}
    except (ValueError, OSError, KeyError) as exc:
        raise CaseError(f"--resume: {folder / ARRAYS} is unreadable ({exc})") from None
    if meta.get("format") != FORMAT:
        raise CaseError(f"--resume: {folder / META} has format {meta.get('format')}, this pantohil reads {FORMAT}")
    return {"meta": meta, "arrays": arrays}


def restore(checkpoint: dict, master, monitor, fmus: dict[str, Path]) -> int:
    """Put a checkpoint back into a new master and monitor; the span to run next."""
    meta, arrays = checkpoint["meta"], checkpoint["arrays"]
    if fmu_digests(fmus) != meta["fmu_digests"]:
        raise CaseError("--resume: the FMUs built now differ from the interrupted run's (the case file or "
                        "pantohil changed since); start a new run")
    master.deserialize_states({name: arrays[f"fmu_state/{name}"].tobytes() for name in master.names})
    span, k = meta["span"], meta["k"]
    start = span * monitor.n
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
