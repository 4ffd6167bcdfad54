"""The rig link's codec (docs/udp-protocol.md) and the actuator limiter."""
import dataclasses
import math
import random
import struct
import zlib

import numpy as np
import pytest

from pantohil.fmus import udp_protocol as proto
from pantohil.models.rig.actuator import ActuatorLimits, Limiter


def _example(t: int) -> proto.Message:
    """A message of type t with every field its type carries set."""
    m = proto.Message(t, 123456, 987654321, a=1.25, b=-3.5, u=2, w=7, session=2**64 - 3, c=0.5)
    if t in (proto.HELLO, proto.STATUS):
        return dataclasses.replace(m, horizon=50)
    if t in (proto.COMMAND, proto.ANSWER):
        return dataclasses.replace(m, u=3, ahead=((0.01, 0.2), (-0.02, -0.3)))
    if t in (proto.FORCE, proto.SAMPLE):
        return dataclasses.replace(m, fresh=11, predicted=22, uncovered=33)
    return m


SIZES = {proto.BYE: 64, proto.HELLO: 68, proto.STATUS: 68, proto.FORCE: 76, proto.SAMPLE: 76,
         proto.COMMAND: 48 + 16 * 3, proto.ANSWER: 48 + 16 * 3}  # docs/udp-protocol.md, "Datagrams"


def test_round_trip_every_type_at_its_documented_size():
    for t in proto.TYPE_NAMES:
        m = _example(t)
        data = proto.encode(m)
        assert len(data) == SIZES[t] == proto.datagram_size(t, 3)
        assert proto.decode(data) == m


def test_a_full_horizon_fits_one_ethernet_frame_and_no_more_is_encoded():
    ahead = tuple((0.001 * i, 0.0) for i in range(proto.MAX_HORIZON_STEPS - 1))
    m = proto.Message(proto.ANSWER, 1, 0, a=0.0, session=3, ahead=ahead)
    assert len(proto.encode(m, b"k" * 32)) == 1100 <= 1472  # 1500-byte MTU less the IP and UDP headers
    assert proto.decode(proto.encode(m)).ahead == ahead
    with pytest.raises(ValueError, match="at most 64"):
        proto.encode(dataclasses.replace(m, ahead=ahead + ((0.0, 0.0),)))


@pytest.mark.parametrize("mutate,why", [
    (lambda d: d[:-1], "size"),
    (lambda d: d + b"\x00", "CRC"),
    (lambda d: b"", "size"),
    (lambda d: bytes([d[0] ^ 1]) + d[1:], "CRC"),
])
def test_malformed_datagrams_are_named(mutate, why):
    data = proto.encode(proto.Message(proto.COMMAND, 1, 0, a=0.1))
    with pytest.raises(proto.Malformed, match=why):
        proto.decode(mutate(data))


def _with_crc(body: bytes) -> bytes:
    return body + struct.pack("<I", zlib.crc32(body))


def test_bad_magic_version_type_and_height_count_with_a_valid_crc():
    fmt = struct.Struct("<IBBHQIQdddII")
    with pytest.raises(proto.Malformed, match="magic"):
        proto.decode(_with_crc(fmt.pack(0xDEADBEEF, 3, 5, 0, 5, 1, 0, 0.0, 0.0, 0.0, 0, 0)))
    with pytest.raises(proto.OtherVersion, match="version 9"):
        proto.decode(_with_crc(fmt.pack(proto.MAGIC, 9, 2, 0, 5, 1, 0, 0.0, 0.0, 0.0, 0, 0)))
    with pytest.raises(proto.Malformed, match="type"):
        proto.decode(_with_crc(fmt.pack(proto.MAGIC, 3, 99, 0, 5, 1, 0, 0.0, 0.0, 0.0, 0, 0)))
    for u in (0, 65):  # a COMMAND of 0 or 65 heights, whatever follows
        with pytest.raises(proto.Malformed, match="heights"):
            proto.decode(_with_crc(fmt.pack(proto.MAGIC, 3, proto.COMMAND, 0, 5, 1, 0, 0.0, 0.0, 0.0, u, 0)))
    two = fmt.pack(proto.MAGIC, 3, proto.COMMAND, 0, 5, 1, 0, 0.0, 0.0, 0.0, 2, 0)  # says 2 heights, carries 1
    with pytest.raises(proto.Malformed, match="size"):
        proto.decode(_with_crc(two))


@pytest.mark.parametrize("version,size", [(1, 48), (2, 64)])
def test_an_older_hello_is_recognised_and_refused_in_its_own_version(version, size):
    if version == 1:
        layout = struct.Struct("<IBBHIQddII")
        hello = _with_crc(layout.pack(proto.MAGIC, 1, proto.HELLO, 0, 0, 0, 0.001, 0.0, 0, 0))
    else:
        layout = struct.Struct("<IBBHQIQdddII")
        hello = _with_crc(layout.pack(proto.MAGIC, 2, proto.HELLO, 0, 77, 0, 0, 0.001, 0.0, 0.0, 0, 0))
    assert len(hello) == size and proto.old_hello_version(hello) == version
    with pytest.raises(proto.OtherVersion, match=f"version {version}"):
        proto.decode(hello)
    refusal = proto.old_refusal(version, 77)
    assert len(refusal) == size and zlib.crc32(refusal[:-4]) == struct.unpack("<I", refusal[-4:])[0]
    fields = layout.unpack(refusal[:-4])
    magic, got, typ, state, faults = fields[0], fields[1], fields[2], fields[-2], fields[-1]
    a = fields[6] if version == 1 else fields[7]
    assert (magic, got, typ, a, state, faults) == (proto.MAGIC, version, proto.STATUS, 3.0, proto.RIG_FAULT,
                                                   proto.FAULT_VERSION)
    if version == 2:
        assert proto.other_version_status(refusal, 77) and not proto.other_version_status(refusal, 78)
    assert proto.old_hello_version(proto.encode(proto.Message(proto.HELLO, 0, 0, a=0.001, session=7))) is None


def test_authenticated_datagrams_need_the_key_and_cover_the_horizon():
    key, other = b"k" * 32, b"j" * 32
    m = proto.Message(proto.COMMAND, 9, 10, a=0.01, session=42, ahead=((0.02, 0.1),))
    signed = proto.encode(m, key)
    assert len(signed) == proto.datagram_size(proto.COMMAND, 2, authenticated=True) == 48 + 32 + 28
    assert proto.decode(signed, key) == dataclasses.replace(m, u=2)
    for data, k in ((signed, other), (signed, None), (proto.encode(m), key)):
        with pytest.raises(proto.Malformed):
            proto.decode(data, k)
    for byte in (30, 62):  # the first height, and the horizon's
        tampered = bytearray(signed)
        tampered[byte] ^= 1
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
        assert not proto.finite(proto.Message(proto.COMMAND, 1, 0, ahead=((0.0, 0.0), (bad, 0.0))))
        assert not proto.finite(proto.Message(proto.COMMAND, 1, 0, ahead=((0.0, bad),)))


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


def test_the_limiters_preview_is_the_limiter_run_ahead_and_leaves_it_unchanged():
    rng = np.random.default_rng(0)
    checked_slow = 0
    for _ in range(200):
        lim = ActuatorLimits(stroke_min_m=-0.05, stroke_max_m=0.05, max_velocity_m_s=rng.uniform(0.05, 2),
                             max_acceleration_m_s2=rng.uniform(5, 300))
        limiter = Limiter(lim, 0.002, 0.0)
        wanted = rng.uniform(0.001, 0.08) * np.sin(2 * np.pi * rng.uniform(0.5, 20) * np.arange(300) * 0.002)
        for w in wanted[:200]:
            limiter(w)
        state = (limiter.z, limiter.v, limiter.limited)
        z, v = limiter.preview(wanted[200:263])
        assert (limiter.z, limiter.v, limiter.limited) == state
        checked_slow += not limiter._passes(wanted[200:263])
        run = np.array([limiter(w) for w in wanted[200:263]])
        # the fast path's heights are the wanted ones; the limiter's differ from them by rounding only
        assert np.max(np.abs(z - run[:, 0])) < 1e-15 and np.max(np.abs(v - run[:, 1])) < 1e-9
    assert 20 < checked_slow < 180  # both paths were taken
