"""FMU states as data (fmus/state_codec.py): what is written is read back equal, with shared objects
still shared; nothing but data and pantohil's own loaded classes can be named."""
from __future__ import annotations

import json
from collections import OrderedDict, deque

import numpy as np
import pytest

from pantohil.fmus import state_codec
from pantohil.models.hil.loop import HilSettings, PeriodicHil


class _Op:
    def column(self, m):
        return np.zeros(4)


def test_a_state_round_trips_with_its_sharing_and_its_constants():
    op = _Op()
    hil = PeriodicHil(op, np.arange(4.0), HilSettings())
    gen = np.random.default_rng(5)
    gen.normal(size=3)
    value = {"hil": hil, "same": hil.last_force, "q": deque([1, 2.5], maxlen=3), "o": OrderedDict([(3, "x")]),
             "t": (np.float32(1.5), np.int64(-2), None, True), "rng": gen, "nan": float("nan"), "big": 2 ** 100,
             "gain": complex(0.5, -2.0)}
    data = state_codec.encode(value, {id(op): "op"})
    back = state_codec.decode(data, {"op": op})
    assert back["hil"].op is op and isinstance(back["hil"], PeriodicHil)
    assert back["hil"].force_estimate is back["hil"].last_force is back["same"]  # shared stays shared
    assert np.array_equal(back["hil"].z0, hil.z0) and back["hil"].s == hil.s
    assert back["q"] == value["q"] and back["q"].maxlen == 3 and back["o"] == value["o"]
    assert back["t"][0].dtype == np.float32 and back["t"][1] == -2 and back["t"][2:] == (None, True)
    assert back["rng"].normal() == gen.normal() and np.isnan(back["nan"]) and back["big"] == 2 ** 100
    assert back["gain"] == complex(0.5, -2.0)


@pytest.mark.parametrize("tree", [
    {"$id": 0, "$o": "os:system", "a": {"$id": 1, "$d": []}},
    {"$id": 0, "$o": "pantohil.models.hil.loop:np", "a": {"$id": 1, "$d": []}},
    {"$id": 0, "$o": "pantohil.not_loaded_module:Thing", "a": {"$id": 1, "$d": []}},
    {"$id": 0, "$a": "AAAA", "dtype": "|O", "shape": [1]},
    {"$id": 0, "$rng": {"$id": 1, "$d": [["bit_generator", "os.system"]]}},
    {"$id": 0, "$l": [{"$r": 7}]},
    {"$id": 3, "$l": []},
])
def test_crafted_state_data_is_refused(tree):
    with pytest.raises(state_codec.StateDataError):
        state_codec.decode(state_codec.FORMAT + json.dumps(tree).encode(), {})


def test_deep_nesting_and_other_formats_are_refused():
    with pytest.raises(state_codec.StateDataError):
        state_codec.decode(state_codec.FORMAT + b"[" * 100_000 + b"]" * 100_000, {})
    with pytest.raises(state_codec.StateDataError, match="not a pantohil FMU state"):
        state_codec.decode(b"\x80\x04pickle", {})
