"""The compiled kernels repeat their numpy paths' arithmetic to the bit (models/compiled.py,
models/hil/span_kernel.py): the pantograph's step products are numpy's pairwise row sums, whatever the shape."""
from __future__ import annotations

import numpy as np
import pytest

from pantohil.models.compiled import compiled
from pantohil.models.hil.span_kernel import _row_products


@pytest.mark.parametrize("shape", [(3, 6), (6, 9), (9, 12), (15, 18), (4, 17), (2, 24)])
def test_the_compiled_row_products_are_numpys_pairwise_sums_to_the_bit(shape):
    kernel = compiled(_row_products)
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
    assert compiled(_row_products) is None
