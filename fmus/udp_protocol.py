"""The pantohil rig link, protocol version 2: fixed-size little-endian UDP datagrams bound to a
session (docs/udp-protocol.md).

    header  magic u32 | version u8 | type u8 | flags u16 | session u64 | seq u32 | time u64 [ns]
    payload a f64 | b f64 | c f64 | u u32 | w u32 (meaning by type)
    trailer CRC-32 u32 of everything before it, or (flag AUTHENTICATED) HMAC-SHA256 of it, 32 bytes

A datagram is 64 bytes (92 with the HMAC). Anything else (size, magic, version, type, CRC or HMAC)
is malformed; a version-1 peer is named as such.
"""
from __future__ import annotations

import hashlib
import hmac
import math
import secrets
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

from pantohil.models.input_files import InputFileError, read_input_bytes

MAGIC = 0x31484850  # b"PHH1" little-endian (kept from version 1, so an old peer is recognised)
VERSION = 2
HELLO, COMMAND, FORCE, STATUS, BYE, SAMPLE, ANSWER = 1, 2, 3, 4, 5, 6, 7
TYPE_NAMES = {HELLO: "hello", COMMAND: "command", FORCE: "force", STATUS: "status", BYE: "bye",
              SAMPLE: "sample", ANSWER: "answer"}

# rig states carried by STATUS, FORCE and SAMPLE
RIG_READY, RIG_RUNNING, RIG_FAULT, RIG_BUSY = 0, 1, 2, 3
# fault bits of a refusing STATUS (w)
FAULT_VERSION, FAULT_BAD_HELLO, FAULT_BUSY, FAULT_PACING = 1, 2, 4, 8
# pacing modes, carried by HELLO (u) and STATUS (w is fault bits, u the state; c echoes the mode)
PACED_BY_MODEL, PACED_BY_RIG = 0, 1

FLAG_AUTHENTICATED = 1

_BODY = struct.Struct("<IBBHQIQdddII")
_CRC = struct.Struct("<I")
SIZE = _BODY.size + _CRC.size  # 64
TAG_BYTES = hashlib.sha256().digest_size
SIZE_AUTHENTICATED = _BODY.size + TAG_BYTES  # 92

_V1_BODY = struct.Struct("<IBBHIQddII")  # version 1, only to recognise and refuse an old peer
V1_SIZE = _V1_BODY.size + _CRC.size  # 48


class Malformed(ValueError):
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
    ANSWER  a = height [m] for the tick seq + D, b = its velocity [m/s], seq = the SAMPLE answered
            (model -> rig, rig-paced)
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


def new_session_id() -> int:
    """A random, non-zero 64-bit session id (the operating system's CSPRNG)."""
    return secrets.randbits(64) or 1


def finite(m: Message) -> bool:
    """Every payload value of the message is a finite number."""
    return math.isfinite(m.a) and math.isfinite(m.b) and math.isfinite(m.c)


def encode(m: Message, key: bytes | None = None) -> bytes:
    """The datagram of a message: the little-endian body and its CRC-32, or with a key its HMAC-SHA256."""
    flags = FLAG_AUTHENTICATED if key else 0
    body = _BODY.pack(MAGIC, VERSION, m.type, flags, m.session & 0xFFFFFFFFFFFFFFFF, m.seq & 0xFFFFFFFF,
                      m.t_ns & 0xFFFFFFFFFFFFFFFF, m.a, m.b, m.c, m.u & 0xFFFFFFFF, m.w & 0xFFFFFFFF)
    if key:
        return body + hmac.new(key, body, hashlib.sha256).digest()
    return body + _CRC.pack(zlib.crc32(body))


def decode(data: bytes, key: bytes | None = None) -> Message:
    """The message in `data`; Malformed (OtherVersion for another protocol version) if it is not one.

    With a key, only datagrams carrying a valid HMAC-SHA256 of that key are accepted."""
    if len(data) >= 6:
        magic, version = struct.unpack_from("<IB", data)
        if magic == MAGIC and version != VERSION:
            raise OtherVersion(version)
    expected = SIZE_AUTHENTICATED if key else SIZE
    if len(data) != expected:
        raise Malformed(f"size {len(data)} bytes, expected {expected}")
    body = data[:_BODY.size]
    if key:
        if not hmac.compare_digest(hmac.new(key, body, hashlib.sha256).digest(), data[_BODY.size:]):
            raise Malformed("bad HMAC (wrong or missing key)")
    else:
        (crc,) = _CRC.unpack_from(data, _BODY.size)
        if zlib.crc32(body) != crc:
            raise Malformed("bad CRC")
    magic, _version, typ, flags, session, seq, t_ns, a, b, c, u, w = _BODY.unpack(body)
    if magic != MAGIC:
        raise Malformed(f"bad magic 0x{magic:08x}")
    if bool(flags & FLAG_AUTHENTICATED) != bool(key):
        raise Malformed("authentication flag does not match this side's key")
    if typ not in TYPE_NAMES:
        raise Malformed(f"unknown type {typ}")
    return Message(typ, seq, t_ns, a, b, u, w, session, c)


def is_v1_hello(data: bytes) -> bool:
    """A valid version-1 HELLO (an old model computer starting a session)."""
    if len(data) != V1_SIZE or zlib.crc32(data[:-4]) != _CRC.unpack_from(data, V1_SIZE - 4)[0]:
        return False
    magic, version, typ = _V1_BODY.unpack(data[:-4])[:3]
    return magic == MAGIC and version == 1 and typ == HELLO


def v1_refusal() -> bytes:
    """A version-1 STATUS in fault (fault bit FAULT_VERSION, a = the version spoken here): a version-1
    peer reads it as a rig in fault and stops."""
    body = _V1_BODY.pack(MAGIC, 1, STATUS, 0, 0, 0, float(VERSION), 0.0, RIG_FAULT, FAULT_VERSION)
    return body + _CRC.pack(zlib.crc32(body))


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
