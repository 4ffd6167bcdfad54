"""FMU states as data: the serialized form of fmi2SerializeFMUstate and of a run's checkpoint.

A state is a tree of plain values (None, bool, int, float, complex, str), containers (list, tuple, dict,
OrderedDict, deque), numeric numpy arrays and scalars, numpy random generators (their bit
generator's state) and instances of pantohil's own classes (their attributes). It is written as
JSON; arrays as base64 of their bytes with dtype and shape. Reading it creates objects without
calling any code of theirs: an instance is made by `object.__new__` of a class that is already
loaded from a `pantohil.` module, and its attributes are set from the data. No other class, no
function and no module import can be named, so a crafted state cannot run anything (unlike pickle).
The class is looked up in this module's own copy of the package (an FMU's, in an FMU: fmus/own_package.py),
not in sys.modules, where another pantohil may be.

Objects shared inside a state stay shared (the first occurrence carries an id, later ones refer to
it), and objects named in `constants` are written as their name and taken from the instance that
reads the state.
"""
from __future__ import annotations

import base64
import json
from collections import OrderedDict, deque
from types import ModuleType

import numpy as np

import pantohil  # this copy of the package: the classes a state names are its own
from pantohil.models.errors import InputError

FORMAT = b"pantohil-fmu-state 2\n"
_OWN_PACKAGE = "pantohil."
_BIT_GENERATORS = ("PCG64", "PCG64DXSM", "MT19937", "Philox", "SFC64")
_NUMERIC_KINDS = "biufc"
MAX_STATE_BYTES = 256 << 20


class StateDataError(InputError):
    """A serialized state that is not valid state data; the text says why."""


def encode(value, constants: dict[int, str]) -> bytes:
    """The state data of `value`; `constants` maps id(obj) -> name for objects written by name only."""
    memo: dict[int, int] = {}
    keep: list = []  # keeps every memoised object alive, so that no id is reused while encoding
    tree = _Encoder(constants, memo, keep).value(value)
    return FORMAT + json.dumps(tree, separators=(",", ":"), allow_nan=True).encode()


def decode(data: bytes, constants: dict[str, object]):
    """The value encoded in `data`; StateDataError (one line) if it is not valid state data."""
    if not data.startswith(FORMAT):
        raise StateDataError(f"not a pantohil FMU state (format {FORMAT!r} expected)")
    if len(data) > MAX_STATE_BYTES:
        raise StateDataError(f"state of {len(data)} bytes, above the limit of {MAX_STATE_BYTES}")
    try:
        tree = json.loads(data[len(FORMAT):])
        return _Decoder(constants).value(tree)
    except StateDataError:
        raise
    except (ValueError, TypeError, KeyError, IndexError, AttributeError, RecursionError) as exc:
        raise StateDataError(f"damaged state data ({type(exc).__name__}: {' '.join(str(exc).split())[:200]})") \
            from None


class _Encoder:
    def __init__(self, constants: dict[int, str], memo: dict[int, int], keep: list):
        self.constants, self.memo, self.keep = constants, memo, keep

    def value(self, v):
        """The JSON tree of one value."""
        if v is None or isinstance(v, (bool, str)):
            return v
        if isinstance(v, (int, float)) and type(v) in (int, float):
            return v
        if type(v) is complex:
            return {"$z": [v.real, v.imag]}
        if id(v) in self.constants:
            return {"$c": self.constants[id(v)]}
        if id(v) in self.memo:
            return {"$r": self.memo[id(v)]}
        if isinstance(v, np.generic):
            return {"$s": v.item(), "dtype": v.dtype.str}
        if isinstance(v, tuple) and type(v) is tuple:
            return {"$t": [self.value(x) for x in v]}
        ref = len(self.memo)
        self.memo[id(v)] = ref
        self.keep.append(v)
        return {"$id": ref, **self._shared(v)}

    def _shared(self, v) -> dict:
        """A value that may be referred to more than once (containers, arrays, objects)."""
        if isinstance(v, np.ndarray):
            if v.dtype.kind not in _NUMERIC_KINDS:
                raise TypeError(f"an array of dtype {v.dtype} cannot be stored in a state")
            return {"$a": base64.b64encode(np.ascontiguousarray(v).tobytes()).decode(), "dtype": v.dtype.str,
                    "shape": list(v.shape)}
        if type(v) is list:
            return {"$l": [self.value(x) for x in v]}
        if type(v) in (dict, OrderedDict):
            tag = "$d" if type(v) is dict else "$od"
            return {tag: [[self.value(k), self.value(x)] for k, x in v.items()]}
        if type(v) is deque:
            return {"$dq": [self.value(x) for x in v], "maxlen": v.maxlen}
        if isinstance(v, np.random.Generator):
            return {"$rng": self.value(v.bit_generator.state)}
        cls = type(v)
        if cls.__module__.startswith(_OWN_PACKAGE) and hasattr(v, "__dict__"):
            return {"$o": f"{cls.__module__}:{cls.__qualname__}", "a": self.value(dict(vars(v)))}
        raise TypeError(f"a {cls.__module__}.{cls.__qualname__} cannot be stored in a state")


class _Decoder:
    def __init__(self, constants: dict[str, object]):
        self.constants = constants
        self.memo: dict[int, object] = {}

    def value(self, t):
        """The value of one JSON tree."""
        if t is None or isinstance(t, (bool, int, float, str)):
            return t
        if isinstance(t, list):
            raise StateDataError("a bare list in state data")
        if "$c" in t:
            name = t["$c"]
            if name not in self.constants:
                raise StateDataError(f"the state refers to {name!r}, which this instance lacks (initialise it with "
                                     "the same case before setting the state)")
            return self.constants[name]
        if "$r" in t:
            return self.memo[int(t["$r"])]
        if "$s" in t:
            return _dtype(t["dtype"]).type(t["$s"])
        if "$t" in t:
            return tuple(self.value(x) for x in t["$t"])
        if "$z" in t:
            re_part, im_part = t["$z"]
            return complex(float(re_part), float(im_part))
        return self._shared(t)

    def _shared(self, t: dict):
        ref = int(t["$id"])
        if ref in self.memo or ref != len(self.memo):
            raise StateDataError("state data with ids out of order")
        if "$a" in t:
            dtype, shape = _dtype(t["dtype"]), tuple(int(n) for n in t["shape"])
            raw = base64.b64decode(t["$a"], validate=True)
            self.memo[ref] = np.frombuffer(raw, dtype=dtype).reshape(shape).copy()
        elif "$l" in t:
            self.memo[ref] = out = []
            out.extend(self.value(x) for x in t["$l"])
        elif "$d" in t or "$od" in t:
            self.memo[ref] = out = {} if "$d" in t else OrderedDict()
            for k, x in t.get("$d", t.get("$od")):
                out[self.value(k)] = self.value(x)
        elif "$dq" in t:
            self.memo[ref] = out = deque(maxlen=t["maxlen"])
            out.extend(self.value(x) for x in t["$dq"])
        elif "$rng" in t:
            self.memo[ref] = None  # reserved; the generator is made from its (plain) state
            self.memo[ref] = _generator(self.value(t["$rng"]))
        elif "$o" in t:
            self.memo[ref] = obj = object.__new__(_own_class(t["$o"]))
            attributes = self.value(t["a"])
            if not isinstance(attributes, dict) or not all(isinstance(k, str) for k in attributes):
                raise StateDataError(f"the attributes of a {t['$o']} are not a table of names")
            obj.__dict__.update(attributes)
        else:
            raise StateDataError(f"unknown entry in state data: {sorted(t)[:3]}")
        return self.memo[ref]


def _dtype(text: str) -> np.dtype:
    dtype = np.dtype(str(text))
    if dtype.kind not in _NUMERIC_KINDS or dtype.hasobject:
        raise StateDataError(f"dtype {text!r} is not numeric")
    return dtype


def _generator(state) -> np.random.Generator:
    name = state.get("bit_generator") if isinstance(state, dict) else None
    if name not in _BIT_GENERATORS:
        raise StateDataError(f"unknown random bit generator {name!r}")
    gen = np.random.Generator(getattr(np.random, name)())
    gen.bit_generator.state = state
    return gen


def _loaded_module(name: str) -> ModuleType | None:
    """The module `name` of this copy of pantohil if it is loaded, else None: found through the package's
    attributes (vars(), so that no module __getattr__ runs and nothing is imported)."""
    if not name.startswith(_OWN_PACKAGE):
        return None
    module = pantohil
    for part in name.split(".")[1:]:
        module = vars(module).get(part)
        if not isinstance(module, ModuleType):
            return None
    return module if module.__name__ == name else None


def _own_class(path: str) -> type:
    """A class of a pantohil module that is already loaded (nothing is imported, nothing else is allowed)."""
    module_name, _, qualname = str(path).partition(":")
    module = _loaded_module(module_name)
    cls = module
    for part in qualname.split(".") if module is not None else ():
        cls = getattr(cls, part, None)
    if not isinstance(cls, type) or cls.__module__ != module_name or "<locals>" in qualname:
        raise StateDataError(f"state data names {path!r}, which is not a loaded pantohil class")
    return cls
