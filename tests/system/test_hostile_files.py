"""Fuzzing of every file reader (issue 28, acceptance 3): seeded random mutations of the shipped files
(truncations, bit flips, huge numbers, deep nesting, NUL, wrong types) and special files (a FIFO, a
directory, a symbolic link to /dev/zero) given to the case, catenary, rig, sweep, SSP and operator-file
readers and to the run folders of `compare` and `watch`. A mutant the reader accepts is a valid file; every
other one must be refused by the command line in one line on stderr, exit 2, with no traceback and nothing
written. The commands run in this process (`main()`), a few as a user would (a subprocess)."""
from __future__ import annotations

import json
import os
import random
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import CASES_DIR, CATENARIES_DIR, ROOT, pantohil, run_main

from pantohil.models.case import CaseError, load_case
from pantohil.models.catenary.fe.definition import CatenaryError, load_definition
from pantohil.models.input_files import InputFileError
from pantohil.models.rig.rig_file import RigFileError, load_rig_file

RIGS_DIR = ROOT / "models" / "data" / "rigs"
SWEEPS_DIR = ROOT / "models" / "data" / "sweeps"
MUTANTS = 24  # per reader; seeded, so each run tries the same files
REFUSALS = (CaseError, CatenaryError, RigFileError, InputFileError)


# ---- mutations -------------------------------------------------------------------------------------------

_NUMBER = re.compile(rb"(?<![\w.])-?\d+(?:\.\d+)?(?:e-?\d+)?(?![\w.])")
_VALUE = re.compile(rb"^([A-Za-z_][\w]*\s*=\s*)(.+)$", re.M)
HUGE = (b"100000000000000000000000000000000000000", b"1e400", b"-1e308", b"9223372036854775808", b"2000000000",
        b"1e-300", b"-9223372036854775809", b"9" * 5000)
WRONG = (b'"text"', b"true", b"[1, 2]", b"{ a = 1 }", b"[]", b'"a\\u0000b"', b"[" * 40 + b"]" * 40)


def _truncate(data: bytes, rng: random.Random) -> bytes:
    return data[: rng.randrange(len(data))]


def _flip(data: bytes, rng: random.Random) -> bytes:
    b = bytearray(data)
    for _ in range(rng.randint(1, 3)):
        i = rng.randrange(len(b))
        b[i] ^= 1 << rng.randrange(8)
    return bytes(b)


def _huge(data: bytes, rng: random.Random) -> bytes:
    spots = list(_NUMBER.finditer(data))
    if not spots:
        return data + b"\nx = " + rng.choice(HUGE) + b"\n"
    m = rng.choice(spots)
    return data[: m.start()] + rng.choice(HUGE) + data[m.end():]


def _wrong(data: bytes, rng: random.Random) -> bytes:
    spots = list(_VALUE.finditer(data))
    m = rng.choice(spots)
    return data[: m.start(2)] + rng.choice(WRONG) + data[m.end(2):]


def _deep(data: bytes, rng: random.Random) -> bytes:
    depth = rng.choice((33, 200, 5000))
    kind = rng.choice(("list", "table", "dotted"))
    if kind == "list":
        line = b"deep = " + b"[" * depth + b"]" * depth
    elif kind == "table":
        line = b"deep = " + b"{a = " * depth + b"1" + b"}" * depth
    else:
        line = b".".join([b"deep"] * depth) + b" = 1"
    return line + b"\n" + data


def _nul(data: bytes, rng: random.Random) -> bytes:
    strings = list(re.finditer(rb'"[^"\n]*"', data))
    if strings and rng.random() < 0.7:
        m = rng.choice(strings)
        return data[: m.start() + 1] + b"\\u0000" + data[m.start() + 1:]
    i = rng.randrange(len(data))
    return data[:i] + b"\0" + data[i:]


TEXT_MUTATIONS = (_truncate, _flip, _huge, _wrong, _deep, _nul)


def text_mutants(data: bytes, seed: int, n: int = MUTANTS) -> list[tuple[str, bytes]]:
    """n mutants of a text file, each with the name of its mutation; the same for the same seed."""
    rng = random.Random(seed)
    out = []
    for i in range(n):
        mutate = TEXT_MUTATIONS[i % len(TEXT_MUTATIONS)]
        out.append((f"{mutate.__name__.strip('_')}-{i}", mutate(data, rng)))
    return out


# ---- the check of one refusal ---------------------------------------------------------------------------

def assert_refused(code: int, stderr: str, out: Path, what: str) -> None:
    """Exit 2, one line on stderr without a traceback, nothing written into out."""
    lines = stderr.strip().splitlines()
    assert code == 2, f"{what}: exit {code}: {stderr[-2000:]}"
    assert "Traceback" not in stderr and len(lines) == 1, f"{what}: {stderr[-2000:]}"
    assert not out.exists() or not any(out.iterdir()), f"{what}: wrote {sorted(out.rglob('*'))}"


def special_files(tmp: Path) -> dict[str, Path]:
    """A FIFO, a directory and a symbolic link to /dev/zero, under names a reader would take."""
    (tmp / "special").mkdir(exist_ok=True)
    fifo, folder, zero = tmp / "special" / "fifo", tmp / "special" / "folder", tmp / "special" / "zero"
    if not fifo.exists():
        os.mkfifo(fifo)
        folder.mkdir()
        zero.symlink_to("/dev/zero")
    return {"fifo": fifo, "directory": folder, "dev-zero": zero}


def fuzz_reader(tmp: Path, name: str, data: bytes, seed: int, accepts, argv) -> tuple[int, int]:
    """Mutants of `data` and the special files through a reader: each one `accepts(path)` raises a refusal
    for must be refused by `argv(path, out)` in one line. Returns (refused, accepted)."""
    refused = accepted = 0
    cases = [(label, tmp / f"{name}-{label}.toml") for label, _ in text_mutants(data, seed)]
    for (_, path), (_, content) in zip(cases, text_mutants(data, seed), strict=True):
        path.write_bytes(content)
    cases += list(special_files(tmp).items())
    for label, path in cases:
        try:
            accepts(path)
        except REFUSALS:
            out = tmp / f"out-{name}-{label}"
            code, err = run_main(argv(path, out))
            assert_refused(code, err, out, f"{name} {label}")
            refused += 1
        else:
            accepted += 1
    return refused, accepted


def absolute_refs(text: str, base: Path) -> str:
    """A shipped file's relative file names made absolute, so that its copy elsewhere still finds them."""
    return re.sub(r'(case|file|definition_file|catenary_file) = "(\.\./[^"]+)"',
                  lambda m: f'{m.group(1)} = "{(base / m.group(2)).resolve()}"', text)


# ---- case, catenary, rig and sweep files ----------------------------------------------------------------

@pytest.mark.parametrize("shipped", ["asm_250.toml", "paper_b_mass_300.toml"])
def test_fuzzed_case_files_are_refused_in_one_line(shipped, tmp_path):
    data = absolute_refs((CASES_DIR / shipped).read_text(), CASES_DIR).encode()
    refused, accepted = fuzz_reader(tmp_path, "case", data, 28, load_case,
                                    lambda p, out: ["run", str(p), "--out", str(out), "--quiet"])
    assert refused >= MUTANTS // 2, (refused, accepted)


def test_fuzzed_catenary_files_are_refused_in_one_line(tmp_path):
    data = (CATENARIES_DIR / "benchmark_simple.toml").read_bytes()
    refused, accepted = fuzz_reader(tmp_path, "catenary", data, 29, load_definition,
                                    lambda p, out: ["catenary", str(p), "--out", str(out)])
    assert refused >= MUTANTS // 2, (refused, accepted)


def test_fuzzed_rig_files_are_refused_in_one_line(tmp_path):
    data = (RIGS_DIR / "paper_b.toml").read_bytes()
    case = CASES_DIR / "paper_b_mass_300.toml"
    refused, accepted = fuzz_reader(
        tmp_path, "rig", data, 30, load_rig_file,
        lambda p, out: ["run", str(case), "--set", f"rig.file={json.dumps(str(p))}", "--out", str(out), "--quiet"])
    assert refused >= MUTANTS // 2, (refused, accepted)


def test_fuzzed_sweep_files_are_refused_in_one_line(tmp_path):
    from pantohil.orchestrator.sweep import load_sweep

    data = absolute_refs((SWEEPS_DIR / "speed_200_300.toml").read_text(), SWEEPS_DIR).encode()
    refused, accepted = fuzz_reader(tmp_path, "sweep", data, 31, load_sweep,
                                    lambda p, out: ["sweep", str(p), "--out", str(out), "--quiet"])
    assert refused >= MUTANTS // 2, (refused, accepted)


@pytest.mark.parametrize("override,words", [
    ("run.speed_kmh=" + "[" * 40 + "]" * 40, ("run.speed_kmh", "nests deeper than 32")),
    ("catenary.tension_N=" + "9" * 400, ("catenary.tension_N", "64-bit range")),
    ('profile.csv_file="a\\u0000b.csv"', ("profile.csv_file", "NUL")),
    ("hil.relaxation=1.0000000001", ("hil.relaxation", "1.0000000001 is outside", "(0, 1]")),
    ("hil.hold_steps=100000", ("hil.hold_steps:", "loop", "hold 100000")),
])
def test_overrides_beyond_any_file_reader_are_refused_naming_the_key(override, words, tmp_path):
    """Issue 28, D10 and D25: --set values pass the same checks as files; a refusal shows the value given
    and blames the key that caused it."""
    out = tmp_path / "out"
    code, err = run_main(["run", "--set", override, "--out", str(out), "--quiet"])
    assert_refused(code, err, out, override)
    assert all(w in err for w in words), err


def test_deep_nesting_huge_integers_and_nul_in_each_toml_reader(tmp_path):
    """Issue 28, D10: RecursionError, OverflowError and ValueError were tracebacks in every TOML loader."""
    texts = {"case": (CASES_DIR / "asm_250.toml").read_text(),
             "catenary": (CATENARIES_DIR / "benchmark_simple.toml").read_text(),
             "rig": (RIGS_DIR / "paper_b.toml").read_text(),
             "sweep": absolute_refs((SWEEPS_DIR / "speed_200_300.toml").read_text(), SWEEPS_DIR)}
    hostile = {"deep": "x = " + "[" * 5000 + "]" * 5000 + "\n", "bigint": "x = " + "9" * 400 + "\n",
               "nul": 'x = "a\\u0000b"\n'}
    argv = {"case": lambda p, o: ["run", str(p), "--out", str(o)], "catenary": lambda p, o: ["catenary", str(p),
                                                                                              "--out", str(o)],
            "rig": lambda p, o: ["rig-emulator", "--listen", "127.0.0.1:0", "--rig", str(p), "--max-seconds", "0"],
            "sweep": lambda p, o: ["sweep", str(p), "--out", str(o)]}
    for reader, text in texts.items():
        for label, line in hostile.items():
            path, out = tmp_path / f"{reader}-{label}.toml", tmp_path / f"out-{reader}-{label}"
            path.write_text(line + text)
            code, err = run_main(argv[reader](path, out))
            assert_refused(code, err, out, f"{reader} {label}")
            assert str(path) in err and ("x " in err or "line 1 " in err), err


# ---- operator files -------------------------------------------------------------------------------------

def _operator_file(tmp: Path) -> Path:
    from pantohil.models.catenary.asm.string import AsmParameters
    from string_references import string_block
    from pantohil.models.catenary.pfem.operator_file import save_operators
    from pantohil.models.catenary.pfem.operators import PfemSettings, build_operators

    cat = AsmParameters(31500.0, 1.4735, 51.15, 0.0125, 1e-4)
    ops = build_operators(string_block(cat, 10.0, 40), PfemSettings(50.0, 10.0 / (50.0 * 100), 100, 8, 2,
                                                                     omega_max=300.0))
    path = tmp / "ops.npz"
    save_operators(ops, path, "k" * 24)
    return path


def test_fuzzed_operator_files_are_refused_in_one_line(tmp_path):
    from pantohil.models.catenary.pfem.operator_file import OperatorFileError, load_operators

    data = _operator_file(tmp_path).read_bytes()
    rng = random.Random(32)
    refused = 0
    for i in range(3 * MUTANTS):
        path = tmp_path / f"mutant-{i}.npz"
        path.write_bytes(_truncate(data, rng) if i % 2 else _flip(data, rng))
        try:
            ops = load_operators(path, "k" * 24)
        except OperatorFileError as exc:
            assert "\n" not in str(exc) and str(path) in str(exc)
            refused += 1
        else:  # a flip inside an array's numbers: a valid file of other numbers
            assert np.all(np.isfinite(ops.cc))
    for label, path in special_files(tmp_path).items():
        with pytest.raises(OperatorFileError, match="regular file|directory"):
            load_operators(path)
        assert label
    assert refused >= MUTANTS


# ---- run folders for compare and watch ------------------------------------------------------------------

def _run_folder(folder: Path, n: int = 200, std: float = 10.0) -> Path:
    """A small HIL run folder: summary.json, steady_span.csv and a finished run.mcap."""
    from pantohil.orchestrator.recorder import McapWriter

    folder.mkdir(parents=True)
    t = np.arange(n) * 1e-3
    f = 120.0 + std * np.sin(2 * np.pi * t / (n * 1e-3))
    rows = "\n".join(f"{a:.6f},0.0,0.0,{b:.9e}" for a, b in zip(t, f, strict=True))
    (folder / "steady_span.csv").write_text("t_s,z0_m,z_m,f_N\n" + rows + "\n")
    (folder / "summary.json").write_text(json.dumps({"case": "fuzz", "dt_s": 1e-3, "status": "converged",
                                                      "message": "converged", "catenary": {"model": "asm"}}))
    writer = McapWriter(folder / "run.mcap", {"/catenary": {"force_at_sample": "force [N]"}}, {"case": "fuzz"})
    for span in range(3):
        writer.write_block("/catenary", t + span * n * 1e-3, f[:, None])
        writer.write_event("/convergence", (span + 1) * n * 1e-3, {"span": span, "change": 0.1, "mean_N": 120.0,
                                                                   "std_N": std, "max_N": 130.0, "min_N": 110.0})
    writer.close()
    return folder


JSON_MUTANTS = (b'{"dt_s": ' + b"9" * 5000 + b"}",
                b"[1, 2]", b'"text"', b"null", b"{", b'{"dt_s": NaN}', b'{"dt_s": "x"}', b'{"dt_s": -1}',
                b'{"dt_s": 1e400}', b"[" * 5000 + b"]" * 5000, b'{"a": "\\u0000"}', b"\xff\xfe", b"")


def _run_folder_mutants(good: Path, tmp: Path, rng: random.Random):
    """(label, folder) with one file of a good run folder replaced by a hostile one."""
    specials = special_files(tmp)
    for name in ("summary.json", "steady_span.csv", "run.mcap"):
        data = (good / name).read_bytes()
        contents = [(f"{m.__name__}-{i}", m(data, rng)) for i, m in enumerate((_truncate, _flip) * 4)]
        if name == "summary.json":
            contents += [(f"json-{i}", c) for i, c in enumerate(JSON_MUTANTS)]
        for label, content in contents:
            yield f"{name}-{label}", name, content
        for label, path in specials.items():
            yield f"{name}-{label}", name, path


def _make(good: Path, folder: Path, name: str, content) -> Path:
    import shutil

    shutil.copytree(good, folder)
    (folder / name).unlink()
    if isinstance(content, Path):
        (folder / name).symlink_to(content)
    else:
        (folder / name).write_bytes(content)
    return folder


def test_compare_and_watch_on_fuzzed_run_folders(tmp_path):
    """Issue 28, D16: a FIFO hung them, /dev/zero exhausted memory, a directory or a JSON list crashed them.
    Each mutant either reads (exit 0) or is refused in one line, exit 2, nothing written."""
    good = _run_folder(tmp_path / "good")
    rng = random.Random(33)
    outcomes = {0: 0, 2: 0}
    for label, name, content in _run_folder_mutants(good, tmp_path, rng):
        folder = _make(good, tmp_path / f"run-{label}", name, content)
        for argv, out in ((["compare", str(good), str(folder), "--out", str(tmp_path / f"cmp-{label}")],
                           tmp_path / f"cmp-{label}"),
                          (["watch", str(folder), "--once"], tmp_path / "nothing")):
            code, err = run_main(argv)
            assert code in (0, 2) and "Traceback" not in err, f"{label} {argv[0]}: exit {code}: {err[-2000:]}"
            if code == 2:
                assert_refused(code, err, out, f"{label} {argv[0]}")
            outcomes[code] += 1
    assert outcomes[2] >= 40, outcomes


def test_a_log_record_claiming_a_huge_length_is_refused_after_one_window(tmp_path):
    """Issue 28, D16: a log is read in bounded windows; a record claiming 2^64 - 1 bytes over a whole window of
    data is a damaged log (while a run writes, a record's length may show so until the writer patches it)."""
    from pantohil.orchestrator.mcap_follow import MAGIC, MAX_POLL_BYTES

    folder = _run_folder(tmp_path / "huge")
    with open(folder / "run.mcap", "wb") as fh:
        fh.write(MAGIC + b"\x06" + b"\xff" * 8)
        fh.truncate(MAX_POLL_BYTES + 64)
    code, err = run_main(["watch", str(folder), "--once"])
    assert code == 2 and err.count("\n") == 1 and "larger than the limit" in err, err


def test_compare_of_a_constant_run_reports_no_percentage(tmp_path):
    """Issue 28, D16: a run whose force does not vary gave a 1e17 % difference of the std."""
    a, b = _run_folder(tmp_path / "a"), _run_folder(tmp_path / "b", std=0.0)
    out = tmp_path / "cmp"
    code, err = run_main(["compare", str(a), str(b), "--out", str(out)])
    assert code == 0, err
    r = json.loads((out / "compare.json").read_text())
    assert r["std_difference_pct"] is None and r["rms_difference_pct_of_std_b"] is None
    assert r["rms_difference_N"] > 0


def test_watch_stops_when_the_run_was_killed(tmp_path):
    """Issue 28, D20: watch followed a killed run's unfinished log for ever. A lock file that no process holds
    and a log without its footer: one line, exit 1, within a few intervals."""
    folder = _run_folder(tmp_path / "killed")
    whole = (folder / "run.mcap").read_bytes()
    (folder / "run.mcap").write_bytes(whole[: len(whole) - 200])  # no footer: the writer was killed too
    (folder / ".pantohil-run.lock").write_text("12345\n")  # the lock's file stays; no process holds it
    proc = pantohil("watch", str(folder), "--interval", "0.05", timeout=60)
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.count("\n") == 1 and "no longer running" in proc.stderr, proc.stderr
    (folder / "run.mcap").write_bytes(whole)
    proc = pantohil("watch", str(folder), "--interval", "0.05", timeout=60)  # finished log, no summary.json
    assert proc.returncode == 0, proc.stderr  # the folder has its summary: a finished run


@pytest.mark.parametrize("interval", ["nan", "inf", "-1", "0"])
def test_watch_interval_must_be_a_finite_positive_time(interval, tmp_path):
    code, err = run_main(["watch", str(tmp_path), "--interval", interval])
    assert code == 2 and err.count("\n") == 1 and "--interval" in err, err


# ---- SSP files ------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def ssp(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("ssp_fuzz") / "asm_250.ssp"
    proc = pantohil("build", "--ssp", str(path))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return path


def _with_member(src: Path, dst: Path, name: str, data: bytes | None = None, ssv=None) -> Path:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            content = zin.read(item)
            if item.filename == "resources/parameters.ssv" and ssv is not None:
                content = ssv(content.decode()).encode()
            zout.writestr(item, content)
        if data is not None:
            zout.writestr(name, data)
    return dst


def _ssv_value(name: str, value: str):
    pattern = re.compile(r'(<ssv:Parameter name="' + re.escape(name) + r'">\s*<ssv:\w+ value=")([^"]*)(")')

    def edit(text: str) -> str:
        assert pattern.search(text), name
        return pattern.sub(lambda m: m.group(1) + value + m.group(3), text)
    return edit


@pytest.mark.parametrize("edit,words", [
    (("catenary.tension_N", "-31500.0"), ("parameters.ssv", "catenary.tension_N", "outside its range")),
    (("catenary.hil_update", "9"), ("hil.update", "not the index")),
    (("catenary.time_step", "1e-09"), ("catenary.time_step", "not what its case gives")),
    (("catenary.delay_steps", "5000"), ("hil.delay_steps", "shorter than a span")),
])
def test_an_ssp_parameter_goes_through_the_case_validation(ssp, tmp_path, edit, words):
    """Issue 28, D12: an SSP's values skipped the case's range checks (a tension of -31500 N ran)."""
    bad = _with_member(ssp, tmp_path / "bad.ssp", "", ssv=_ssv_value(*edit))
    out = tmp_path / "out"
    code, err = run_main(["run", str(bad), "--out", str(out), "--quiet"])
    assert_refused(code, err, out, str(edit))
    assert all(w in err for w in words), err


def test_the_summary_of_an_ssp_run_reports_the_values_that_ran(ssp, tmp_path):
    """Issue 28, D12: the summary said 31500 N where the SSP's tension ran."""
    edited = _with_member(ssp, tmp_path / "edited.ssp", "", ssv=_ssv_value("catenary.tension_N", "40000.0"))
    out = tmp_path / "run"
    proc = pantohil("run", str(edited), "--set", "run.max_spans=2", "--out", str(out), "--quiet")
    assert proc.returncode == 1, proc.stderr  # 2 spans: not converged
    assert json.loads((out / "summary.json").read_text())["catenary"]["tension_N"] == 40000.0


def test_ssp_archives_are_bounded_and_stay_in_their_folder(ssp, tmp_path):
    """Issue 28, D26: a 2 MB archive with a 1 GiB member was extracted whole; members that leave the folder."""
    bomb = tmp_path / "bomb.ssp"
    with zipfile.ZipFile(ssp) as zin, zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        for item in zin.infolist():
            z.writestr(item, zin.read(item))
        with z.open("resources/big.bin", "w", force_zip64=True) as fh:
            chunk = bytes(1 << 20)
            for _ in range(257):  # just above the per-member limit of 256 MiB
                fh.write(chunk)
    cases = {"bomb": (bomb, "above the limit"),
             "traversal": (_with_member(ssp, tmp_path / "t.ssp", "../../evil.txt", b"x"), "leaves the archive"),
             "absolute": (_with_member(ssp, tmp_path / "a.ssp", "/tmp/evil.txt", b"x"), "leaves the archive"),
             "many": (tmp_path / "many.ssp", "members, above the limit")}
    with zipfile.ZipFile(ssp) as zin, zipfile.ZipFile(cases["many"][0], "w") as z:
        for item in zin.infolist():
            z.writestr(item, zin.read(item))
        for i in range(100):
            z.writestr(f"resources/x{i}", b"")
    for label, (path, words) in cases.items():
        out = tmp_path / f"out-{label}"
        code, err = run_main(["run", str(path), "--out", str(out), "--quiet"])
        assert_refused(code, err, out, label)
        assert words in err, err
    assert not (tmp_path.parent / "evil.txt").exists()


def test_fuzzed_ssp_files_are_refused_in_one_line(ssp, tmp_path):
    data = ssp.read_bytes()
    rng = random.Random(34)
    for i in range(8):
        path = tmp_path / f"mutant-{i}.ssp"
        path.write_bytes(_truncate(data, rng) if i % 2 else _flip(data[:4096], rng) + data[4096:])
        out = tmp_path / f"out-{i}"
        code, err = run_main(["run", str(path), "--set", "run.max_spans=1", "--out", str(out), "--quiet"])
        if code != 2:  # a flip in a member's data the archive's CRC does not cover: the run goes on
            assert "Traceback" not in err, err
            continue
        assert_refused(code, err, out, f"ssp mutant {i}")
    for label, path in special_files(tmp_path).items():
        out = tmp_path / f"out-{label}"
        target = tmp_path / f"{label}.ssp"
        target.symlink_to(path)
        code, err = run_main(["run", str(target), "--out", str(out), "--quiet"])
        assert_refused(code, err, out, label)


# ---- the FMU cache --------------------------------------------------------------------------------------

def test_a_damaged_fmu_cache_entry_is_rebuilt(tmp_path, capsys, monkeypatch):
    """Issue 28, D14: a truncated or bit-flipped cache entry was trusted for ever. The test damages a cache
    of its own: the session's is shared with the other tests."""
    from pantohil.builder.build_fmus import build_case_fmus
    from pantohil.models.storage import cache_root

    monkeypatch.setenv("PANTOHIL_CACHE", str(tmp_path / "cache"))
    case = load_case()
    build_case_fmus(case, tmp_path / "fmus", names=("rig",))
    capsys.readouterr()
    entries = sorted((cache_root() / "fmus").glob("*/PantohilRig.fmu"))
    assert entries
    for damage in (lambda b: b[: len(b) // 2], lambda b: b[:100] + bytes([b[100] ^ 4]) + b[101:]):
        for entry in entries:
            entry.write_bytes(damage(entry.read_bytes()))
        build_case_fmus(case, tmp_path / "fmus", names=("rig",))
        assert "does not match its digest" in capsys.readouterr().err
        build_case_fmus(case, tmp_path / "fmus", names=("rig",))  # rebuilt: whole again
        assert "digest" not in capsys.readouterr().err


@pytest.mark.parametrize("where", ["file", "under-file"])
def test_a_cache_path_that_is_a_file_is_one_line(where, tmp_path, monkeypatch):
    (tmp_path / "file").write_text("x")
    monkeypatch.setenv("PANTOHIL_CACHE", str(tmp_path / "file" / ("sub" if where == "under-file" else "")))
    out = tmp_path / "out"
    code, err = run_main(["build", "--out", str(out)])
    assert_refused(code, err, out, where)
    assert "PANTOHIL_CACHE" in err, err


# ---- a few as a user would run them ---------------------------------------------------------------------

@pytest.mark.parametrize("argv,words", [
    (["run", "{deep}", "--out", "{out}"], ("nests deeper",)),
    (["compare", "{fifo_run}", "{good}", "--out", "{out}"], ("not a regular file",)),
    (["watch", "{zero_run}"], ("not a regular file",)),
    (["watch", "{good}", "--interval", "nan"], ("--interval",)),
])
def test_hostile_files_as_a_user_runs_them(argv, words, tmp_path):
    good = _run_folder(tmp_path / "good")
    deep = tmp_path / "deep.toml"
    deep.write_text("x = " + "[" * 5000 + "]" * 5000 + "\n" + (CASES_DIR / "asm_250.toml").read_text())
    fifo_run = _make(good, tmp_path / "fifo_run", "summary.json", special_files(tmp_path)["fifo"])
    zero_run = _make(good, tmp_path / "zero_run", "run.mcap", special_files(tmp_path)["dev-zero"])
    subst = {"{deep}": deep, "{out}": tmp_path / "out", "{good}": good, "{fifo_run}": fifo_run,
             "{zero_run}": zero_run}
    args = [str(subst.get(a, a)) for a in argv]
    proc = subprocess.run([sys.executable, "-m", "pantohil.orchestrator.cli", *args], capture_output=True, text=True,
                          timeout=120)
    assert_refused(proc.returncode, proc.stderr, tmp_path / "out", " ".join(argv))
    assert all(w in proc.stderr for w in words), proc.stderr
