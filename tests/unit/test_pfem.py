"""PFEM (Paper C sec. 3-5, Paper D sec. 3): the appendix numbers, the fast path against the direct one,
the cross-check against ASM2, operator files; the benchmark-like case end to end is in
tests/system/test_pfem_cli.py."""
from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import CASES_DIR as CASES
from conftest import CATENARIES_DIR
from pantohil.models.catenary.asm.string import AsmParameters
from pantohil.models.catenary.fe.definition import load_definition
from pantohil.models.catenary.pfem.blocks import catenary_block
from string_references import string_block
from pantohil.models.catenary.pfem.frf import FixedInterfaceModel, direct_receptance
from pantohil.models.catenary.pfem.operator_file import (
    OperatorFileError,
    load_operators,
    save_operators,
)
from pantohil.models.catenary.pfem.operators import PfemSettings, build_operators
from pantohil.models.catenary.pfem.paper_c_appendix import paper_c_appendix
from pantohil.models.catenary.receptance import asm_operator, harmonic_count


# Paper C Appendix A, printed to 4 decimals (x 1e-4 m/N)
H3000_COL1 = np.array([-0.1113 + 0.0845j, 0.0549 - 0.0074j, -0.1147 - 0.0797j])
RE_I3000 = np.array([
    [0.0555, -0.0001, -0.0557, -0.1113, -0.0688, -0.0264],
    [-0.0012, -0.0195, -0.0377, -0.0559, -0.0461, -0.0362],
    [-0.0580, -0.0388, -0.0197, -0.0005, -0.0233, -0.0461],
    [-0.1147, -0.0582, -0.0016, 0.0549, -0.0005, -0.0559],
    [-0.0704, -0.0475, -0.0246, -0.0016, -0.0197, -0.0377],
    [-0.0261, -0.0368, -0.0475, -0.0582, -0.0388, -0.0195]])
OPERATOR = np.array([
    [0.3804, 0.3934, 0.4126, 0.3758, 0.4676, 0.4853],
    [0.4853, 0.3735, 0.3778, 0.4197, 0.4216, 0.4319],
    [0.4676, 0.4439, 0.3676, 0.3934, 0.4029, 0.4216],
    [0.3758, 0.4750, 0.4902, 0.3627, 0.3934, 0.4197],
    [0.4126, 0.4200, 0.4437, 0.4902, 0.3676, 0.3778],
    [0.3934, 0.3913, 0.4200, 0.4750, 0.4439, 0.3735]])
STEADY = np.array([14.1319, 14.2372, 14.4190, 14.1001, 14.2078, 14.4236])


@pytest.fixture(scope="module")
def appendix():
    return paper_c_appendix()


def test_appendix_frf_receptance_and_operator_to_printed_digits(appendix):
    h = np.array(appendix["frf_w3000_first_column_m_per_N"]["re"]) + 1j * np.array(
        appendix["frf_w3000_first_column_m_per_N"]["im"]
    )
    half_digit = 0.5e-4 * 1e-4 + 1e-12
    assert np.max(np.abs(h.real - H3000_COL1.real * 1e-4)) <= half_digit
    assert np.max(np.abs(h.imag - H3000_COL1.imag * 1e-4)) <= half_digit
    assert np.max(np.abs(np.array(appendix["receptance_w3000_real_m_per_N"]) - RE_I3000 * 1e-4)) <= half_digit
    assert np.max(np.abs(np.array(appendix["operator_m_per_N"]) - OPERATOR * 1e-4)) <= half_digit


def test_appendix_hil_forces_to_printed_digits(appendix):
    assert appendix["first_forces_N"][:2] == pytest.approx([50.0, 25.7351], abs=0.5e-4)
    assert np.max(np.abs(np.array(appendix["steady_force_N"]) - STEADY)) <= 0.5e-4


def test_fixed_interface_path_equals_the_direct_frf_on_a_catenary_span():
    """The Craig-Bampton evaluation keeps every mode: it must give Paper C eq. (16) to round-off."""
    cb = catenary_block(load_definition(CATENARIES_DIR / "benchmark_simple.toml"))
    T = 55.0 / (250 / 3.6)
    fim = FixedInterfaceModel.build(cb.block, T)
    Sx = cb.contact_shapes(np.array([0.0, 3.3, 27.5, 54.9]))
    el, load = cb.dropper_shapes()
    for w in (0.0, 7.0, 95.0, 600.0):
        fast = fim.receptance(np.array([w]), Sx, Sx)[0]
        ref = direct_receptance(cb.block, w, T, Sx.toarray(), Sx.toarray())
        assert np.max(np.abs(fast - ref)) <= 1e-8 * np.max(np.abs(ref))
        fast = fim.receptance(np.array([w]), el[:3], load[:3])[0]
        ref = direct_receptance(cb.block, w, T, el[:3].toarray(), load[:3].toarray())
        assert np.max(np.abs(fast - ref)) <= 1e-8 * np.max(np.abs(ref))


def test_pfem_of_the_asm_string_reproduces_the_asm_operator():
    """A 0.1 m mesh of ASM2 (Paper B Table 1), 250 km/h, 25 Hz: the two
    periodic models agree within 2 % (relative Frobenius norm after the same reduction; measured 0.97 %)."""
    cat = AsmParameters(31500.0, 1.4735, 51.15, 0.0125, 1e-4)
    L, V, n = 65.0, 250 / 3.6, 936
    dt = L / (V * n)
    nh = harmonic_count(25.0, n, dt)
    ops = build_operators(string_block(cat, L, 650), PfemSettings(V, dt, n, nh, 2))
    ref = asm_operator(cat, V, n, dt, nh).dense()
    pfem = ops.cc.T
    assert np.linalg.norm(pfem - ref) / np.linalg.norm(ref) < 0.02


def _small_operators():
    cat = AsmParameters(31500.0, 1.4735, 51.15, 0.0125, 1e-4)
    L, V, n = 10.0, 50.0, 100
    return build_operators(string_block(cat, L, 40), PfemSettings(V, L / (V * n), n, 8, 2, omega_max=300.0))


def test_operator_files_round_trip_and_refuse_bad_files(tmp_path):
    ops = _small_operators()
    path = tmp_path / "ops.npz"
    save_operators(ops, path, "k" * 24)
    back = load_operators(path, "k" * 24)
    assert np.max(np.abs(back.cc - ops.cc)) <= 1e-6 * np.max(np.abs(ops.cc))
    assert not list(tmp_path.glob("*.part"))
    with pytest.raises(OperatorFileError, match="built for other inputs"):
        load_operators(path, "x" * 24)
    data = path.read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(OperatorFileError, match="corrupt or truncated"):
        load_operators(tmp_path / "cut.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip at all")
    with pytest.raises(OperatorFileError, match="corrupt or truncated"):
        load_operators(tmp_path / "junk.npz")
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    for change, message in ((lambda a, m: m.__setitem__("format_version", 99), "format version"),
                            (lambda a, m: a.__setitem__("cc", a["cc"][:-1]), "shape")):
        a, m = dict(arrays), dict(meta)
        change(a, m)
        a["meta"] = np.array(json.dumps(m))
        np.savez(tmp_path / "bad.npz", **a)
        with pytest.raises(OperatorFileError, match=message):
            load_operators(tmp_path / "bad.npz")


def test_an_operator_file_header_claiming_a_huge_shape_is_refused_before_allocating(tmp_path):
    """Issue 28, D09: a header claiming (1e6, 1e6) asked for 7.28 TiB; each header is checked against the bytes
    of its member and the shape the settings give before any array is read."""
    import zipfile

    path = tmp_path / "ops.npz"
    save_operators(_small_operators(), path, "k" * 24)
    with zipfile.ZipFile(path) as zin, zipfile.ZipFile(tmp_path / "forged.npz", "w") as out:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename in ("cc.npy", "dd.npy"):
                data = data.replace(b"(100, ", b"(1000000, ", 1)
            out.writestr(info.filename, data)
    with pytest.raises(OperatorFileError, match="header .* does not match its"):
        load_operators(tmp_path / "forged.npz")
    for special in ("/dev/zero", str(tmp_path)):
        with pytest.raises(OperatorFileError, match="not a regular file|is a directory"):
            load_operators(special)


def test_an_interrupted_build_leaves_no_cache_entry(tmp_path, monkeypatch):
    from pantohil.models.catenary.pfem import operator_cache as ob
    from pantohil.models.case import load_case

    monkeypatch.setenv("PANTOHIL_CACHE", str(tmp_path / "cache"))
    case = load_case(CASES / "pfem_benchmark_250.toml")

    def interrupt(*args, **kwargs):
        kwargs["progress"](1, 10)
        raise KeyboardInterrupt

    monkeypatch.setattr(ob, "build_operators", interrupt)
    with pytest.raises(KeyboardInterrupt):
        ob.case_operators(case, progress=False)
    ops_dir = tmp_path / "cache" / "operators"
    assert not (ops_dir.exists() and [p for p in ops_dir.rglob("*") if p.is_file()])


def test_the_lag_transform_gives_the_direct_sum_of_eq_19():
    """The non-uniform FFT behind the operators against the direct sum over the graded grid of the
    benchmark-like case (alpha = 0.0125 1/s, beta = 1e-4 s, w_max = 750 rad/s, lags up to 2 N = 1584):
    single-mode lag functions from the first mode (7 rad/s) to far above w_max (measured: 4e-11)."""
    from pantohil.models.catenary.pfem.frf import graded_grid
    from pantohil.models.catenary.pfem.lag_transform import LagTransform

    omega, w = graded_grid(0.0125, 1e-4, 750.0, 0.094, 0.5, 1e-3)
    x, n = omega * 1e-3, 792
    lt = LagTransform(x[-1], 2 * n)
    lam = np.array([49.7, 1e4, 5e5, 3e6])
    a = w[:, None] / ((1 + 1e-4j * omega[:, None]) * lam + 0.0125j * omega[:, None] - omega[:, None] ** 2)
    acc = np.zeros((lt.n_rows, len(lam)), dtype=complex)
    for k0 in range(0, len(x), 300):
        rows, kernel = lt.spreading(x[k0:k0 + 300])
        acc[rows] += kernel @ a[k0:k0 + 300]
    lags = np.arange(-2 * n, 2 * n + 1, 7)
    fast = lt.evaluate(acc, lags)
    direct = (np.exp(1j * np.outer(lags, x)) @ a).T
    assert np.max(np.abs(fast - direct) / np.abs(direct).max(axis=1, keepdims=True)) < 1e-9
