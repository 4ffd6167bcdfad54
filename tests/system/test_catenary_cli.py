"""`pantohil catenary` end to end, its bad input, and a case run on the form-found profile."""
import json
import tomllib

import pytest
from conftest import CASES_DIR, load_run, pantohil
from conftest import CATENARIES_DIR as CATENARIES


@pytest.mark.slow
def test_catenary_command_writes_its_folder(tmp_path):
    out = tmp_path / "cat"
    proc = pantohil("catenary", str(CATENARIES / "paper_a_stitched.toml"), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    for name in ("catenary.json", "profile.csv", "stiffness.csv", "droppers.csv", "geometry.png", "stiffness.png"):
        assert (out / name).stat().st_size > 0
    s = json.loads((out / "catenary.json").read_text())
    for key in ("span_m", "dropper_lengths_m", "max_height_error_m", "min_dropper_tension_N",
                "mean_vertical_stiffness_N_m", "asm_fit", "z0_harmonics"):
        assert key in s
    assert set(s["asm_fit"]) >= {"support_stiffness_N_m2", "density_kg_m", "band_hz"}
    header = (out / "profile.csv").read_text().splitlines()[0]
    assert header == "x_m,z0_m" and (out / "stiffness.csv").read_text().startswith("x_m,kz_N_m")


def _bad(tmp_path, edit) -> str:
    raw = tomllib.loads((CATENARIES / "benchmark_simple.toml").read_text())
    edit(raw)
    path = tmp_path / "bad.toml"
    lines = []
    for sec, body in raw.items():
        lines.append(f"[{sec}]")
        lines += [f"{k} = {json.dumps(v)}" for k, v in body.items()]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


@pytest.mark.parametrize("edit,key", [
    (lambda r: r["catenary"].update(dropper_positions_m=[4.5, 10.25, 10.25, 21.75]), "catenary.dropper_positions_m"),
    (lambda r: r["catenary"].update(dropper_positions_m=[4.5, 10.25, 60.0]), "catenary.dropper_positions_m"),
    (lambda r: r["contact_wire"].update(tension_N=0.0), "contact_wire.tension_N"),
    (lambda r: r["catenary"].update(presag_m=-1.5), "catenary.presag_m"),  # a dropper length < 0
    (lambda r: r["catenary"].update(presag_m=1.5), "catenary.presag_m"),  # a dropper in compression
    (lambda r: r["catenary"].update(colour="red"), "catenary.colour"),
])
def test_bad_catenary_files_give_one_line_and_exit_2(tmp_path, edit, key):
    proc = pantohil("catenary", _bad(tmp_path, edit), "--out", str(tmp_path / "out"))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and "Traceback" not in proc.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_a_case_with_the_form_found_profile_converges(tmp_path):
    out = tmp_path / "fe_case"
    proc = pantohil("run", str(CASES_DIR / "asm_paper_a_fe.toml"), "--out", str(out), "--quiet",
                    "--engine", "inprocess")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary, _ = load_run(out)
    assert summary["converged"] and summary["reference"]["rms_error_rel_std"] < 5e-3
