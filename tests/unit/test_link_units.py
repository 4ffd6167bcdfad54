"""The rig link's codec (docs/udp-protocol.md) and the actuator limiter."""
import math
import random
import struct
import zlib

import numpy as np
import pytest

from pantohil.fmus import udp_protocol as proto
from pantohil.models.rig.actuator import ActuatorLimits, Limiter


def test_round_trip_every_type():
    for t in proto.TYPE_NAMES:
        m = proto.Message(t, 123456, 987654321, a=1.25, b=-3.5, u=2, w=7)
        data = proto.encode(m)
        assert len(data) == proto.SIZE == 48
        assert proto.decode(data) == m


@pytest.mark.parametrize("mutate,why", [
    (lambda d: d[:-1], "size"),
    (lambda d: d + b"\x00", "size"),
    (lambda d: b"", "size"),
    (lambda d: bytes([d[0] ^ 1]) + d[1:], "CRC"),
])
def test_malformed_datagrams_are_named(mutate, why):
    data = proto.encode(proto.Message(proto.COMMAND, 1, 0, a=0.1))
    with pytest.raises(proto.Malformed, match=why):
        proto.decode(mutate(data))


def _with_crc(body: bytes) -> bytes:
    return body + struct.pack("<I", zlib.crc32(body))


def test_bad_magic_version_and_type_with_a_valid_crc():
    fmt = struct.Struct("<IBBHIQddII")
    with pytest.raises(proto.Malformed, match="magic"):
        proto.decode(_with_crc(fmt.pack(0xDEADBEEF, 1, 2, 0, 1, 0, 0.0, 0.0, 0, 0)))
    with pytest.raises(proto.Malformed, match="version"):
        proto.decode(_with_crc(fmt.pack(proto.MAGIC, 9, 2, 0, 1, 0, 0.0, 0.0, 0, 0)))
    with pytest.raises(proto.Malformed, match="type"):
        proto.decode(_with_crc(fmt.pack(proto.MAGIC, 1, 99, 0, 1, 0, 0.0, 0.0, 0, 0)))


def test_parse_endpoint():
    assert proto.parse_endpoint("127.0.0.1:47800") == ("127.0.0.1", 47800)
    for bad in ("127.0.0.1", ":80", "host:0", "host:70000", "host:x"):
        with pytest.raises(ValueError):
            proto.parse_endpoint(bad)


def test_limiter_never_exceeds_the_limits():
    lim = ActuatorLimits(-0.05, 0.04, 0.5, 40.0)
    dt = 1e-3
    rng = random.Random(3)
    limiter = Limiter(lim, dt)
    z = []
    for k in range(20000):
        wanted = 0.2 * math.sin(k * 0.01) + (rng.random() - 0.5) * (0.3 if k % 500 < 20 else 0.0)
        zk, vk = limiter(wanted)
        z.append(zk)
    z = np.array(z)
    v = np.diff(z) / dt
    a = np.diff(v) / dt
    assert z.min() >= lim.stroke_min_m and z.max() <= lim.stroke_max_m
    assert np.abs(v).max() <= lim.max_velocity_m_s * (1 + 1e-9)
    assert np.abs(a).max() <= lim.max_acceleration_m_s2 * (1 + 1e-6)
    assert limiter.limited > 0


def test_limiter_passes_feasible_commands_unchanged():
    limiter = Limiter(ActuatorLimits(), 1e-3)
    t = np.arange(2000) * 1e-3
    wanted = 0.01 * np.sin(2 * np.pi * 2 * t)
    got = np.array([limiter(w)[0] for w in wanted])
    assert np.max(np.abs(got - wanted)) < 1e-12 and limiter.limited == 0
