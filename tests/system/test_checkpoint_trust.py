"""`pantohil run --resume` of a received or damaged run folder: nothing in it is executed (a pickle
payload in a checkpoint, a crafted state naming a function), a damaged checkpoint or a finished run is
one line with exit 2 and the folder is left as it was, and an interrupted run resumes after the FMU
cache was emptied (the FMUs are identified by what they contain, and builds are reproducible)."""
from __future__ import annotations

import hashlib
import io
import json
import os
import pickle
import signal
import subprocess
import sys
import time
import zipfile

import numpy as np
import pytest

from conftest import default_sigint, pantohil, run_main

STATE = "state"


def _folder_digest(folder) -> dict:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _interrupted(tmp_path, env=None):
    """A run of the default case stopped by SIGINT after its second span was saved."""
    out = tmp_path / "interrupted"
    proc = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--out", str(out), "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint,
                            env=env)
    meta = out / STATE / "checkpoint.json"
    while True:
        try:
            if json.loads(meta.read_text())["span"] >= 1:
                break
        except (FileNotFoundError, ValueError):
            pass
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=600)
    assert json.loads((out / "summary.json").read_text())["status"] == "interrupted"
    return out


@pytest.fixture(scope="module")
def interrupted(tmp_path_factory):
    return _interrupted(tmp_path_factory.mktemp("resume"))


class _Payload:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _with_state(folder, name: str, data: bytes) -> None:
    path = folder / STATE / "checkpoint.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays[f"fmu_state/{name}"] = np.frombuffer(data, dtype=np.uint8)
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


def _copy(src, dst):
    import shutil

    shutil.copytree(src, dst)
    return dst


def _refused(folder, *words):
    before = _folder_digest(folder)
    proc = pantohil("run", "--resume", str(folder))
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert all(w in lines[0] for w in words), lines[0]
    assert _folder_digest(folder) == before  # nothing written, nothing replaced
    return lines[0]


@pytest.mark.slow
@pytest.mark.parametrize("header", [b"pantohil-fmu-state 1\n", b"pantohil-fmu-state 2\n"])
def test_a_pickle_payload_in_a_checkpoint_runs_nothing(interrupted, tmp_path, header):
    folder = _copy(interrupted, tmp_path / "crafted")
    marker = tmp_path / "PWNED"
    _with_state(folder, "catenary", header + pickle.dumps(_Payload(marker)))
    _refused(folder, "fmu_state/catenary")
    assert not marker.exists()


@pytest.mark.slow
def test_a_state_naming_a_function_or_a_foreign_class_runs_nothing(interrupted, tmp_path):
    for i, path in enumerate(("os:system", "pantohil.models.hil.loop:np.save", "subprocess:Popen",
                              "pantohil.models.hil.loop:PeriodicHil.__init__")):
        folder = _copy(interrupted, tmp_path / f"crafted{i}")
        tree = {"$id": 0, "$d": [["owner", "PantohilCatenary"], ["items", {"$id": 1, "$o": path, "a": {}}]]}
        _with_state(folder, "catenary", b"pantohil-fmu-state 2\n" + json.dumps(tree).encode())
        _refused(folder, "fmu_state/catenary", "not a loaded pantohil class")


@pytest.mark.slow
def test_an_object_array_in_a_checkpoint_is_refused(interrupted, tmp_path):
    folder = _copy(interrupted, tmp_path / "objects")
    path = folder / STATE / "checkpoint.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["values/catenary"] = np.array([_Payload(tmp_path / "PWNED")], dtype=object)
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    _refused(folder, "damaged")
    assert not (tmp_path / "PWNED").exists()


def _truncate(folder):
    path = folder / STATE / "checkpoint.npz"
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _flip(folder):
    path = folder / STATE / "checkpoint.npz"
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(io.BytesIO(bytes(data))) as z:  # a bit in the middle of the catenary's state
        info = z.getinfo("fmu_state/catenary.npy")
    data[info.header_offset + 200] ^= 0x10
    path.write_bytes(bytes(data))


def _meta(edit):
    def change(folder):
        path = folder / STATE / "checkpoint.json"
        meta = json.loads(path.read_text())
        path.write_text(json.dumps(edit(meta)))
    return change


DAMAGES = {
    "truncated arrays": (_truncate, "damaged"),
    "a bit flipped": (_flip, "damaged"),
    "meta a list": (_meta(lambda m: [m]), "not a JSON table"),
    "meta without history": (_meta(lambda m: {k: v for k, v in m.items() if k != "history"}), "history"),
    "span a string": (_meta(lambda m: {**m, "span": "3"}), "span"),
    "old format": (_meta(lambda m: {**m, "format": 1}), "format"),
    "span beyond the arrays": (_meta(lambda m: {**m, "span": m["span"] + 5}), "does not fit"),
    "a state of another FMU": (lambda f: _swap_states(f), "does not fit"),
}


def _swap_states(folder):
    path = folder / STATE / "checkpoint.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["fmu_state/catenary"] = arrays["fmu_state/rig"]
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


@pytest.mark.slow
@pytest.mark.parametrize("damage", sorted(DAMAGES))
def test_a_damaged_checkpoint_is_one_line_and_nothing_written(interrupted, tmp_path, damage):
    folder = _copy(interrupted, tmp_path / "damaged")
    edit, words = DAMAGES[damage]
    edit(folder)
    _refused(folder, words)


@pytest.mark.slow
def test_a_finished_run_is_not_resumed(interrupted, tmp_path):
    folder = _copy(interrupted, tmp_path / "finished")
    summary = json.loads((folder / "summary.json").read_text())
    (folder / "summary.json").write_text(json.dumps({**summary, "status": "converged"}))
    _refused(folder, "finished run", "converged")


@pytest.mark.slow
def test_a_run_resumes_after_the_fmu_cache_was_emptied(tmp_path):
    env = {**os.environ, "PANTOHIL_CACHE": str(tmp_path / "cache-first")}
    folder = _interrupted(tmp_path, env)
    proc = subprocess.run([sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--resume", str(folder),
                           "--quiet"], capture_output=True, text=True, timeout=1800,
                          env={**os.environ, "PANTOHIL_CACHE": str(tmp_path / "cache-new")})
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["status"] == "converged" and summary["resumed_from_span"] >= 2


HOSTILE_VALUES = (None, [], {}, "x", -1, 2 ** 70, 1.5, True, [[[[]]]], {"$o": "os:system"}, "\0")
TYPED_KEYS = ("format", "span", "k", "history", "fmu_digests", "case_file", "overrides")


def _mutants(folder, rng):
    """Seeded hostile checkpoints: bytes of checkpoint.npz flipped or cut, and checkpoint.json's typed entries
    given values of other types."""
    arrays = (folder / STATE / "checkpoint.npz").read_bytes()
    meta = json.loads((folder / STATE / "checkpoint.json").read_text())
    for _ in range(12):
        data = bytearray(arrays)
        for _ in range(rng.randint(1, 8)):
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        yield "npz bits flipped", "checkpoint.npz", bytes(data)
    for _ in range(6):
        yield "npz cut", "checkpoint.npz", arrays[:rng.randrange(len(arrays))]
    for _ in range(16):
        key, value = rng.choice(TYPED_KEYS), rng.choice(HOSTILE_VALUES)
        if type(value) is type(meta[key]) and not isinstance(value, bool):
            continue
        yield f"json {key}={value!r}", "checkpoint.json", json.dumps({**meta, key: value}).encode()
    yield "json not an object", "checkpoint.json", b"[1, 2, 3]"
    yield "json nested", "checkpoint.json", b"[" * 100_000 + b"]" * 100_000
    yield "json binary", "checkpoint.json", bytes(rng.randrange(256) for _ in range(200))


@pytest.mark.slow
def test_fuzzed_checkpoints_are_refused_in_one_line(interrupted, tmp_path):
    import random

    rng = random.Random(28)
    folder = _copy(interrupted, tmp_path / "fuzzed")
    originals = {name: (folder / STATE / name).read_bytes() for name in ("checkpoint.npz", "checkpoint.json")}
    before = _folder_digest(folder)
    tried = 0
    for what, name, data in _mutants(folder, rng):
        (folder / STATE / name).write_bytes(data)
        code, err = run_main(["run", "--resume", str(folder), "--quiet"])
        (folder / STATE / name).write_bytes(originals[name])
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1 and "Traceback" not in err, f"{what}: exit {code}: {err[-1500:]}"
        assert _folder_digest(folder) == before, f"{what}: the folder changed"
        tried += 1
    assert tried >= 30
