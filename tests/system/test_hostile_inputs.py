"""Hostile inputs (case, catenary, profile CSV, sweep and stability files, command-line values): each is
refused with one line on stderr naming what is wrong, exit 2, no traceback and nothing written into
--out, in a process limited to 1 GB of address space (the slow test; the fast one calls the CLI's main
in this process). How long each refusal takes is measured by tests/benchmarks/bench_hostile_inputs.py,
not asserted here."""
from __future__ import annotations

import os
import resource
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import run_main

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_CASE = ROOT / "models" / "data" / "cases" / "asm_250.toml"
CATENARY = ROOT / "models" / "data" / "catenaries" / "benchmark_simple.toml"
MEMORY_LIMIT_BYTES = 1 << 30


@dataclass(frozen=True)
class Hostile:
    """One hostile input: the command (with {case}, {csv}, {cat}, {sweep}, {out}, {tmp} placeholders),
    the files it needs, and the words the one-line refusal must contain."""

    name: str
    argv: tuple
    words: tuple
    case: str | None = None  # case file text
    csv: bytes | None = None  # profile CSV content
    cat: str | None = None  # catenary file text
    sweep: str | None = None  # sweep file text


def case_text(*edits: tuple[str, str], append: str = "") -> str:
    """The default case with lines replaced (old, new) and text appended."""
    text = DEFAULT_CASE.read_text()
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new, 1)
    return text + append


def catenary_text(*edits: tuple[str, str], append: str = "") -> str:
    text = CATENARY.read_text()
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new, 1)
    return text + append


SCALAR_HIL = "hil = 5\n" + case_text().split("[hil]")[0] + "[run]" + case_text().split("[run]")[1]
CSV_CASE = case_text(('source = "droppers"', 'source = "csv"\ncsv_file = "profile.csv"'))
RUN = ("run", "{case}", "--out", "{out}", "--quiet")
SWEEP_HEAD = f'[sweep]\nname = "hostile"\ncase = "{DEFAULT_CASE}"\nkind = "direct"\n'
CAT_CASE = case_text(('model = "asm"                    # analytical string model ASM2 (Paper A sec. 3)',
                      'model = "asm"\ndefinition_file = "catenary.toml"'))


def _case(name, words, *edits, append="", argv=RUN):
    return Hostile(name, argv, words, case=case_text(*edits, append=append))


def _set(name, override, words, case=None):
    return Hostile(name, ("run", *(("{case}",) if case else ()), "--set", override, "--out", "{out}", "--quiet"),
                   words, case=case)


def _csv(name, content: bytes, words):
    return Hostile(name, RUN, words, case=CSV_CASE, csv=content)


def _cat(name, words, *edits, append=""):
    return Hostile(name, ("catenary", "{cat}", "--out", "{out}"), words, cat=catenary_text(*edits, append=append))


def _sweep(name, grid: str, words):
    return Hostile(name, ("sweep", "{sweep}", "--out", "{out}", "--quiet"), words, sweep=SWEEP_HEAD + grid)


def _stab(name, options, words):
    return Hostile(name, ("stability", *options, "--out", "{out}", "--quiet"), words)


TENSION = "tension_N = 31500.0              # string tension T [N]"
SPAN = "span_m = 65.0                    # span length L [m] (Paper B Table 1)"
KC = "contact_stiffness_N_m = 50000.0  # penalty stiffness k_c [N/m]"
MASSES = "masses_kg = [6.6, 5.8, 5.8]"
SPACING = "dropper_spacing_m = [6.0, 9.48, 8.7, 8.32, 8.32, 8.7, 9.48, 6.0]"
RIG_DELAY = "delay_steps = 4\n"
RAMP = "ramp_steps = 1000                # initial ramp N_r [steps]"
MAX_SPANS = "max_spans = 200"
DT = "dt_s = 0.001                     # 65 m at 69.44 m/s = 0.936 s = 936 samples of exactly 1 ms"
SPEED = "speed_kmh = 250.0"
CAT_TENSION = "tension_N = 22000.0"

CASES = [
    # case files that are not text, or not there
    Hostile("case-binary", RUN, ("case file", "binary"), case="\0\1\2 binary"),
    Hostile("case-directory", ("run", "{tmp}", "--out", "{out}"), ("is a directory",)),
    Hostile("case-dev-zero", ("run", "/dev/zero", "--out", "{out}"), ("/dev/zero", "not a regular file")),
    Hostile("case-fifo", ("run", "{tmp}/fifo.toml", "--out", "{out}"), ("not a regular file",)),
    Hostile("case-not-utf8", RUN, ("not UTF-8",), case='[case]\nname = "caf\xe9"\n'),
    Hostile("case-too-large", RUN, ("above the limit", "bytes"), case="#" * (5 << 20)),
    Hostile("case-invalid-toml", RUN, ("not valid TOML",), case="[run\nspeed_kmh = 250\n"),
    Hostile("case-missing", ("run", "{tmp}/nowhere.toml", "--out", "{out}"), ("does not exist",)),
    # numbers that are not finite, also inside lists
    _case("case-nan-scalar", ("catenary.tension_N", "finite"), (TENSION, "tension_N = nan")),
    _case("case-inf-scalar", ("run.speed_kmh", "finite"), (SPEED, "speed_kmh = inf")),
    _case("case-minus-inf", ("pantograph.contact_stiffness_N_m", "finite"), (KC, "contact_stiffness_N_m = -inf")),
    _case("case-inf-in-list", ("pantograph.masses_kg[0]", "finite"), (MASSES, "masses_kg = [inf, 5.8, 5.8]")),
    _case(
        "case-nan-in-list",
        ("profile.dropper_spacing_m[2]", "finite"),
        (SPACING, "dropper_spacing_m = [6.0, 9.48, nan, 8.32, 8.32, 8.7, 9.48, 6.0]"),
    ),
    # integers beyond the FMU's xs:int
    _case(
        "case-seed-above-int32",
        ("rig.noise_seed", "FMI integer range"),
        (RIG_DELAY, RIG_DELAY + "noise_seed = 2147483648\n"),
    ),
    _case("case-ramp-above-int32", ("hil.ramp_steps", "FMI integer range"), (RAMP, "ramp_steps = 1099511627776")),
    _case(
        "case-int64-min", ("rig.delay_steps", "FMI integer range"), (RIG_DELAY, "delay_steps = -9223372036854775808\n")
    ),
    # sizes without bound
    _case("case-max-spans-1e9", ("run.max_spans", "[1, 10000]"), (MAX_SPANS, "max_spans = 1000000000")),
    _case("case-dt-1e-7", ("run.dt_s", "[1e-05, 0.1]"), (DT, "dt_s = 1e-7")),
    _case("case-speed-1e-6", ("run.speed_kmh", "[1, 600]"), (SPEED, "speed_kmh = 1e-6")),
    _case("case-samples-per-span", ("samples per span", "100000"), (SPEED, "speed_kmh = 1.0"), (DT, "dt_s = 1e-5")),
    _case(
        "case-long-list",
        ("pantograph.masses_kg", "limit of 100"),
        (MASSES, f"masses_kg = [{', '.join(['1.0'] * 101)}]"),
    ),
    _case("case-span-1e308", ("catenary.span_m", "[1, 1000]"), (SPAN, "span_m = 1e308")),
    # physical ranges: 1e308 would "converge" with a contact force of 0 N
    _case("case-tension-1e308", ("catenary.tension_N", "(0, 1e+06]"), (TENSION, "tension_N = 1e308")),
    _case("case-uplift-1e308", ("pantograph.uplift_force_N", "(0, 2000]"), (KC, KC + "\nuplift_force_N = 1e308")),
    _case(
        "case-contact-stiffness-1e308",
        ("pantograph.contact_stiffness_N_m", "(0, 1e+08]"),
        (KC, "contact_stiffness_N_m = 1e308"),
    ),
    _case("case-density-zero", ("catenary.density_kg_m", "(0, 100]"), ("density_kg_m = 1.4735", "density_kg_m = 0.0")),
    _case("case-relaxation-zero", ("hil.relaxation", "(0, 1]"), ("relaxation = 0.1 ", "relaxation = 0.0 ")),
    # negative delay advance is not "automatic": only "auto" is
    _case(
        "case-hil-delay-negative",
        ("hil.delay_steps", "auto"),
        ("delay_compensation = true", "delay_compensation = true\ndelay_steps = -1"),
    ),
    _case(
        "case-uplift-wrong-word",
        ("pantograph.uplift_force_N", "expected a number"),
        (KC, KC + '\nuplift_force_N = "automatic"'),
    ),
    # valid TOML that crashed every loader (issue 28, D10)
    _case("case-deep-nesting", ("line 56", "nests deeper than 32"), append="x = " + "[" * 5000 + "]" * 5000 + "\n"),
    _case("case-dotted-deep", ("nests deeper than 32",), append="[run.a]\n" + ".".join(["b"] * 100) + " = 1\n"),
    _case("case-int-beyond-64-bits", ("catenary.tension_N", "64-bit range"), (TENSION, "tension_N = " + "9" * 400)),
    _case("case-int-5000-digits", ("case file", "4300"), append="x = " + "9" * 5000 + "\n"),
    _set("set-int-5000-digits", "run.max_spans=" + "9" * 5000, ("override", "4300")),
    _case("case-nul-in-file-name", ("profile.csv_file", "NUL"),
          ('source = "droppers"', 'source = "csv"\ncsv_file = "profile\\u0000.csv"')),
    # refusals that name the right value and key (issue 28, D25)
    _set("set-relaxation-digits", "hil.relaxation=1.0000000001", ("hil.relaxation", "1.0000000001 is outside")),
    _set("set-hold-steps-blamed", "hil.hold_steps=100000", ("hil.hold_steps:", "hold 100000")),
    Hostile("watch-interval-nan", ("watch", "{tmp}", "--interval", "nan"), ("--interval", "finite")),
    # structure
    Hostile("case-section-scalar", RUN, ("hil", "table"), case=SCALAR_HIL),
    _case("case-unknown-section", ("bogus", "unknown section"), append="[bogus]\nx = 1\n"),
    _case("case-unknown-key", ("run.colour", "unknown key"), (MAX_SPANS, "max_spans = 200\ncolour = 1")),
    _case("case-string-for-number", ("catenary.tension_N", "expected a number"), (TENSION, 'tension_N = "high"')),
    _case("case-bool-for-integer", ("run.max_spans", "integer"), (MAX_SPANS, "max_spans = true")),
    _case(
        "case-stroke-inverted",
        ("actuator.stroke_max_m",),
        append="[actuator]\nstroke_min_m = 0.1\nstroke_max_m = 0.0\n",
    ),
    # --set overrides
    _set("set-newline", "run.speed_kmh=250\nrun.max_spans=1", ("one line",)),
    _set("set-carriage-return", "run.speed_kmh=250\r", ("one line",)),
    _set("set-into-scalar-section", "hil.relaxation=0.1", ("hil", "not a table"), case=SCALAR_HIL),
    _set("set-no-equals", "run.speed_kmh", ("section.key=value",)),
    _set("set-no-section", "speed_kmh=250", ("section.key=value",)),
    _set("set-bad-name", "run..speed=1", ("plain names",)),
    _set("set-delay-negative", "hil.delay_steps=-5", ("hil.delay_steps", "auto")),
    _set("set-nan", "run.speed_kmh=nan", ("run.speed_kmh", "finite")),
    _set("set-inf", "catenary.tension_N=inf", ("catenary.tension_N", "finite")),
    _set("set-nan-in-list", "pantograph.stiffnesses_N_m=[7000.0, nan, 80.0]", ("stiffnesses_N_m[1]", "finite")),
    _set("set-seed-above-int32", "rig.noise_seed=99999999999", ("rig.noise_seed", "FMI integer range")),
    _set("set-ramp-negative", "hil.ramp_steps=-1", ("hil.ramp_steps", "[0, 1e+08]")),
    _set("set-max-spans-1e9", "run.max_spans=1000000000", ("run.max_spans", "10000")),
    _set("set-contact-stiffness-1e308", "pantograph.contact_stiffness_N_m=1e308", ("contact_stiffness_N_m",)),
    _set("set-unknown-section", "bogus.key=1", ("bogus", "unknown section")),
    # profile CSVs
    _csv("csv-nan-row", b"x_m,z0_m\n0,0\n30,nan\n65,0\n", ("profile", "row 2", "not finite")),
    _csv("csv-inf-row", b"x_m,z0_m\n0,0\ninf,0\n65,0\n", ("profile", "not finite")),
    _csv("csv-binary", b"\x00\x01\x02\x03", ("profile file", "binary")),
    _csv("csv-not-utf8", b"x_m,z0_m\n0,0\xff\n", ("profile file", "not UTF-8")),
    _csv("csv-not-numeric", b"x_m,z0_m\n0,zero\n65,0\n", ("profile file", "numeric")),
    _csv("csv-wrong-columns", b"x,z\n0,0\n65,0\n", ("profile file", "x_m,z0_m")),
    _csv("csv-decreasing", b"x_m,z0_m\n30,0\n10,0\n65,0\n", ("profile file", "increase")),
    Hostile(
        "csv-dev-zero",
        RUN,
        ("/dev/zero", "not a regular file"),
        case=case_text(('source = "droppers"', 'source = "csv"\ncsv_file = "/dev/zero"')),
    ),
    Hostile(
        "csv-directory",
        RUN,
        ("profile file", "directory"),
        case=case_text(('source = "droppers"', 'source = "csv"\ncsv_file = "."')),
    ),
    # catenary files
    _cat("catenary-tension-1e308", ("contact_wire.tension_N", "(0, 1e+06]"), (CAT_TENSION, "tension_N = 1e308")),
    _cat("catenary-nan", ("contact_wire.tension_N", "finite"), (CAT_TENSION, "tension_N = nan")),
    _cat("catenary-mesh-tiny", ("catenary.mesh_size_m", "[0.05, 10]"), ("mesh_size_m = 0.25", "mesh_size_m = 1e-9")),
    _cat(
        "catenary-many-droppers",
        ("catenary.dropper_positions_m", "above the limit of 100"),
        (
            "dropper_positions_m = [4.5, 10.25, 16.0, 21.75, 27.5, 33.25, 39.0, 44.75, 50.5]",
            f"dropper_positions_m = [{', '.join(f'{0.01 * (i + 1):.2f}' for i in range(200))}]",
        ),
    ),
    _cat(
        "catenary-elements-per-span",
        ("catenary.span_m / catenary.mesh_size_m", "limit of 1000", "GiB"),
        ("span_m = 55.0", "span_m = 1000.0"),
        ("mesh_size_m = 0.25", "mesh_size_m = 0.5"),
    ),
    _cat(
        "catenary-missing-section",
        ("messenger_wire", "missing section"),
        ("[messenger_wire]\nlinear_mass_kg_m = 1.08\nbending_stiffness_N_m2 = 131.7\ntension_N = 16000.0\n", ""),
    ),
    Hostile("catenary-binary", ("catenary", "{cat}", "--out", "{out}"), ("catenary file", "binary"), cat="\0\0\0"),
    Hostile("catenary-dev-zero", ("catenary", "/dev/zero", "--out", "{out}"), ("not a regular file",)),
    Hostile("catenary-directory", ("catenary", "{tmp}", "--out", "{out}"), ("is a directory",)),
    Hostile("catenary-in-case-is-binary", RUN, ("catenary.definition_file", "binary"), case=CAT_CASE, cat="\0"),
    # sweep files
    _sweep(
        "sweep-1e12-points",
        '[grid]\n"run.speed_kmh" = { start = 200.0, stop = 300.0, num = 1000000000000 }\n',
        ("run.speed_kmh", "limit of 10000 points"),
    ),
    _sweep(
        "sweep-start-a",
        '[grid]\n"run.speed_kmh" = { start = "a", stop = 300.0, num = 3 }\n',
        ("start", "finite number"),
    ),
    _sweep("sweep-stop-nan", '[grid]\n"run.speed_kmh" = { start = 200.0, stop = nan, num = 3 }\n', ("finite",)),
    _sweep(
        "sweep-grid-product",
        '[grid]\n"run.speed_kmh" = { start = 200.0, stop = 300.0, num = 1000 }\n'
        '"hil.relaxation" = { start = 0.05, stop = 1.0, num = 1000 }\n',
        ("1000000 points", "limit"),
    ),
    _sweep("sweep-bad-key", '[grid]\n"run.colour" = [1, 2]\n', ("run.colour", "not a case key")),
    _sweep("sweep-bad-point", '[grid]\n"run.speed_kmh" = [200.0, 1e308]\n', ("run.speed_kmh", "range")),
    Hostile("sweep-point-plots-text", ("sweep", "{sweep}", "--out", "{out}", "--quiet"),
            ("sweep.point_plots", "true or false"),
            sweep=SWEEP_HEAD + 'point_plots = "yes"\n[grid]\n"run.speed_kmh" = [200.0]\n'),
    Hostile("sweep-dev-zero", ("sweep", "/dev/zero", "--out", "{out}"), ("sweep file", "not a regular file")),
    Hostile(
        "sweep-section-scalar",
        ("sweep", "{sweep}", "--out", "{out}"),
        ("grid", "table"),
        sweep="grid = 5\n" + SWEEP_HEAD,
    ),
    # stability grids
    _stab("stability-1e12-points", ("--fmax", "1:2:1000000000000"), ("--fmax", "limit")),
    _stab("stability-letters", ("--fmax", "a:b:3"), ("--fmax", "expected")),
    _stab("stability-nan", ("--fmax", "nan"), ("--fmax", "finite")),
    _stab("stability-inf-stiffness", ("--contact-stiffness", "inf"), ("--contact-stiffness", "finite")),
    _stab("stability-negative-delay", ("--delay", "-3"), ("delay", "must lie in 1..")),
    _stab(
        "stability-map-too-large",
        ("--fmax", "1:20:10000", "--contact-stiffness", "1e4:1e5:10000"),
        ("stability map", "limit"),
    ),
    _stab("stability-relaxation-nan", ("--relaxation", "nan"), ("--relaxation", "finite")),
    # command-line values
    Hostile(
        "fem-sim-spans-huge",
        ("fem-sim", str(DEFAULT_CASE), "--spans", "1000000000", "--out", "{out}"),
        ("--spans", "outside"),
    ),
    Hostile("fem-sim-spans-negative", ("fem-sim", str(DEFAULT_CASE), "--spans", "-1", "--out", "{out}"), ("--spans",)),
    Hostile("run-rt-priority", ("run", "--rt-priority", "1000", "--out", "{out}"), ("--rt-priority", "outside")),
    Hostile("run-master-bogus", ("run", "--master", "bogus", "--out", "{out}"), ("--master",)),
    Hostile("emulator-loss-nan", ("rig-emulator", "--listen", "127.0.0.1:0", "--loss", "nan"), ("--loss", "finite")),
    Hostile(
        "emulator-max-seconds-inf",
        ("rig-emulator", "--listen", "127.0.0.1:0", "--max-seconds", "inf"),
        ("--max-seconds", "finite"),
    ),
    Hostile("direct-max-spacing-inf", ("direct", "--max-spacing", "inf", "--out", "{out}"), ("--max-spacing",)),
    Hostile(
        "direct-second-nan", ("direct", "--second-pantograph-at", "nan", "--out", "{out}"), ("--second-pantograph-at",)
    ),
    Hostile(
        "sweep-workers-huge",
        ("sweep", "{sweep}", "--workers", "100000", "--out", "{out}"),
        ("--workers",),
        sweep=SWEEP_HEAD + '[grid]\n"run.speed_kmh" = [200.0]\n',
    ),
]


def _limit_memory():
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT_BYTES, MEMORY_LIMIT_BYTES))


def prepare(h: Hostile, tmp: Path) -> list[str]:
    """Write the files a hostile input needs; the command line with its placeholders filled."""
    files = {"case": tmp / "case.toml", "csv": tmp / "profile.csv", "cat": tmp / "catenary.toml",
             "sweep": tmp / "sweep.toml"}
    if h.case is not None:
        files["case"].write_bytes(h.case.encode("latin-1") if "\xe9" in h.case else h.case.encode())
    if h.csv is not None:
        files["csv"].write_bytes(h.csv)
    if h.cat is not None:
        files["cat"].write_text(h.cat)
    if h.sweep is not None:
        files["sweep"].write_text(h.sweep)
    if h.name == "case-fifo":
        os.mkfifo(tmp / "fifo.toml")
    subst = {"{" + k + "}": str(v) for k, v in files.items()} | {"{out}": str(tmp / "out"), "{tmp}": str(tmp)}
    return [next((a.replace(k, v) for k, v in subst.items() if k in a), a) for a in h.argv]


def run_hostile(h: Hostile, tmp: Path) -> subprocess.CompletedProcess:
    argv = prepare(h, tmp)
    return subprocess.run(
        [sys.executable, "-m", "pantohil.orchestrator.cli", *argv],
        cwd=tmp,
        capture_output=True,
        text=True,
        preexec_fn=_limit_memory,
        timeout=600,
        env={**os.environ, "PYTHONWARNINGS": "ignore"},
    )


def test_there_are_at_least_sixty_distinct_hostile_inputs():
    assert len(CASES) >= 60 and len({h.name for h in CASES}) == len(CASES)


def check_refusal(hostile: Hostile, exit_code: int, stderr: str, tmp: Path) -> None:
    lines = stderr.strip().splitlines()
    assert exit_code == 2, stderr
    assert "Traceback" not in stderr and len(lines) == 1, stderr
    for word in hostile.words:
        assert word in lines[0], lines[0]
    out = tmp / "out"
    assert not out.exists() or not any(out.iterdir()), sorted(out.rglob("*"))


@pytest.mark.slow
@pytest.mark.parametrize("hostile", CASES, ids=[h.name for h in CASES])
def test_hostile_input_is_refused_in_one_line(hostile: Hostile, tmp_path: Path):
    proc = run_hostile(hostile, tmp_path)
    check_refusal(hostile, proc.returncode, proc.stderr, tmp_path)


@pytest.mark.parametrize("hostile", CASES, ids=[h.name for h in CASES])
def test_hostile_input_is_refused_by_main(hostile: Hostile, tmp_path: Path):
    code, err = run_main(prepare(hostile, tmp_path))
    check_refusal(hostile, code, err, tmp_path)
