"""The compiled kernels repeat their numpy paths' arithmetic to the bit (models/compiled.py,
models/hil/span_kernel.py): the pantograph's step products are numpy's pairwise row sums, whatever the shape."""
from __future__ import annotations

import numpy as np
import pytest

from pantohil.models.compiled import compiled
from pantohil.models.hil.kernels import PAIRWISE_MAX, pairwise_dot, row_products, solve_small


@pytest.mark.parametrize("shape", [(3, 6), (6, 9), (9, 12), (15, 18), (4, 17), (2, 24)])
def test_the_compiledrow_products_are_numpys_pairwise_sums_to_the_bit(shape):
    kernel = compiled(row_products)
    assert kernel is not None, "numba is a dependency: the kernels compile"
    rng = np.random.default_rng(shape[1])
    for _ in range(200):  # magnitudes 1e-6..1e6 apart, where a different order of the sum changes its last bits
        P = rng.normal(size=shape) * 10.0 ** rng.integers(-6, 7, size=shape)
        x = rng.normal(size=shape[1]) * 10.0 ** rng.integers(-6, 7, size=shape[1])
        out = np.empty(shape[0])
        kernel(P, x, out)
        assert np.array_equal(out, (P * x).sum(axis=1))


def test_no_kernel_is_compiled_with_pantohil_jit_0(monkeypatch):
    monkeypatch.setenv("PANTOHIL_JIT", "0")
    assert compiled(row_products) is None


def test_the_compiled_pairwise_dot_is_numpys_sum_of_products_to_the_bit():
    kernel = compiled(pairwise_dot)
    rng = np.random.default_rng(7)
    for n in range(1, PAIRWISE_MAX + 1):  # every length the kernels take
        for _ in range(10):
            a = rng.normal(size=n) * 10.0 ** rng.integers(-6, 7, size=n)
            b = rng.normal(size=n) * 10.0 ** rng.integers(-6, 7, size=n)
            assert kernel(a, b) == (a * b).sum() == pairwise_dot(a, b)


def test_the_small_solve_is_the_same_compiled_and_in_python_and_solves():
    kernel = compiled(solve_small)
    rng = np.random.default_rng(3)
    for m in (1, 2, 3, 5, 9):
        for _ in range(20):
            A = np.eye(m) + rng.normal(size=(m, m)) * 10.0 ** rng.integers(-3, 3)
            b = rng.normal(size=m)
            x_py, x_jit = solve_small(A.copy(), b.copy()), kernel(A.copy(), b.copy())
            assert np.array_equal(x_py, x_jit)
            # LAPACK's solve, an independent method: agreement to the rounding of a well-conditioned system
            x_ref = np.linalg.solve(A, b)
            assert np.allclose(x_py, x_ref, rtol=1e-9 * np.linalg.cond(A), atol=0.0)


def test_a_damaged_compile_cache_entry_is_compiled_again(tmp_path):
    """The in-process engine's kernel from a compile cache whose entries are garbage: the run succeeds (the same
    convergence as with a sound cache), the entries are written anew, and the log names the cache."""
    import json
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PANTOHIL_JIT")}
    env["PANTOHIL_CACHE"] = str(tmp_path / "cache")
    args = [sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--engine", "inprocess", "--no-plots", "--quiet",
            "--set", "run.max_spans=4"]
    first = subprocess.run([*args, "--out", str(tmp_path / "a")], env=env, capture_output=True, text=True,
                           timeout=600)
    assert first.returncode in (0, 1), first.stderr  # 1: stopped at run.max_spans before converging
    entries = sorted((tmp_path / "cache" / "numba").rglob("kernels.*.nb*"))
    assert entries, "the kernel was compiled into the cache"
    for entry in entries:
        entry.write_bytes(b"garbage")
    second = subprocess.run([*args, "--out", str(tmp_path / "b")], env=env, capture_output=True, text=True,
                            timeout=600)
    assert second.returncode == first.returncode, second.stderr
    assert "Traceback" not in second.stderr
    assert all(e.read_bytes() != b"garbage" for e in sorted((tmp_path / "cache" / "numba").rglob("kernels.*.nb*")))
    spans = [json.loads((tmp_path / r / "summary.json").read_text())["convergence"] for r in "ab"]
    assert spans[0] == spans[1]
    assert "the compile cache entries of kernels" in second.stderr and "compiling again" in second.stderr
