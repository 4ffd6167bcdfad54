"""The pantohil rig link, protocol version 3: little-endian UDP datagrams bound to a session, whose
heights carry a horizon of the next ticks (docs/udp-protocol.md).

    header     magic u32 | version u8 | type u8 | flags u16 | session u64 | seq u32 | time u64 [ns]
    payload    a f64 | b f64 | c f64 | u u32 | w u32 (meaning by type)
    extension  by type: HELLO, STATUS horizon u32; COMMAND, ANSWER (u - 1) x (height f64, velocity f64);
               FORCE, SAMPLE fresh u32 | predicted u32 | uncovered u32; BYE none
    trailer    CRC-32 u32 of everything before it, or (flag AUTHENTICATED) HMAC-SHA256 of it, 32 bytes

Anything else (size, magic, version, type, horizon count, CRC or HMAC) is malformed; a peer of
another version is named as such.
"""
from __future__ import annotations

import dataclasses
import hashlib
import hmac
import itertools
import math
import secrets
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

from pantohil.models.errors import InputError
from pantohil.models.hil.loop import MAX_HORIZON_STEPS
from pantohil.models.input_files import InputFileError, read_input_bytes

MAGIC = 0x31484850  # b"PHH1" little-endian (kept from version 1, so an old peer is recognised)
VERSION = 3
HELLO, COMMAND, FORCE, STATUS, BYE, SAMPLE, ANSWER = 1, 2, 3, 4, 5, 6, 7
TYPE_NAMES = {HELLO: "hello", COMMAND: "command", FORCE: "force", STATUS: "status", BYE: "bye",
              SAMPLE: "sample", ANSWER: "answer"}

# rig states carried by STATUS, FORCE and SAMPLE
RIG_READY, RIG_RUNNING, RIG_FAULT, RIG_BUSY = 0, 1, 2, 3
# fault bits of a refusing STATUS (w)
FAULT_VERSION, FAULT_BAD_HELLO, FAULT_BUSY, FAULT_PACING, FAULT_HORIZON = 1, 2, 4, 8, 16
# pacing modes, carried by HELLO (u) and STATUS (w is fault bits, u the state; c echoes the mode)
PACED_BY_MODEL, PACED_BY_RIG = 0, 1

FLAG_AUTHENTICATED = 1

_BODY = struct.Struct("<IBBHQIQdddII")
_CRC = struct.Struct("<I")
_HORIZON = struct.Struct("<I")  # HELLO: the horizon asked for; STATUS: the one granted [ticks]
_AHEAD = struct.Struct("<dd")  # COMMAND, ANSWER: one more tick's height [m] and velocity [m/s]
_COUNTS = struct.Struct("<III")  # FORCE, SAMPLE: fresh, predicted, uncovered ticks so far
TAG_BYTES = hashlib.sha256().digest_size
SIZE = _BODY.size + _CRC.size  # a BYE; the other types add their extension

_V1_BODY = struct.Struct("<IBBHIQddII")  # version 1, only to recognise and refuse an old peer
V1_SIZE = _V1_BODY.size + _CRC.size  # 48


class Malformed(InputError):
    """A datagram that is not a valid pantohil message; the text says why."""


class OtherVersion(Malformed):
    """A pantohil datagram of another protocol version."""

    def __init__(self, version: int):
        super().__init__(f"peer speaks protocol version {version}; this side speaks version {VERSION}")
        self.version = version


@dataclass(frozen=True)
class Message:
    """One datagram. Payload meaning by type:
    HELLO   a = dt [s], u = pacing mode      (model -> rig: start a session with this id)
    COMMAND a = height [m], b = velocity [m/s]  (model -> rig, model-paced)
    FORCE   a = measured force [N], b = actuator height [m], u = rig state  (rig -> model, model-paced)
    STATUS  a = rig latency [steps], b = rig tick [s], c = pacing mode, u = rig state, w = fault bits
            (the rig's answer to HELLO, or its refusal)
    BYE     (model -> rig: end of session)
    SAMPLE  a = measured force [N], b = actuator height [m], u = rig state, w = ticks so far that
            reused an old answer; t_ns = rig time (rig -> model every rig tick, rig-paced)
    ANSWER  a = height [m] for the tick seq + 1 (the catenary's sample seq + D), b = its velocity [m/s],
            seq = the SAMPLE answered (model -> rig, rig-paced)
    COMMAND and ANSWER carry u = H heights: a, b and `ahead`, the (height, velocity) of the H - 1 ticks
    after; HELLO asks for a horizon of H = `horizon` ticks and STATUS grants it; FORCE and SAMPLE carry
    the rig's counts of ticks whose height was `fresh`, `predicted` (an older answer's horizon) or
    `uncovered` (no answer covered it: the actuator held).
    """

    type: int
    seq: int
    t_ns: int
    a: float = 0.0
    b: float = 0.0
    u: int = 0
    w: int = 0
    session: int = 0
    c: float = 0.0
    ahead: tuple = ()  # COMMAND, ANSWER: ((height [m], velocity [m/s]), ...) for the ticks after a, b
    horizon: int = 1  # HELLO, STATUS: the horizon H [ticks]
    fresh: int = 0  # FORCE, SAMPLE: the rig's tick counts (docs/udp-protocol.md)
    predicted: int = 0
    uncovered: int = 0


def new_session_id() -> int:
    """A random, non-zero 64-bit session id (the operating system's CSPRNG)."""
    return secrets.randbits(64) or 1


def finite(m: Message) -> bool:
    """Every payload value of the message, its horizon included, is a finite number."""
    return (math.isfinite(m.a) and math.isfinite(m.b) and math.isfinite(m.c)
            and all(math.isfinite(h) and math.isfinite(v) for h, v in m.ahead))


def _extension(m: Message) -> bytes:
    if m.type in (HELLO, STATUS):
        return _HORIZON.pack(m.horizon & 0xFFFFFFFF)
    if m.type in (COMMAND, ANSWER):
        return struct.pack(f"<{2 * len(m.ahead)}d", *itertools.chain.from_iterable(m.ahead))
    if m.type in (FORCE, SAMPLE):
        return _COUNTS.pack(m.fresh & 0xFFFFFFFF, m.predicted & 0xFFFFFFFF, m.uncovered & 0xFFFFFFFF)
    return b""


def encode(m: Message, key: bytes | None = None) -> bytes:
    """The datagram of a message: the little-endian body, its extension and the CRC-32 of both, or with a
    key their HMAC-SHA256. COMMAND and ANSWER carry u = 1 + len(ahead) heights."""
    if m.type in (COMMAND, ANSWER) and len(m.ahead) >= MAX_HORIZON_STEPS:
        raise ValueError(f"a horizon of {len(m.ahead) + 1} heights; at most {MAX_HORIZON_STEPS}")
    flags = FLAG_AUTHENTICATED if key else 0
    u = len(m.ahead) + 1 if m.type in (COMMAND, ANSWER) else m.u
    body = _BODY.pack(MAGIC, VERSION, m.type, flags, m.session & 0xFFFFFFFFFFFFFFFF, m.seq & 0xFFFFFFFF,
                      m.t_ns & 0xFFFFFFFFFFFFFFFF, m.a, m.b, m.c, u & 0xFFFFFFFF, m.w & 0xFFFFFFFF) + _extension(m)
    if key:
        return body + hmac.new(key, body, hashlib.sha256).digest()
    return body + _CRC.pack(zlib.crc32(body))


def _extension_size(typ: int, u: int) -> int | None:
    """Bytes of a type's extension (None: a COMMAND or ANSWER whose height count u is out of range)."""
    if typ in (HELLO, STATUS):
        return _HORIZON.size
    if typ in (COMMAND, ANSWER):
        return _AHEAD.size * (u - 1) if 1 <= u <= MAX_HORIZON_STEPS else None
    if typ in (FORCE, SAMPLE):
        return _COUNTS.size
    return 0


def datagram_size(typ: int, heights: int = 1, authenticated: bool = False) -> int:
    """The size of a datagram of a type [bytes]; COMMAND and ANSWER carry `heights` heights."""
    return _BODY.size + _extension_size(typ, heights) + (TAG_BYTES if authenticated else _CRC.size)


def decode(data: bytes, key: bytes | None = None) -> Message:
    """The message in `data`; Malformed (OtherVersion for another protocol version) if it is not one.

    With a key, only datagrams carrying a valid HMAC-SHA256 of that key are accepted."""
    if len(data) >= 6:
        magic, version = struct.unpack_from("<IB", data)
        if magic == MAGIC and version != VERSION:
            raise OtherVersion(version)
    trailer = TAG_BYTES if key else _CRC.size
    if len(data) < _BODY.size + trailer:
        raise Malformed(f"size {len(data)} bytes, below the {_BODY.size + trailer} of the shortest datagram")
    body = data[:len(data) - trailer]
    if key:
        if not hmac.compare_digest(hmac.new(key, body, hashlib.sha256).digest(), data[len(body):]):
            raise Malformed("bad HMAC (wrong or missing key)")
    else:
        (crc,) = _CRC.unpack_from(data, len(body))
        if zlib.crc32(body) != crc:
            raise Malformed("bad CRC")
    magic, _version, typ, flags, session, seq, t_ns, a, b, c, u, w = _BODY.unpack_from(body)
    if magic != MAGIC:
        raise Malformed(f"bad magic 0x{magic:08x}")
    if bool(flags & FLAG_AUTHENTICATED) != bool(key):
        raise Malformed("authentication flag does not match this side's key")
    if typ not in TYPE_NAMES:
        raise Malformed(f"unknown type {typ}")
    extension = _extension_size(typ, u)
    if extension is None:
        raise Malformed(f"a {TYPE_NAMES[typ]} of {u} heights (1 to {MAX_HORIZON_STEPS})")
    if len(body) != _BODY.size + extension:
        raise Malformed(f"size {len(data)} bytes, expected {len(data) - len(body) + _BODY.size + extension} "
                        f"for a {TYPE_NAMES[typ]}")
    m = Message(typ, seq, t_ns, a, b, u, w, session, c)
    if typ in (HELLO, STATUS):
        return dataclasses.replace(m, horizon=_HORIZON.unpack_from(body, _BODY.size)[0])
    if typ in (COMMAND, ANSWER):
        return dataclasses.replace(m, ahead=tuple(_AHEAD.iter_unpack(body[_BODY.size:])))
    if typ in (FORCE, SAMPLE):
        fresh, predicted, uncovered = _COUNTS.unpack_from(body, _BODY.size)
        return dataclasses.replace(m, fresh=fresh, predicted=predicted, uncovered=uncovered)
    return m


def old_hello_version(data: bytes) -> int | None:
    """The version of a valid HELLO of an older protocol (1 or 2, unauthenticated: an old model computer
    starting a session), else None."""
    olds = {1: (_V1_BODY, V1_SIZE), 2: (_BODY, _BODY.size + _CRC.size)}
    for version, (layout, size) in olds.items():
        if len(data) == size and zlib.crc32(data[:-4]) == _CRC.unpack_from(data, size - 4)[0]:
            magic, got, typ = layout.unpack(data[:-4])[:3]
            if magic == MAGIC and got == version and typ == HELLO:
                return version
    return None


def old_refusal(version: int, session: int = 0) -> bytes:
    """A STATUS in fault in an older protocol's own layout (fault bit FAULT_VERSION, a = the version spoken
    here): a peer of that version reads it as a rig in fault, for the protocol version, and stops."""
    if version == 1:
        body = _V1_BODY.pack(MAGIC, 1, STATUS, 0, 0, 0, float(VERSION), 0.0, RIG_FAULT, FAULT_VERSION)
    else:
        body = _BODY.pack(MAGIC, version, STATUS, 0, session, 0, 0, float(VERSION), 0.0, 0.0, RIG_FAULT,
                          FAULT_VERSION)
    return body + _CRC.pack(zlib.crc32(body))


def other_version_status(data: bytes, session: int) -> bool:
    """Whether `data` is a rig's STATUS of another protocol version for this session (a peer that speaks
    another version refused it): the model names the version as the reason."""
    if len(data) < _BODY.size or struct.unpack_from("<IB", data) == (MAGIC, VERSION):
        return False
    magic, _version, typ, _flags, sid = struct.unpack_from("<IBBHQ", data)
    return magic == MAGIC and typ == STATUS and sid == session


MAX_KEY_FILE_BYTES = 64 * 1024


def read_key(path: str) -> bytes:
    """The pre-shared key in a file: its bytes, surrounding whitespace removed, at least 16 bytes.
    ValueError with one line otherwise."""
    try:  # a regular file only: a FIFO or a device would hang the run or the emulator
        key = read_input_bytes(Path(path), "key file", MAX_KEY_FILE_BYTES).strip()
    except InputFileError as exc:
        raise ValueError(str(exc)) from None
    if not 16 <= len(key) <= 4096:
        raise ValueError(f"key file {path}: the key must have 16 to 4096 bytes (got {len(key)})")
    return key


def parse_endpoint(text: str, listening: bool = False) -> tuple[str, int]:
    """HOST:PORT -> (host, port); port 0 (any free port) only for listening. ValueError with one line."""
    host, sep, port = text.rpartition(":")
    lowest = 0 if listening else 1
    if not sep or not host or not port.isdigit() or not lowest <= int(port) < 65536:
        raise ValueError(f"expected HOST:PORT, got {text!r}")
    return host, int(port)
