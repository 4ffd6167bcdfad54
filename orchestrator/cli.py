"""The `pantohil` command line.

Exit codes: 0 success; 1 a run that did not converge (diverged, reached its span limit or lost
contact), an FMU failure or a failed write (a full disk); 2 bad input (one line naming the key) or a
missing tool (the C compiler); 3 a lost hardware link; 130 / 143 / 129 a command stopped by SIGINT /
SIGTERM / SIGHUP (a run's folder complete, status `interrupted`; any other command's output not
written). The codes and the errors that carry them: models/errors.py.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import shutil
import signal
import os
import sys
import tempfile
from pathlib import Path

from pantohil.models.case import CaseError, load_case
from pantohil.models.data import catalog
from pantohil.models.errors import ExitCode, FmuFailure, PantohilError
from pantohil.orchestrator.masters import DEFAULT_MASTER, MASTERS

EXIT_BAD_INPUT = int(ExitCode.BAD_INPUT)


MAX_FEM_SPANS = 200  # spans of a fem-sim section
MAX_WORKERS = 256  # LocalCluster worker processes


class _Parser(argparse.ArgumentParser):
    """argparse that reports a bad command line in one line (and exit 2), as every other bad input."""

    def error(self, message: str):
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def number(low: float | None = None, high: float | None = None, integer: bool = False, unit: str = ""):
    """An argparse type: a finite number (an integer if asked) within [low, high]."""

    def parse(text: str):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            kind = "an integer" if integer else "a number"
            raise argparse.ArgumentTypeError(f"expected {kind}, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
        if (low is not None and value < low) or (high is not None and value > high):
            lo = "-inf" if low is None else f"{low:g}"
            hi = "inf" if high is None else f"{high:g}"
            raise argparse.ArgumentTypeError(f"{text} is outside [{lo}, {hi}]{' ' + unit if unit else ''}")
        return value

    parse.__name__ = "integer" if integer else "number"
    return parse


def _add_overwrite(p: argparse.ArgumentParser) -> None:
    p.add_argument("--overwrite", action="store_true", help="replace --out whole if it is not empty")


def _add_case_args(p: argparse.ArgumentParser, optional: bool) -> None:
    if optional:
        p.add_argument("case", nargs="?", type=Path, help="case file (TOML); default: the built-in asm_250 case")
    else:
        p.add_argument("case", type=Path, help="case file (TOML)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a case key, e.g. --set hil.update=span (repeatable)")


def _add_run_command(sub) -> None:
    """`pantohil run` and its options."""
    run = sub.add_parser("run", help="virtual HIL run of a case or of an SSP file written by `pantohil build --ssp`")
    _add_case_args(run, optional=True)
    run.add_argument("--out", type=Path, help="run folder, new or empty (default: runs/<case>-<time>)")
    run.add_argument("--overwrite", action="store_true", help="replace the contents of --out if it is not empty")
    run.add_argument("--master", choices=MASTERS.names(), default=DEFAULT_MASTER,
                     help="co-simulation master: fmpy, pantohil's own (default); libcosim, OSP's; or one another "
                          "package registers (entry points pantohil.masters)")
    run.add_argument("--engine", choices=("fmu", "inprocess"), default="fmu",
                     help="fmu: the FMUs in the master (default); inprocess: the same models stepped in this "
                          "process without the FMI boundary, same result, much faster (virtual HIL only)")
    run.add_argument("--hardware", metavar="HOST:PORT",
                     help="run against a rig controller (or `pantohil rig-emulator`) through the adapter FMU")
    run.add_argument("--paced-by", choices=("model", "rig"),
                     help="with --hardware: who owns the clock (default: the case's link.paced_by, model); rig: "
                          "the adapter takes one rig sample per step, so the rig paces any master")
    run.add_argument("--realtime", action="store_true", help="pace the master against the wall clock at dt")
    run.add_argument("--rt-priority", type=number(0, 99, integer=True), default=50, metavar="P",
                     help="with --realtime or rig-paced: SCHED_FIFO priority if permitted (0: normal scheduling; "
                          "default 50)")
    run.add_argument("--live", nargs="?", const="", metavar="HOST:PORT",
                     help="serve the run's channels to Foxglove over WebSocket while it runs (default "
                          "127.0.0.1:8765; port 0 picks a free one); open docs/foxglove/pantohil-layout.json")
    run.add_argument("--live-wait", action="store_true",
                     help="with --live: start stepping once a viewer has subscribed to a channel")
    run.add_argument("--resume", type=Path, metavar="RUN_FOLDER",
                     help="continue an interrupted run from the last span it saved (its case, overrides and FMUs)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--no-plots", action="store_true",
                     help="leave the figures out of the run folder (summary.json, steady_span.csv, run.mcap stay)")


def _add_watch_command(sub) -> None:
    """`pantohil watch` and its options."""
    watch = sub.add_parser("watch", help="follow a run's log as it is written: convergence, span force, newest "
                                         "values (a terminal view; Foxglove users: `run --live`)")
    watch.add_argument("folder", type=Path, help="run folder (the --out of `pantohil run`)")
    watch.add_argument("--interval", type=number(0.01, 60.0, unit="s"), default=0.5, metavar="S",
                       help="seconds between reads (default 0.5)")
    watch.add_argument("--once", action="store_true", help="show what the log holds now and exit")


def _add_rig_emulator_command(sub) -> None:
    """`pantohil rig-emulator` and its options."""
    emu = sub.add_parser("rig-emulator", help="play a rig controller over UDP for a case (lockstep or on its own "
                                              "clock, fault injection)")
    emu.add_argument("--paced-by", choices=("model", "rig"), default="model",
                     help="model: answer each COMMAND (lockstep, default); rig: a free-running loop sending a "
                          "SAMPLE every tick")
    emu.add_argument("--drift-ppm", type=number(-1e4, 1e4, unit="ppm"), default=0.0, metavar="P",
                     help="rig-paced: the rig clock's rate error against the nominal dt [ppm]")
    emu.add_argument("--jitter-us", type=number(0.0, 1e5, unit="us"), default=0.0, metavar="J",
                     help="rig-paced: each tick moved by a uniform random time in [-J, J] us")
    emu.add_argument("--slow-motion", type=number(1.0, 1000.0), default=1.0, metavar="S",
                     help="rig-paced: a tick every S dt of wall time, the rig still counting dt per tick (tests "
                          "the link without a real-time deadline on a loaded machine; default 1: real time)")
    emu.add_argument("--listen", required=True, metavar="HOST:PORT", help="address to listen on")
    emu.add_argument("--case", type=Path, help="case file (TOML): the pantograph (or mass) on the rig, and its rig "
                                               "file if it names one; default: the built-in case")
    emu.add_argument("--rig", type=Path, metavar="FILE", help="rig file (TOML) whose chain the emulator runs (the "
                                                              "drive's ramp, position loop, load cell...); default: "
                                                              "the case's rig")
    emu.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE")
    for name, what in (("loss", "drop an answer"), ("reorder", "send an answer after the next one"),
                       ("duplicate", "send an answer twice"), ("corrupt", "flip a bit of an answer")):
        emu.add_argument(f"--{name}", type=number(0.0, 1.0), default=0.0, metavar="P", help=f"probability to {what}")
    emu.add_argument(
        "--delay-us", type=number(0.0, 1e6, unit="us"), default=0.0, help="wait this long before each answer [us]"
    )
    emu.add_argument("--seed", type=number(0, 2**31 - 1, integer=True), default=0, help="seed of the fault injection")
    emu.add_argument("--stats", type=Path, help="write the emulator's counters to this JSON file")
    emu.add_argument("--key-file", type=Path, help="pre-shared key: accept and send only datagrams authenticated "
                                                   "with it (HMAC-SHA256)")
    emu.add_argument("--session-timeout-s", type=number(0.01, 3600.0, unit="s"), default=5.0, metavar="S",
                     help="end a session whose master has been silent this long (default 5 s)")
    emu.add_argument(
        "--max-seconds", type=number(0.0, 1e7, unit="s"), help="stop after this long (default: until SIGTERM/Ctrl-C)"
    )
    emu.add_argument("--rt-priority", type=number(0, 99, integer=True), default=49, metavar="P",
                     help="SCHED_FIFO priority if permitted (0: normal scheduling; default 49)")


def _add_rig_identify_command(sub) -> None:
    """`pantohil rig-identify` and its options."""
    ident = sub.add_parser("rig-identify", help="measure a rig's frequency response at a case's kept harmonics with "
                                                "its mass mounted, into a rig file the case compensates with")
    rig = ident.add_mutually_exclusive_group(required=True)
    rig.add_argument("--rig", type=Path, metavar="FILE", help="identify this rig file's chain in process")
    rig.add_argument("--hardware", metavar="HOST:PORT", help="identify the rig controller (or rig-emulator) at "
                                                             "HOST:PORT through the adapter FMU and the UDP link")
    ident.add_argument("--case", type=Path, required=True, help="case file (TOML): the rigid mass mounted, the span "
                                                                "and the kept harmonics (link settings for --hardware)")
    ident.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                       help="override a case key (repeatable)")
    ident.add_argument("--out", type=Path, required=True, help="rig file to write (TOML)")
    ident.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
    ident.add_argument("--amplitude-mm", type=number(0.001, 50.0, unit="mm"), default=1.0, metavar="A",
                       help="multisine amplitude per harmonic times sqrt(harmonics) [mm] (default 1)")
    ident.add_argument("--spans", type=number(1, 64, integer=True), metavar="S",
                       help="spans recorded (default: whole periods of the rig file's clocks, at least 4; 8 "
                            "without a rig file)")
    ident.add_argument("--rt-priority", type=number(0, 99, integer=True), default=50, metavar="P",
                       help="rig-paced: SCHED_FIFO priority while stepping, if permitted (0: normal; default 50)")


def _add_catenary_command(sub) -> None:
    """`pantohil catenary` and its options."""
    catenary = sub.add_parser("catenary", help="form-finding, stiffness and ASM fit of a catenary file (FE model)")
    catenary.add_argument(
        "file", type=Path, help="catenary definition (TOML), e.g. models/data/catenaries/paper_a_stitched.toml"
    )
    catenary.add_argument("--out", type=Path, required=True,
                          help="folder for catenary.json, CSV files and plots (new or empty)")
    _add_overwrite(catenary)


def _add_build_command(sub) -> None:
    """`pantohil build` and its options."""
    build = sub.add_parser("build", help="build and validate the four FMUs of a case (catenary, rig, pantograph, "
                                         "hardware adapter); optionally an SSP file of the virtual HIL system")
    _add_case_args(build, optional=True)
    build.add_argument("--out", type=Path, help="folder for the FMUs (new or empty)")
    _add_overwrite(build)
    build.add_argument("--ssp", type=Path, metavar="FILE.ssp",
                       help="also write the whole system as an SSP file, with an OSP system structure next to it")


def _add_package_command(sub) -> None:
    """`pantohil package` and its options."""
    package = sub.add_parser("package", help="folder for a partner lab: FMUs, SSP/OSP files, runner, reference results")
    _add_case_args(package, optional=True)
    package.add_argument("--out", type=Path, required=True, help="package folder (must not exist or be empty)")
    package.add_argument("--zip", action="store_true", help="also write OUT.zip")
    package.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_fem_sim_command(sub) -> None:
    """`pantohil fem-sim` and its options."""
    fem = sub.add_parser(
        "fem-sim",
        help="conventional simulation of a finite section of N spans of the case's catenary "
        "(the reference for the periodic models, Paper C sec. 6)",
    )
    _add_case_args(fem, optional=False)
    fem.add_argument(
        "--spans", type=number(1, MAX_FEM_SPANS, integer=True), required=True, help="number of spans of the section"
    )
    fem.add_argument(
        "--central",
        type=number(1, MAX_FEM_SPANS, integer=True),
        default=3,
        help="central spans whose statistics are reported (default 3)",
    )
    fem.add_argument("--out", type=Path, required=True, help="run folder (new or empty)")
    _add_overwrite(fem)
    fem.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_compare_command(sub) -> None:
    """`pantohil compare` and its options."""
    compare = sub.add_parser("compare", help="contact force of two run folders overlaid (HIL or fem-sim), 20 Hz")
    compare.add_argument("run_a", type=Path)
    compare.add_argument("run_b", type=Path)
    compare.add_argument("--out", type=Path, required=True, help="folder for compare.json and plots (new or empty)")
    _add_overwrite(compare)


def _add_stability_command(sub) -> None:
    """`pantohil stability` and its options."""
    stab = sub.add_parser(
        "stability",
        help="spectral radius of the virtual HIL iteration over f_max, contact stiffness "
        "and delay, with the best relaxation (Paper D sec. 4, Figs. 5-7)",
    )
    _add_case_args(stab, optional=True)
    stab.add_argument("--update", choices=("step", "span"), help="updating strategy (default: the case's; "
                      "a two-pantograph case: both)")
    stab.add_argument("--fmax", metavar="A:B:N", help="highest frequency of the catenary response [Hz] "
                      "(A:B:N, A:B:N:log, A,B,C or A; default: the case's)")
    stab.add_argument("--contact-stiffness", metavar="A:B:N", help="penalty contact stiffness k_c [N/m] "
                      "(default: the case's)")
    stab.add_argument("--delay", metavar="A:B:N", help="loop delay D [steps], compensated in full; with a rig "
                      "file, the advance D with the rig's chain in the loop (default: the case's latency and advance)")
    stab.add_argument("--relaxation", type=number(0.0, 2.0), help="fix mu_c instead of searching the best one")
    stab.add_argument("--out", type=Path, required=True,
                      help="folder for stability.csv, maps and summary.json (new or empty)")
    _add_overwrite(stab)
    stab.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler (default: a LocalCluster)")
    stab.add_argument(
        "--workers", type=number(1, MAX_WORKERS, integer=True), help="LocalCluster worker processes (default: 2)"
    )
    stab.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_sweep_command(sub) -> None:
    """`pantohil sweep` and its options."""
    sweep = sub.add_parser("sweep", help="a grid over case keys as independent runs on Dask (resumable; CSV, "
                                         "Parquet and plots)")
    sweep.add_argument("file", type=Path, help="sweep file (TOML), e.g. models/data/sweeps/speed_200_300.toml")
    sweep.add_argument("--out", type=Path, required=True, help="sweep folder (a restart into it skips done points)")
    sweep.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler, e.g. tcp://10.0.0.1:8786 "
                                                              "(default: a LocalCluster)")
    sweep.add_argument(
        "--workers", type=number(1, MAX_WORKERS, integer=True), help="LocalCluster worker processes (default: 2)"
    )
    sweep.add_argument("--engine", choices=("inprocess", "fmu"),
                       help="how each point runs: inprocess (the default, or the sweep file's sweep.engine) or "
                            "fmu (the FMUs in the fmpy master); the results are the same")
    sweep.add_argument("--point-plots", action="store_true",
                       help="each point's run folder with its figures too (or the sweep file's sweep.point_plots)")
    sweep.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_export_command(sub) -> None:
    export = sub.add_parser("export", help="a run's per-step history as a table: RUN_FOLDER/steps.parquet (and "
                                           "steps.csv), one row per step, one column per logged signal")
    export.add_argument("folder", type=Path, help="run folder (the --out of `pantohil run`)")
    export.add_argument("--csv", action="store_true", help="also write steps.csv")


def _cmd_export(args) -> int:
    from pantohil.orchestrator.export import export_run

    for path in export_run(args.folder, args.csv):
        print(f"written: {path}")
    return 0


def _add_cases_command(sub) -> None:
    sub.add_parser("cases", help="list the shipped cases, catenaries, rigs and sweeps, which every command takes "
                                 "by name (pantohil run pfem_benchmark_250)")


def _cmd_cases(args) -> int:
    print(catalog.listing())
    return 0


def _add_example_command(sub) -> None:
    """`pantohil example` and its options."""
    example = sub.add_parser("example", help="reproduce a worked example of the thesis")
    example.add_argument("name", choices=["paper-c-appendix"],
                         help="paper-c-appendix: the academic periodic string of Paper C, Appendix A")
    example.add_argument("--out", type=Path, required=True, help="folder for summary.json and a plot (new or empty)")
    _add_overwrite(example)


def _add_direct_command(sub) -> None:
    """`pantohil direct` and its options."""
    direct = sub.add_parser("direct", help="closed-form ASM steady state of a case (Paper A)")
    _add_case_args(direct, optional=True)
    direct.add_argument("--second-pantograph-at", type=number(0.0, 10_000.0, unit="m"), metavar="L",
                        help="spacing of a trailing pantograph [m]: its std and the optimal spacings L_min")
    direct.add_argument(
        "--max-spacing", type=number(0.0, 10_000.0, unit="m"), default=200.0, help="longest L_min listed [m]"
    )
    direct.add_argument("--out", type=Path, help="also write the result as JSON to this file")


def _parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="pantohil", description="HIL pantograph tests against a virtual periodic "
                                                               "catenary, built from FMI 2.0 co-simulation units.")
    sub = ap.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for add_command, handler in COMMANDS:
        known = set(sub.choices)
        add_command(sub)
        (name,) = set(sub.choices) - known  # the command the function added
        sub.choices[name].set_defaults(handler=handler)
    return ap


def _resume_case(args):
    """The case and checkpoint of `run --resume RUN_FOLDER`; the run folder fixes everything else."""
    from pantohil.orchestrator import checkpoint

    given = [flag for flag, value in (("a case file", args.case), ("--set", args.overrides), ("--out", args.out),
                                      ("--hardware", args.hardware),
                                      (f"--master {args.master}", args.master != DEFAULT_MASTER)) if value]
    if given:
        raise CaseError(f"--resume: continues RUN_FOLDER with its own case and FMUs; remove {', '.join(given)}")
    state = checkpoint.load(args.resume)
    meta = state["meta"]
    return load_case(Path(meta["case_file"]), meta["overrides"]), state


def _hardware_endpoint(text: str | None) -> tuple[str, int] | None:
    if text is None:
        return None
    import socket

    from pantohil.fmus.udp_protocol import parse_endpoint

    try:
        hardware = parse_endpoint(text)
        socket.getaddrinfo(hardware[0], hardware[1], socket.AF_INET, socket.SOCK_DGRAM)
    except ValueError as exc:
        raise CaseError(f"--hardware: {exc}") from None
    except OSError as exc:
        raise CaseError(f"--hardware: cannot resolve {hardware[0]!r} ({exc.strerror})") from None
    return hardware


def _check_key_file(case) -> None:
    """link.key_file, read once before anything is written: one line if it is not a usable key."""
    if case.sections.link.key_file:
        from pantohil.fmus.udp_protocol import read_key

        try:
            read_key(case.sections.link.key_file)
        except ValueError as exc:
            raise CaseError(f"link.key_file: {exc}") from None


def _print_run(result, out: Path) -> None:
    print(f"{result.status}: {result.message}")
    cf = result.contact_force
    if cf is not None:
        print(f"contact force: mean {cf.mean_N:.2f} N, std {cf.std_N:.2f} N, 20 Hz std {cf.filtered_20hz.std_N:.2f} N; "
              f"{result.timing.realtime_factor:.1f}x real time while stepping (build {result.timing.build_s:.1f} s)")
        lp = cf.filtered_20hz
        print(f"EN 50367, 20 Hz: mean +- 3 std {lp.stat_min_N:.1f} to {lp.stat_max_N:.1f} N, actual {lp.min_N:.1f} to "
              f"{lp.max_N:.1f} N, " + ("no contact loss for a rigid mass" if cf.contact_loss_pct is None
                                      else f"contact loss {cf.contact_loss_pct:.2f} % (raw)"))
    second = result.second_pantograph
    if second is not None:
        f2 = second["contact_force"]
        print(f"second pantograph ({second['position']}, {second['spacing_m']:g} m): mean {f2['mean_N']:.2f} N, std "
              f"{f2['std_N']:.2f} N, 20 Hz std {f2['filtered_20hz']['std_N']:.2f} N, actual {f2['min_N']:.1f} to "
              f"{f2['max_N']:.1f} N")
    if result.realtime is not None:
        rt = result.realtime
        late = rt["lateness_us"]
        print(f"real time ({rt['scheduling']}): {rt['deadline_misses']} of {rt['steps']} deadlines missed; "
              f"lateness p50 {late['p50']:.0f} us, p99 {late['p99']:.0f} us, max {late['max']:.0f} us")
    if result.link is not None:
        from pantohil.orchestrator.link_diagnostics import LINK_COUNTERS

        print("link: " + ", ".join(f"{k} {result.link[k]}" for k in LINK_COUNTERS))
        if "answer_us" in result.link:
            ln, a = result.link, result.link["answer_us"]
            print(f"rig-paced: {ln['samples']} samples, {ln['answered']} answered; rig ticks {ln['fresh']} fresh, "
                  f"{ln['predicted']} predicted, {ln['uncovered']} uncovered; "
                  f"answer p50 {a['p50']:.0f} us, p99 {a['p99']:.0f} us, max {a['max']:.0f} us")
    print(f"run folder: {out}")
    if result.status in ("link_lost", "interrupted"):
        print(f"pantohil: {'error: ' if result.status == 'link_lost' else ''}{result.message}", file=sys.stderr)


def _cmd_run(args, stop) -> int:
    from pantohil.orchestrator.hil_run import RunInterrupted, run_case
    from pantohil.orchestrator.run_folder import RunFolderError, default_run_folder

    if args.paced_by is not None:
        if args.hardware is None:
            raise CaseError("--paced-by: only with --hardware (a virtual run has no rig clock)")
        args.overrides = [*args.overrides, f"link.paced_by={args.paced_by}"]
    with contextlib.ExitStack() as cleanup:
        system = None
        resume = None
        if args.resume is not None:
            case, resume = _resume_case(args)
            args.out = args.resume
        elif args.case is not None and args.case.suffix == ".ssp":
            from pantohil.builder.ssp import read_ssp, ssp_case, temporary_dir

            if any(not o.startswith("run.") for o in args.overrides):
                raise CaseError("--set: an SSP file fixes its system; only run.* keys can be overridden")
            if not args.case.is_file():
                raise CaseError(f"SSP file {args.case} does not exist or is not a file")
            unpacked = temporary_dir("pantohil_ssp_")
            cleanup.callback(shutil.rmtree, unpacked, True)
            system = read_ssp(args.case, unpacked)  # SspError: bad input, exit 2
            case = ssp_case(args.case, system, args.overrides)  # the case as the SSP's values make it, validated
        else:
            case = load_case(args.case, args.overrides)
        checkpoint_info = None  # an SSP run saves no checkpoint: its system lives in a temporary folder
        if resume is not None:
            checkpoint_info = {k: resume["meta"][k] for k in ("case_file", "overrides")}
        elif system is None:
            checkpoint_info = {"case_file": str(Path(case.source).resolve()), "overrides": list(args.overrides)}
        hardware = _hardware_endpoint(args.hardware)
        if hardware is not None:
            _check_key_file(case)
        if args.live_wait and args.live is None:
            raise CaseError("--live-wait: needs --live")
        live = _live_endpoint(args.live) if args.live is not None else None
        out = args.out or default_run_folder(case.name)
        try:
            result = run_case(case, out, progress=not args.quiet, master_kind=args.master, system=system,
                              hardware=hardware, realtime=args.realtime, rt_priority=args.rt_priority,
                              live=live, live_wait=args.live_wait, checkpoint_info=checkpoint_info, resume=resume,
                              overwrite=args.overwrite, stop=stop, engine=args.engine, plots=not args.no_plots)
        except RunFolderError as exc:
            raise CaseError(f"--out: {exc}") from None
        except RunInterrupted as exc:
            print(f"pantohil: {exc}", file=sys.stderr)
            return 128 + stop.signum
    _print_run(result, out)
    return result.exit_code


def _live_endpoint(value: str) -> tuple[str, int]:
    """--live HOST:PORT, checked before anything is written: the host resolves and the port is free."""
    import socket

    from pantohil.orchestrator.live import parse_live

    try:
        host, port = parse_live(value)
    except ValueError as exc:
        raise CaseError(str(exc)) from None
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            probe.bind((host, port))
    except OSError as exc:
        raise CaseError(f"--live: cannot listen on {host}:{port} ({exc.strerror})") from None
    return host, port


def _cmd_watch(args) -> int:
    from pantohil.orchestrator.watch import watch

    try:
        return watch(args.folder, args.interval, args.once)
    except KeyboardInterrupt as exc:
        return _interrupt_code(exc)


def _rig_file_arg(path: Path | None, option: str = "--rig"):
    """A rig file named on the command line, validated (one line naming the key if it is bad)."""
    if path is None:
        return None
    from pantohil.models.rig.rig_file import RigFileError, load_rig_file

    try:
        return load_rig_file(catalog.resolve(path, "rig"))
    except RigFileError as exc:
        raise CaseError(f"{option}: {exc}") from None


def _cmd_emulator(args) -> int:
    from pantohil.fmus.udp_protocol import parse_endpoint, read_key
    from pantohil.orchestrator.rig_emulator import Faults, RigEmulator, RigPacing

    case = load_case(args.case, args.overrides)
    rig = _rig_file_arg(args.rig)
    if args.stats is not None:  # written at the end of every session: checked before the first
        from pantohil.orchestrator.output_paths import check_output_file

        check_output_file(args.stats, "--stats")
    try:
        listen = parse_endpoint(args.listen, listening=True)
        faults = Faults(args.loss, args.reorder, args.duplicate, args.corrupt, args.delay_us, args.seed)
        pacing = RigPacing(args.paced_by, args.drift_ppm, args.jitter_us, args.seed, args.slow_motion)
    except ValueError as exc:
        raise CaseError(f"--listen: {exc}" if "HOST:PORT" in str(exc) else str(exc)) from None
    try:
        key = read_key(str(args.key_file)) if args.key_file is not None else None
    except ValueError as exc:
        raise CaseError(f"--key-file: {exc}") from None
    try:
        emulator = RigEmulator(case, listen, faults, args.stats, key, args.session_timeout_s,
                               announce=lambda line: print(line, flush=True), pacing=pacing, rig=rig)
    except OSError as exc:
        raise CaseError(f"--listen: cannot listen on {args.listen}: {exc.strerror}") from None
    from pantohil.orchestrator.pacing import set_realtime_priority

    scheduling = set_realtime_priority(args.rt_priority)
    chain = f" with rig {emulator.rig_spec.name}" if emulator.rig_spec is not None else ""
    print(f"rig emulator for {case.name}{chain} listening on {emulator.address[0]}:{emulator.address[1]} "
          f"({args.paced_by}-paced, {scheduling})", flush=True)
    emulator.serve(args.max_seconds)
    return 0


def _cmd_identify(args) -> int:
    from pantohil.orchestrator.rig_identify import IdentifyRequest, identify

    case = load_case(args.case, args.overrides)
    rig = _rig_file_arg(args.rig)
    hardware = _hardware_endpoint(args.hardware)
    if hardware is not None:
        _check_key_file(case)
    request = IdentifyRequest(case, args.out, rig, hardware, args.amplitude_mm * 1e-3, args.spans, args.overwrite,
                              args.rt_priority)
    identify(request, announce=lambda line: print(line, flush=True))  # LinkLost: exit 3; IdentificationError: 1
    return 0


def _cmd_build(args) -> int:
    from pantohil.builder.build_fmus import build_case_fmus
    from pantohil.orchestrator.run_topology import delay_plan
    from pantohil.orchestrator.output_paths import atomic_output_folder, check_output_file

    case = load_case(args.case, args.overrides)
    if args.out is None and args.ssp is None:
        raise CaseError("build: give --out DIR, --ssp FILE.ssp, or both")
    if args.ssp is not None:
        check_output_file(args.ssp, "--ssp")
    plan = delay_plan(case)
    pair = case.sections.second_pantograph is not None
    with contextlib.ExitStack() as stack:
        if args.out is not None:
            # the adapter is the rig link of one pantograph (a pair on a rig is not built yet)
            names = ("catenary", "rig", "pantograph") + (() if pair else ("adapter",))
            folder = stack.enter_context(atomic_output_folder(args.out, "--out", args.overwrite))
        else:
            from pantohil.builder.system import FMU_NAMES

            names, folder = FMU_NAMES, Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="pantohil_build_")))
        fmus = build_case_fmus(case, folder, plan["delay_steps"], names)
        bad = _validate_built(fmus, args.out)
        if args.ssp is not None:
            _write_ssp(case, fmus, args)
    return 1 if bad else 0


def _validate_built(fmus: dict, out: Path | None) -> int:
    """fmpy's validation of the built FMUs (printed under their final names with --out); problems found."""
    from fmpy.validation import validate_fmu

    bad = 0
    for path in fmus.values():
        problems = validate_fmu(str(path))
        bad += len(problems)
        if out is not None:
            print(f"{out / Path(path).name}: {'valid' if not problems else '; '.join(problems)}")
    return bad


def _write_ssp(case, fmus: dict, args) -> None:
    from pantohil.builder.system import FMU_NAMES
    from pantohil.orchestrator.package import make_ssp

    in_ssp = {n: fmus[n] for n in FMU_NAMES}  # the virtual HIL: the adapter is for rigs
    ssp = make_ssp(case, in_ssp, args.ssp, args.overrides)
    second = "; pantograph_2 a second instance of pantograph" if case.sections.second_pantograph is not None else ""
    print(f"{ssp}: SSP of {len(in_ssp)} FMUs ({', '.join(in_ssp)}{second}); OSP system structure in "
          f"{ssp.parent / (ssp.stem + '_osp')}")


def _cmd_catenary(args) -> int:
    from pantohil.orchestrator.catenary_report import catenary_report

    s = catenary_report(catalog.resolve(args.file, "catenary"), args.out, args.overwrite)  # CatenaryError: exit 2
    fit = s["asm_fit"]
    print(f"{s['name']}: {len(s['dropper_lengths_m'])} droppers, lengths {min(s['dropper_lengths_m']):.3f}-"
          f"{max(s['dropper_lengths_m']):.3f} m, tensions >= {s['min_dropper_tension_N']:.1f} N, height error "
          f"{s['max_height_error_m'] * 1e3:.2e} mm")
    print(f"vertical stiffness: mean {s['mean_vertical_stiffness_N_m']:.1f} N/m ({s['min_vertical_stiffness_N_m']:.0f}-"
          f"{s['max_vertical_stiffness_N_m']:.0f}); ASM fit: kbar {fit['support_stiffness_N_m2']:.2f} N/m^2, "
          + ", ".join(f"mu({b['band_hz'][0]:g}-{b['band_hz'][1]:g} Hz) {b['density_kg_m']:.4f}" for b in fit["bands"])
          + " kg/m")
    print(f"written to {args.out} in {s['elapsed_s']:.1f} s")
    return 0


def _cmd_package(args) -> int:
    import shutil

    from pantohil.orchestrator.package import make_package

    case = load_case(args.case, args.overrides)
    try:
        out = make_package(case, args.out, args.overrides, progress=not args.quiet)
    except KeyboardInterrupt as exc:
        print(f"pantohil: package {_interrupted_by(exc)}: no package written", file=sys.stderr)
        return _interrupt_code(exc)
    if args.zip:
        archive = shutil.make_archive(str(out), "zip", root_dir=out.parent, base_dir=out.name)
        print(f"archive: {archive}")
    print(f"partner package: {out} (see its README.md)")
    return 0


def _cmd_direct(args) -> int:
    from pantohil.orchestrator.direct import direct_solution

    case = load_case(args.case, args.overrides)
    if args.second_pantograph_at is not None and args.second_pantograph_at <= 0:
        raise CaseError(f"--second-pantograph-at: must be > 0 m (got {args.second_pantograph_at:g})")
    second = case.sections.second_pantograph
    if args.second_pantograph_at is None and second is not None:  # the closed form takes the first as leading
        args.second_pantograph_at = second.spacing_m
    if args.out:
        from pantohil.orchestrator.output_paths import check_output_file

        check_output_file(args.out, "--out")
    res = direct_solution(case, args.second_pantograph_at, args.max_spacing)
    s = res["single"]
    print(
        f"{case.name}: {res['speed_kmh']:.0f} km/h, {res['harmonics']} harmonics up to {res['max_frequency_hz']:.2f} Hz"
    )
    print(
        f"single pantograph: mean {s['mean_N']:.2f} N, std {s['std_N']:.3f} N "
        f"(harmonics <= 20 Hz: {s['std_20hz_N']:.3f} N)"
    )
    if "two_pantographs" in res:
        t = res["two_pantographs"]
        print(f"two pantographs {t['spacing_m']:g} m apart: leading std {t['leading_std_N']:.3f} N, "
              f"trailing std {t['trailing_std_N']:.3f} N")
        for h in t["optimal_spacings_m"]:
            ls = ", ".join(f"{x:.1f}" for x in h["L_min_m"])
            print(
                f"  L_min for harmonic {h['harmonic']} ({h['frequency_hz']:.2f} Hz, "
                f"|Z| {h['z0_amplitude_m'] * 1e3:.2f} mm): {ls} m"
            )
    if args.out:
        from pantohil.orchestrator.report import write_json_atomic

        write_json_atomic(args.out, res)
    return 0


def _cmd_fem_sim(args) -> int:
    from pantohil.orchestrator.fem_sim import run_fem_sim

    case = load_case(args.case, args.overrides)
    s = run_fem_sim(case, args.spans, args.out, args.central, progress=not args.quiet, overwrite=args.overwrite)
    c = s["contact_force"]
    print(f"{s['n_spans']} spans, central {s['central_spans']}: mean {c['mean_N']:.2f} N, std {c['std_N']:.2f} N "
          f"(20 Hz), max {c['max_N']:.1f} N, min {c['min_N']:.1f} N, contact loss {c['contact_loss_pct']:.2f} %; "
          f"{s['timing']['wall_s']:.1f} s")
    second = s.get("second_pantograph")
    if second is not None:
        c = second["contact_force"]
        print(f"second pantograph, {second['position']} {second['spacing_m']:g} m: mean {c['mean_N']:.2f} N, std "
              f"{c['std_N']:.2f} N (20 Hz), max {c['max_N']:.1f} N, min {c['min_N']:.1f} N, contact loss "
              f"{c['contact_loss_pct']:.2f} %")
    print(f"run folder: {args.out}")
    return 0


def _cmd_compare(args) -> int:
    from pantohil.orchestrator.fem_sim import compare_runs

    r = compare_runs(args.run_a, args.run_b, args.out, args.overwrite)
    if r["std_difference_pct"] is None:  # the second run's force does not vary: no % of its std
        print(f"std {r['a']['std_N']:.2f} N ({r['a']['label']}) vs {r['b']['std_N']:.2f} N ({r['b']['label']}, "
              f"constant); rms difference {r['rms_difference_N']:.2f} N")
        return 0
    print(f"std {r['a']['std_N']:.2f} N ({r['a']['label']}) vs {r['b']['std_N']:.2f} N ({r['b']['label']}): "
          f"{r['std_difference_pct']:+.2f} %; rms difference {r['rms_difference_N']:.2f} N = "
          f"{r['rms_difference_pct_of_std_b']:.2f} % of the second std")
    second = r.get("second_pantograph")
    if second is not None and second["std_difference_pct"] is not None:
        print(f"second pantograph: std {second['a']['std_N']:.2f} N vs {second['b']['std_N']:.2f} N: "
              f"{second['std_difference_pct']:+.2f} %; rms difference {second['rms_difference_N']:.2f} N = "
              f"{second['rms_difference_pct_of_std_b']:.2f} % of the second std")
    return 0


def _cmd_stability(args) -> int:
    from pantohil.orchestrator.stability_run import parse_range, run_stability

    f_max = parse_range(args.fmax, "--fmax")
    stiffness = parse_range(args.contact_stiffness, "--contact-stiffness", positive=True)
    delays = parse_range(args.delay, "--delay", integer=True)
    try:
        s = run_stability(args.case, args.overrides, args.out, args.update, f_max, stiffness, delays,
                          args.relaxation, args.scheduler, args.workers, progress=not args.quiet,
                          overwrite=args.overwrite)
    except KeyboardInterrupt as exc:
        print(f"pantohil: stability {_interrupted_by(exc)}: no map written", file=sys.stderr)
        return _interrupt_code(exc)
    except RuntimeError as exc:  # rows that failed on a worker: the others are in stability.csv
        print(f"pantohil: error: {exc}", file=sys.stderr)
        return 1
    print(f"{s['points']} points ({s['update']}), {s['stable_points']} stable, lowest spectral radius "
          f"{s['min_spectral_radius']:.4f}; {s['timing']['map_s']:.1f} s on {s['workers']} workers")
    if "verdict" in s:
        print(f"two pantographs, L = {s['second_pantograph']['spacing_m']:g} m {s['second_pantograph']['position']}: "
              f"{s['verdict']}")
    print(f"written to {args.out}")
    return 0


def _cmd_sweep(args) -> int:
    from pantohil.orchestrator.output_paths import check_output_folder
    from pantohil.orchestrator.sweep import run_sweep

    check_output_folder(args.out, "--out", keep_if="sweep.json")  # a sweep folder continues the same sweep
    try:
        s = run_sweep(catalog.resolve(args.file, "sweep"), args.out, args.scheduler, args.workers,
                      progress=not args.quiet, engine=args.engine, point_plots=True if args.point_plots else None)
    except KeyboardInterrupt as exc:
        print(f"pantohil: sweep {_interrupted_by(exc)}: the points done so far are in {args.out / 'results.csv'}; "
              "run the same command again to run the others", file=sys.stderr)
        return _interrupt_code(exc)
    print(f"{s['name']}: {s['points']} points ({s['skipped_done']} already done, {s['ran']} run): "
          + ", ".join(f"{k} {v}" for k, v in sorted(s["statuses"].items())) + f"; {s['wall_s']:.1f} s on "
          f"{s['workers']} workers")
    print(f"results: {args.out / 'results.csv'} and results.parquet")
    return 0 if "error" not in s["statuses"] else 1


def _cmd_example(args) -> int:
    from pantohil.models.catenary.pfem.paper_c_appendix import paper_c_appendix
    from pantohil.orchestrator.report import plot_force_history, write_json_atomic

    from pantohil.orchestrator.output_paths import atomic_output_folder

    with atomic_output_folder(args.out, "--out", args.overwrite) as part:
        res = paper_c_appendix()
        write_json_atomic(part / "summary.json", res)
        plot_force_history(part / "contact_force.png", res["force_history_N"], res["contact_points"],
                           "Paper C Appendix A: contact force of the simulated HIL test (Fig. A.4)")
    print(f"first forces {', '.join(f'{f:.4f}' for f in res['first_forces_N'][:2])} N; steady force "
          f"{' '.join(f'{f:.4f}' for f in res['steady_force_N'])} N after {res['blocks_to_converge']} blocks")
    print(f"written to {args.out}")
    return 0


def _add_optimise_command(sub) -> None:
    """`pantohil optimise` and its options."""
    opt = sub.add_parser("optimise", help="catenary design of least contact-force std (0-20 Hz) over the contact-wire "
                                          "heights at the droppers or the dropper positions (Paper D sec. 5.3)")
    opt.add_argument("catenary_file", type=Path, help="catenary file (TOML) of the nominal design, symmetric span")
    opt.add_argument("--case", type=Path, required=True,
                     help="case whose pantograph, step and PFEM settings evaluate each design (e.g. pfem_stitched_250)")
    opt.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                     help="override a case key (repeatable)")
    opt.add_argument("--vary", required=True, metavar="heights|spacing",
                     help="heights: the contact-wire heights at the droppers; spacing: the dropper positions")
    opt.add_argument("--speeds", type=number(1.0, 600.0, unit="km/h"), nargs="+", default=[], metavar="KMH",
                     help="speeds of the objective [km/h] (default: the case's)")
    opt.add_argument("--weights", type=number(0.0, 1e6), nargs="+", default=[], help="a weight per speed")
    opt.add_argument("--max-height-deviation", type=number(1e-4, 1.0, unit="m"), default=0.1,
                     help="largest change of a height at a dropper [m] (default 0.1)")
    opt.add_argument("--min-dropper-length", type=number(0.0, 10.0, unit="m"), default=0.3,
                     help="shortest dropper [m] (default 0.3)")
    opt.add_argument("--min-dropper-spacing", type=number(0.01, 100.0, unit="m"), default=3.0,
                     help="shortest distance between droppers [m] (default 3)")
    opt.add_argument("--max-designs", type=number(2, 100000, integer=True), default=200,
                     help="most designs evaluated (default 200)")
    opt.add_argument("--max-minutes", type=number(0.1, 10080.0, unit="min"), default=13.5,
                     help="most minutes of search; the best design found by then is kept and confirmed (default 13.5)")
    opt.add_argument("--explore", type=number(0, 10000, integer=True), default=24,
                     help="designs of a first Sobol sample of the limits, evaluated in parallel (default 24)")
    opt.add_argument("--starts", type=number(1, 100, integer=True), default=1,
                     help="descents: from the best designs evaluated by then (default 1)")
    opt.add_argument("--extremes", default="nominal", metavar="nominal|free",
                     help="nominal: no design's max above the nominal design's nor its min below (Paper D Table 2's "
                          "pattern, the default); free: the std alone")
    opt.add_argument("--out", type=Path, required=True, help="folder (the same command continues a folder it started)")
    opt.add_argument("--overwrite", action="store_true", help="start again in a used folder")
    opt.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler (default: a LocalCluster)")
    opt.add_argument("--workers", type=number(1, MAX_WORKERS, integer=True), help="LocalCluster workers (default: 2)")
    opt.add_argument("--no-confirm", action="store_true",
                     help="skip the virtual HIL runs with dropper slackening of the nominal and optimised designs")
    opt.add_argument("--quiet", action="store_true", help="no progress bar")


def _cmd_optimise(args) -> int:
    from pantohil.models.catenary.design import DesignLimits
    from pantohil.orchestrator.optimise import OptimiseRequest
    from pantohil.orchestrator.optimise_run import run_optimise

    limits = DesignLimits(args.max_height_deviation, args.min_dropper_length, args.min_dropper_spacing)
    request = OptimiseRequest(catalog.resolve(args.catenary_file, "catenary"), catalog.resolve(args.case, "case"),
                              tuple(args.overrides), args.vary, tuple(args.speeds), tuple(args.weights), limits,
                              args.max_designs, args.explore, args.starts, args.extremes,
                              args.max_minutes)
    try:
        s = run_optimise(request, args.out, args.scheduler, args.workers, args.overwrite, not args.quiet,
                         not args.no_confirm)
    except KeyboardInterrupt as exc:
        print(f"pantohil: optimise {_interrupted_by(exc)}: the designs evaluated are in {args.out}; run the same "
              "command again to continue", file=sys.stderr)
        return _interrupt_code(exc)
    for sp in s["speeds"]:
        n, o = sp["nominal"], sp["optimised"]
        print(f"{sp['speed_kmh']:g} km/h: std {n['std_N']:.2f} -> {o['std_N']:.2f} N "
              f"({-sp['std_reduction_percent']:+.2f} %), max {n['max_N']:.1f} -> {o['max_N']:.1f} N, "
              f"min {n['min_N']:.1f} -> {o['min_N']:.1f} N (PFEM steady state, {n['slack_pairs']} -> "
              f"{o['slack_pairs']} slack dropper instants)")
    c = s["nonlinear_confirmation"]
    if c:
        print(f"virtual HIL with dropper slackening: std {c['nominal']['std_N']:.2f} -> "
              f"{c['optimised']['std_N']:.2f} N ({-c['std_reduction_percent']:+.2f} %; {c['nominal']['status']}, "
              f"{c['optimised']['status']})")
    print(f"{s['designs']['in_journal']} designs ({s['designs']['evaluated_now']} now) in "
          f"{s['timing']['wall_s']:.0f} s on {s['workers']} workers; {s['stopped']}")
    print(f"written to {args.out} (optimised_catenary.toml, optimised_case.toml, optimise.png)")
    return 0


COMMANDS = (  # each command's parser and its handler, in the order of `pantohil --help`
    (_add_run_command, _cmd_run),
    (_add_watch_command, _cmd_watch),
    (_add_rig_emulator_command, _cmd_emulator),
    (_add_rig_identify_command, _cmd_identify),
    (_add_catenary_command, _cmd_catenary),
    (_add_build_command, _cmd_build),
    (_add_package_command, _cmd_package),
    (_add_fem_sim_command, _cmd_fem_sim),
    (_add_compare_command, _cmd_compare),
    (_add_stability_command, _cmd_stability),
    (_add_sweep_command, _cmd_sweep),
    (_add_optimise_command, _cmd_optimise),
    (_add_example_command, _cmd_example),
    (_add_direct_command, _cmd_direct),
    (_add_cases_command, _cmd_cases),
    (_add_export_command, _cmd_export),
)


def main(argv: list[str] | None = None) -> int:
    """The `pantohil` command: parse the arguments, run the command, return its exit code.

    SIGINT, SIGTERM and SIGHUP end every command the same way: one line, exit 128 + the signal; a run
    ends at a step boundary with a complete record, any other command at once, leaving no output half
    written (orchestrator/stopping.py)."""
    from pantohil.models.scratch import process_scratch
    from pantohil.orchestrator.stopping import stop_on_signals

    # every temporary file of the command (FMU builds, extracted FMUs, unpacked SSP files) in one folder of
    # this process: removed at its exit, or by the next command if this one is killed
    previous, tempfile.tempdir = tempfile.tempdir, str(process_scratch())
    try:
        with stop_on_signals(raising=True) as stop:
            args = _parser().parse_args(argv)
            if args.command == "run":  # a stop signal ends the run at a step boundary with a complete record
                stop.defer()
                return _guarded(lambda a: _cmd_run(a, stop), args)
            return _guarded(args.handler, args)
    finally:
        tempfile.tempdir = previous


def _guarded(handler, args) -> int:
    """Every error pantohil raises on purpose: one line and its own exit code (models/errors.py: 2 bad
    input or a missing tool, 1 a failure, 3 a lost link); a failed write: one line and exit 1; a stop
    signal: one line and exit 128 + the signal."""
    try:
        return handler(args)
    except PantohilError as exc:
        prefix = "an FMU failed: " if isinstance(exc, FmuFailure) else ""
        print(f"pantohil: error: {prefix}{exc.line()}", file=sys.stderr)
        return int(exc.exit_code)
    except BrokenPipeError:  # the reader of stdout went away (`pantohil cases | head`): nothing more to say
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # so that the interpreter's last flush does not fail again
        return 0
    except KeyboardInterrupt as exc:  # the output mechanisms have removed what they had not finished
        print(f"pantohil: {args.command} {_interrupted_by(exc)}", file=sys.stderr)
        return _interrupt_code(exc)
    except Exception as exc:  # a failed write, or an FMU failure fmpy reports: one line, what was written stays
        code = _failure_code(exc)
        if code is None:
            raise
        return code


def _interrupt_code(exc: BaseException) -> int:
    """The exit code of a command a stop signal ended: 128 + the signal."""
    from pantohil.orchestrator.stopping import exit_code, signal_of

    return exit_code(signal_of(exc))


def _interrupted_by(exc: BaseException) -> str:
    from pantohil.orchestrator.stopping import signal_of

    return f"interrupted by {signal.Signals(signal_of(exc)).name}"


def _failure_code(exc: Exception) -> int | None:
    """One line on stderr and the exit code of a known failure that is not a PantohilError (a full disk, an
    FMU call fmpy reports as failed); None for an unexpected one (a bug)."""
    from pantohil.orchestrator.output_paths import write_failure

    failure = write_failure(exc)
    if failure is not None:  # a full disk, a file size limit: what was written stays readable
        print(f"pantohil: error: {failure}", file=sys.stderr)
        return int(ExitCode.FAILED)
    fmi1 = sys.modules.get("fmpy.fmi1")  # not imported: not raised
    if fmi1 is not None and isinstance(exc, fmi1.FMICallException):
        print(f"pantohil: error: an FMU failed: {exc}", file=sys.stderr)
        return int(ExitCode.FAILED)
    return None


if __name__ == "__main__":
    sys.exit(main())
