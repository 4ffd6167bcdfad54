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
        m = proto.Message(t, 123456, 987654321, a=1.25, b=-3.5, u=2, w=7, session=2**64 - 3, c=0.5)
        data = proto.encode(m)
        assert len(data) == proto.SIZE == 64
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
    fmt = struct.Struct("<IBBHQIQdddII")
    with pytest.raises(proto.Malformed, match="magic"):
        proto.decode(_with_crc(fmt.pack(0xDEADBEEF, 2, 2, 0, 5, 1, 0, 0.0, 0.0, 0.0, 0, 0)))
    with pytest.raises(proto.OtherVersion, match="version 9"):
        proto.decode(_with_crc(fmt.pack(proto.MAGIC, 9, 2, 0, 5, 1, 0, 0.0, 0.0, 0.0, 0, 0)))
    with pytest.raises(proto.Malformed, match="type"):
        proto.decode(_with_crc(fmt.pack(proto.MAGIC, 2, 99, 0, 5, 1, 0, 0.0, 0.0, 0.0, 0, 0)))


def test_a_version_1_hello_is_recognised_and_refused_in_version_1():
    v1 = struct.Struct("<IBBHIQddII")
    hello = _with_crc(v1.pack(proto.MAGIC, 1, proto.HELLO, 0, 0, 0, 0.001, 0.0, 0, 0))
    assert proto.is_v1_hello(hello)
    with pytest.raises(proto.OtherVersion, match="version 1"):
        proto.decode(hello)
    refusal = proto.v1_refusal()
    assert len(refusal) == 48 and zlib.crc32(refusal[:-4]) == struct.unpack("<I", refusal[-4:])[0]
    magic, version, typ, _, _, _, a, _, state, faults = v1.unpack(refusal[:-4])
    assert (magic, version, typ, a, state, faults) == (proto.MAGIC, 1, proto.STATUS, 2.0, proto.RIG_FAULT,
                                                       proto.FAULT_VERSION)
    assert not proto.is_v1_hello(proto.encode(proto.Message(proto.HELLO, 0, 0, a=0.001, session=7)))


def test_authenticated_datagrams_need_the_key():
    key, other = b"k" * 32, b"j" * 32
    m = proto.Message(proto.COMMAND, 9, 10, a=0.01, session=42)
    signed = proto.encode(m, key)
    assert len(signed) == proto.SIZE_AUTHENTICATED == 92
    assert proto.decode(signed, key) == m
    for data, k in ((signed, other), (signed, None), (proto.encode(m), key)):
        with pytest.raises(proto.Malformed):
            proto.decode(data, k)
    tampered = bytearray(signed)
    tampered[20] ^= 1  # the height
    with pytest.raises(proto.Malformed, match="HMAC"):
        proto.decode(bytes(tampered), key)


def test_session_ids_are_random_and_non_zero():
    ids = {proto.new_session_id() for _ in range(1000)}
    assert len(ids) == 1000 and 0 not in ids


def test_finite_checks_every_payload_value():
    assert proto.finite(proto.Message(proto.COMMAND, 1, 0, a=0.1, b=0.2, c=0.3))
    for bad in (math.nan, math.inf, -math.inf):
        for field in ("a", "b", "c"):
            assert not proto.finite(proto.Message(proto.COMMAND, 1, 0, **{field: bad}))


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


def test_a_slow_motion_rig_clock_stretches_the_wall_period_not_the_rig_time():
    from pantohil.orchestrator.rig_clock import RigClock

    real, slow = RigClock(0.001, 0, drift_ppm=100), RigClock(0.001, 0, drift_ppm=100, slow_motion=5)
    for _ in range(10):
        real.advance(), slow.advance()
    assert slow.due_ns == 5 * real.due_ns == 5 * 11 * 1_000_100
    assert slow.rig_time_ns(10) == real.rig_time_ns(10) == 10_000_000
