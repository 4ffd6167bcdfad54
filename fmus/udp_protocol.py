"""The pantohil rig link: fixed-size little-endian UDP datagrams (docs/udp-protocol.md).

    header  magic u32 | version u8 | type u8 | flags u16 | seq u32 | sample time u64 [ns]
    payload a f64 | b f64 | u u32 | w u32 (meaning by type)
    crc     u32 CRC-32 of everything before it

Every datagram is 48 bytes. Anything else (size, magic, version, type, CRC) is malformed.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

MAGIC = 0x31484850  # b"PHH1" little-endian
VERSION = 1
HELLO, COMMAND, FORCE, STATUS, BYE = 1, 2, 3, 4, 5
TYPE_NAMES = {HELLO: "hello", COMMAND: "command", FORCE: "force", STATUS: "status", BYE: "bye"}

# rig states carried by STATUS
RIG_READY, RIG_RUNNING, RIG_FAULT = 0, 1, 2

_BODY = struct.Struct("<IBBHIQddII")
SIZE = _BODY.size + 4


class Malformed(ValueError):
    """A datagram that is not a valid pantohil message; the text says why."""


@dataclass(frozen=True)
class Message:
    """One datagram. Payload meaning by type:
    HELLO   a = dt [s]                      (model -> rig: reset, start a session)
    COMMAND a = height [m], b = velocity [m/s]  (model -> rig)
    FORCE   a = measured force [N], b = actuator height [m], u = rig state  (rig -> model)
    STATUS  u = rig state, w = fault bits   (rig -> model heartbeat; also the answer to HELLO)
    BYE     (model -> rig: end of session)
    """

    type: int
    seq: int
    t_ns: int
    a: float = 0.0
    b: float = 0.0
    u: int = 0
    w: int = 0


def encode(m: Message) -> bytes:
    """The 48-byte datagram of a message: the little-endian body and its CRC-32 (docs/udp-protocol.md)."""
    body = _BODY.pack(MAGIC, VERSION, m.type, 0, m.seq & 0xFFFFFFFF, m.t_ns, m.a, m.b, m.u, m.w)
    return body + struct.pack("<I", zlib.crc32(body))


def decode(data: bytes) -> Message:
    """The message of a 48-byte datagram; Malformed names a wrong size, CRC, magic, version or type."""
    if len(data) != SIZE:
        raise Malformed(f"size {len(data)} bytes, expected {SIZE}")
    body = data[:-4]
    (crc,) = struct.unpack_from("<I", data, SIZE - 4)
    if zlib.crc32(body) != crc:
        raise Malformed("bad CRC")
    magic, version, typ, _flags, seq, t_ns, a, b, u, w = _BODY.unpack(body)
    if magic != MAGIC:
        raise Malformed(f"bad magic 0x{magic:08x}")
    if version != VERSION:
        raise Malformed(f"unsupported version {version}")
    if typ not in TYPE_NAMES:
        raise Malformed(f"unknown type {typ}")
    return Message(typ, seq, t_ns, a, b, u, w)


def parse_endpoint(text: str, listening: bool = False) -> tuple[str, int]:
    """HOST:PORT -> (host, port); port 0 (any free port) only for listening. ValueError with one line."""
    host, sep, port = text.rpartition(":")
    lowest = 0 if listening else 1
    if not sep or not host or not port.isdigit() or not lowest <= int(port) < 65536:
        raise ValueError(f"expected HOST:PORT, got {text!r}")
    return host, int(port)
