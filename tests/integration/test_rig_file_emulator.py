"""Rig files over the wire (issues 16 and 17): `pantohil rig-emulator --rig FILE` runs the rig file's
chain (the model code of the in-process loop and the rig FMU), and `pantohil rig-identify` measures a
rig's response with the case's mass mounted, in process or through the adapter FMU and real UDP
sockets on loopback, into a rig file a case compensates with."""
import socket
from pathlib import Path

import numpy as np
import pytest

from conftest import CASES_DIR, PATIENT_LINK, ROOT, load_run, pantohil
from test_hardware import Emulator, rel_rms
from pantohil.fmus import udp_protocol as proto
from pantohil.models.case import load_case
from pantohil.models.hil.rig_loop import run_loop
from pantohil.models.metrics import lowpass_periodic
from pantohil.models.rig.drive_chain import frequency_response
from pantohil.models.rig.identification import response_errors
from pantohil.models.rig.rig_file import load_rig_file

RIGS = ROOT / "models" / "data" / "rigs"
CASE_B = CASES_DIR / "paper_b_mass_300.toml"
CASE_D = CASES_DIR / "paper_d_mass_300.toml"


def _errors(rig_file: Path, case) -> dict:
    """The identified file's gains against the rig model's own frequency_response."""
    spec = load_rig_file(rig_file)
    gz, gf = frequency_response(spec, case.dt_s, case.samples_per_span, case.n_harmonics)
    return response_errors(spec.measured, gz[1:], gf[1:])


def _figures(err: dict) -> str:
    return "; ".join(f"{p}: |G| {100 * e['max_magnitude_error']:.2g} %, arg {e['max_phase_error_deg']:.2g} deg"
                     for p, e in err.items())


# (case, rig file, limit on the difference to the in-process loop as it starts, its measured figure)
LOOP_CASES = [
    pytest.param("paper_b_mass_300", "paper_b", 0.005, marks=pytest.mark.extended),        # 0.023 %
    ("paper_b_pantograph_300", "paper_b", 0.005),                                           # 0.015 %
    pytest.param("paper_b_pantograph_250", "paper_b", 0.005, marks=pytest.mark.extended),  # 0.0066 %
    ("paper_d_mass_300", "paper_d", 0.015),  # 1.05 %: the drive's clock phase, see the docstring
    pytest.param("paper_d_mass_250", "paper_d", 0.005, marks=pytest.mark.extended),        # 0.30 %
]


def _in_process(case, rig_lead_steps: int):
    """run_loop of the case (a PFEM case on the operators its hardware run built into the cache)."""
    result = run_loop(case, rig_lead_steps=rig_lead_steps)
    assert result.status == "converged"
    return result


def _run_against_the_emulator(tmp_path: Path, case_file: Path, rig: str):
    """`pantohil run CASE --hardware` against `rig-emulator --rig RIG` in lockstep: (summary, span, stats)."""
    emu = Emulator(tmp_path, "--rig", str(RIGS / f"{rig}.toml"), "--case", str(case_file))
    out = tmp_path / "hardware"
    try:
        proc = pantohil("run", str(case_file), "--hardware", emu.address, "--out", str(out), "--quiet",
                        "--set", PATIENT_LINK)
    finally:
        stats = emu.stop()
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary, span = load_run(out)
    return summary, span, stats


@pytest.mark.network
@pytest.mark.slow
@pytest.mark.parametrize("name,rig,limit", LOOP_CASES)
def test_the_emulator_runs_a_rig_file_as_the_in_process_loop(tmp_path, name, rig, limit):
    """Issue 17 / issue 16 acceptance 5: each validation of acceptance 2 against `rig-emulator --rig`
    its rig file in lockstep (as fast as possible) converges to the span of the in-process virtual loop
    through the same chain, compensated the same way, within 0.5 % RMS of the std in the kept band (25 Hz;
    figures in docs/validation.md). Above it the span holds the drive's staircase (N_com = 8 for Paper B,
    5 for Paper D), which the iteration does not control and which follows the phase of the drive's clock
    against the span: the link's loop is 3 connections, the virtual one's 4, so the emulated rig runs one
    step ahead. With the in-process rig started one step earlier (run_loop's rig_lead_steps=1) the spans
    agree within 0.5 % (Paper D: 6e-4 %, unfiltered too). Paper D's in-band span itself depends on that
    phase (its linear chain as well, so not the drive's limits): the PFEM operator is not circulant and
    maps the staircase's force above the band into heights in it. paper_d_mass_300 as the in-process loop
    starts is 1.05 % from the hardware run, and the 5 phases of its 10 ms control loop spread up to 1.74 %;
    that comparison is bounded per case (LOOP_CASES), at 1.5 % for it."""
    case_file = CASES_DIR / f"{name}.toml"
    summary, span, stats = _run_against_the_emulator(tmp_path, case_file, rig)
    assert summary["converged"] and summary["link"]["lost"] == 0 and summary["link"]["limited"] == 0
    # the chain's latency, reported by the emulator's STATUS
    assert summary["link"]["rig_latency_steps"] == {"paper_b": 18, "paper_d": 10}[rig]
    assert stats["commands"] == summary["link"]["sent"]
    case = load_case(case_file)
    f_max, dt = case.values["hil"]["max_frequency_hz"], case.dt_s
    hardware = lowpass_periodic(span[:, 3], dt, f_max)
    diffs = {}
    for lead in (0, 1):
        virtual = _in_process(case, lead)
        diffs[lead] = rel_rms(hardware, lowpass_periodic(virtual.force_N, dt, f_max))
        print(f"\n{name} through the emulated {rig} rig vs the in-process loop, its rig {lead} step(s) ahead: "
              f"{100 * diffs[lead]:.3g} % RMS of the std below {f_max:g} Hz, "
              f"{100 * rel_rms(span[:, 3], virtual.force_N):.3g} % unfiltered ({summary['spans']} and "
              f"{virtual.spans} spans)")
    assert diffs[1] <= 0.005 and diffs[0] <= limit


@pytest.mark.network
@pytest.mark.slow
@pytest.mark.parametrize("rig,case_file", [("paper_b", CASE_B), ("paper_d", CASE_D)])
def test_identification_through_the_adapter_and_udp(tmp_path, rig, case_file):
    """Issue 16 acceptance 3: the emulated Paper B and Paper D rigs, the case's 5.29 kg mass mounted,
    identified through the adapter FMU and the UDP link: within 2 % and 2 deg of the rig model's own
    response at every kept harmonic. For Paper B (an ASM case) a run compensated with the identified file
    equals one compensated with the model within 0.5 % RMS of the std."""
    emu = Emulator(tmp_path, "--rig", str(RIGS / f"{rig}.toml"), "--case", str(case_file))
    out = tmp_path / "identified.toml"
    try:
        proc = pantohil("rig-identify", "--hardware", emu.address, "--case", str(case_file), "--out", str(out),
                        "--set", PATIENT_LINK)
    finally:
        stats = emu.stop()
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert stats["sessions"] == 1 and stats["session_log"][0]["end"] == "bye"
    case = load_case(case_file)
    err = _errors(out, case)
    print(f"\n{rig} identified over UDP: {_figures(err)}")
    for path in ("height", "force"):
        assert err[path]["max_magnitude_error"] < 0.02 and err[path]["max_phase_error_deg"] < 2.0
    if rig == "paper_b":
        exact = run_loop(case)
        identified = run_loop(load_case(case_file, [f"rig.file=\"{out}\""]))
        assert exact.status == identified.status == "converged"
        diff = rel_rms(identified.force_N, exact.force_N)
        print(f"compensated with the identified file vs the model: {100 * diff:.3g} % RMS of the std")
        assert diff < 0.005


@pytest.mark.network
@pytest.mark.realtime
def test_identification_of_a_rig_paced_emulator(tmp_path):
    """The rig-paced emulator runs the same chain from its own clock: identified through the adapter
    (one answer per rig sample), the Paper B rig is within 2 % and 2 deg of its model. The rig's clock runs
    in slow motion (a tick every 5 dt of wall time), so that an answer has 5 ms, not 1 ms, on a loaded
    machine: the test is of the link and the identification, not of the machine's speed (real time:
    tests/benchmarks/bench_rig_paced.py). The adapter sends the excitation's next heights as its horizon,
    so a late answer costs the record nothing; ticks no answer covered (the actuator held) are kept out of
    the record, or at most 1 % of it taken; more is exit 1 and nothing written: two more tries."""
    emu = Emulator(tmp_path, "--paced-by", "rig", "--slow-motion", "5", "--rig", str(RIGS / "paper_b.toml"),
                   "--case", str(CASE_B))
    out = tmp_path / "identified.toml"
    try:
        for _ in range(3):
            proc = pantohil("rig-identify", "--hardware", emu.address, "--case", str(CASE_B), "--out", str(out),
                            "--set", "link.paced_by=\"rig\"")
            if proc.returncode != 1 or "held an old height" not in proc.stderr:
                break
            assert not out.exists()
    finally:
        emu.stop()
    assert proc.returncode == 0, proc.stdout + proc.stderr
    err = _errors(out, load_case(CASE_B))
    print(f"\npaper_b identified rig-paced: {_figures(err)}")
    for path in ("height", "force"):
        assert err[path]["max_magnitude_error"] < 0.02 and err[path]["max_phase_error_deg"] < 2.0


@pytest.mark.network
def test_the_emulator_refuses_a_hello_at_another_dt_than_its_rig_file(tmp_path):
    emu = Emulator(tmp_path, "--rig", str(RIGS / "paper_b.toml"))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.settimeout(30.0)
    peer = ("127.0.0.1", emu.port)
    try:
        sock.sendto(proto.encode(proto.Message(proto.HELLO, 0, 0, a=0.002, session=7)), peer)
        status = proto.decode(sock.recvfrom(2048)[0])
        assert status.u == proto.RIG_FAULT and status.w == proto.FAULT_BAD_HELLO
        sock.sendto(proto.encode(proto.Message(proto.HELLO, 0, 0, a=0.001, session=7)), peer)
        status = proto.decode(sock.recvfrom(2048)[0])
        assert status.w == 0 and status.a == 18  # the chain's latency in steps
    finally:
        stats = emu.stop()
    assert stats["bad_hello"] == 1 and stats["sessions"] == 1


def _bad_rig(tmp_path: Path) -> Path:
    path = tmp_path / "bad_rig.toml"
    path.write_text("[rig]\nname = \"x\"\nmodel_step_s = 0.001\n[force]\nfilter_order = 9\n")
    return path


@pytest.mark.parametrize("args,message", [
    (["--rig", "{bad}", "--case", str(CASE_B)], "--rig: force.filter_order: 9 is outside its range [1, 8]"),
    (["--rig", str(RIGS / "paper_d.toml"), "--case", str(CASE_B)], "--rig: the rig runs at dt = 0.002 s"),
    (["--rig", str(RIGS / "paper_b.toml"), "--case", str(CASES_DIR / "paper_b_pantograph_300.toml")],
     "--case: rig-identify mounts the case's rigid mass"),
    (["--case", str(CASE_B)], "one of the arguments --rig --hardware is required"),
    (["--hardware", "127.0.0.1:0", "--case", str(CASE_B)], "--hardware:"),
    (["--rig", str(RIGS / "paper_b.toml"), "--case", str(CASE_B), "--amplitude-mm", "nan"], "--amplitude-mm"),
    (["--rig", str(RIGS / "paper_b.toml"), "--case", str(CASE_B), "--spans", "3"],
     "--spans: the rig's clocks repeat every 2 spans"),
])
def test_bad_identify_inputs_are_one_line_and_write_nothing(tmp_path, args, message):
    out = tmp_path / "out.toml"
    args = [a.replace("{bad}", str(_bad_rig(tmp_path))) for a in args]
    proc = pantohil("rig-identify", *args, "--out", str(out))
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], proc.stderr
    assert not out.exists()


def test_identify_refuses_an_existing_out_and_a_missing_folder(tmp_path):
    existing = tmp_path / "there.toml"
    existing.write_text("keep")
    for out, message in ((existing, "exists (--overwrite to replace it)"),
                         (tmp_path / "nowhere" / "x.toml", "does not exist")):
        proc = pantohil("rig-identify", "--rig", str(RIGS / "paper_b.toml"), "--case", str(CASE_B), "--out", str(out))
        assert proc.returncode == 2 and message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert existing.read_text() == "keep"


def test_the_emulator_refuses_a_bad_rig_file(tmp_path):
    proc = pantohil("rig-emulator", "--listen", "127.0.0.1:0", "--rig", str(_bad_rig(tmp_path)))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "--rig: force.filter_order: 9 is outside its range [1, 8]" in lines[0]


def test_identify_in_process_writes_a_rig_file_the_case_compensates_with(tmp_path):
    out = tmp_path / "paper_b_identified.toml"
    proc = pantohil("rig-identify", "--rig", str(RIGS / "paper_b.toml"), "--case", str(CASE_B), "--out", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "against the rig file's model" in proc.stdout
    case = load_case(CASE_B, [f"rig.file=\"{out}\""])
    assert case.compensates_rig_response and case.rig_spec.measured is not None
    gz, gf = case.rig_response()
    model = frequency_response(load_rig_file(RIGS / "paper_b.toml"), case.dt_s, case.samples_per_span,
                               case.n_harmonics)
    np.testing.assert_allclose(gz, model[0], rtol=1e-6)
    np.testing.assert_allclose(gf, model[1], rtol=1e-6)
