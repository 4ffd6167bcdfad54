"""Rig-paced: the force of a tick no answer covered (the actuator held) and the forces within
link.settle_after_hold_s after it are not taken as measured (docs/udp-protocol.md, "A session" rig-paced).

The test plays the rig on a real UDP socket, sending SAMPLEs whose `uncovered` count it chooses, to the
adapter's link client."""
from __future__ import annotations

import math
import socket
import threading

from pantohil.fmus import udp_protocol as proto
from pantohil.fmus.link_client import LINK_OK, LinkClient, LinkConfig
from pantohil.models.rig.actuator import ActuatorLimits

DT_S = 0.01


class ScriptedRig:
    """A rig-paced controller whose samples the test sends one by one."""

    def __init__(self):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(30.0)
        self.port = self.sock.getsockname()[1]
        self.peer = self.session = None
        self.ready = threading.Event()
        threading.Thread(target=self._handshake, daemon=True).start()

    def _handshake(self):
        while True:
            data, peer = self.sock.recvfrom(4096)
            m = proto.decode(data)
            if m.type == proto.HELLO:
                self.peer, self.session = peer, m.session
                self.sock.sendto(proto.encode(proto.Message(proto.STATUS, 0, 0, a=0.0, b=DT_S, u=proto.RIG_READY,
                                                            session=m.session, c=float(proto.PACED_BY_RIG),
                                                            horizon=m.horizon)), peer)
                self.ready.set()
                return

    def sample(self, k: int, force_N: float, uncovered: int):
        self.sock.sendto(proto.encode(proto.Message(proto.SAMPLE, k, k * 10_000_000, a=force_N, b=0.0,
                                                    u=proto.RIG_RUNNING, w=uncovered, session=self.session,
                                                    fresh=k - uncovered, uncovered=uncovered)), self.peer)


def run(settle_s: float, uncovered_at: dict[int, int], steps: int = 20) -> tuple[list[float], LinkClient]:
    """The forces the link client takes over `steps` samples; `uncovered_at[k]` is the rig's uncovered
    count from sample k on."""
    rig = ScriptedRig()
    client = LinkClient(LinkConfig(rig_host="127.0.0.1", rig_port=rig.port, dt_s=DT_S, limits=ActuatorLimits(),
                                   paced_by=proto.PACED_BY_RIG, horizon_steps=4, settle_after_hold_s=settle_s))
    client.open(0.0)
    assert rig.ready.wait(30.0) and client.session_started
    forces, uncovered = [], 0
    try:
        for k in range(1, steps + 1):
            uncovered = uncovered_at.get(k, uncovered)
            rig.sample(k, 100.0 + k, uncovered)
            client.step(0.0, (0.0,) * 3)
            forces.append(client.measured_force)
    finally:
        client.close()
        rig.sock.close()
    return forces, client


def test_forces_at_and_after_a_held_tick_are_not_measured():
    # ticks 5 and 6 uncovered; a settling time of 3 ticks holds out 7, 8, 9 as well
    forces, client = run(3 * DT_S, {5: 1, 6: 2})
    held = [k for k, f in enumerate(forces, start=1) if math.isnan(f)]
    assert held == [5, 6, 7, 8, 9]
    assert all(f == 100.0 + k for k, f in enumerate(forces, start=1) if k not in held)
    assert client.counts.held_out == 5 and client.counts.uncovered == 2 and client.state == LINK_OK


def test_a_jump_of_the_count_over_a_lost_sample_holds_out_the_next_one():
    # the rig's count grew by 3 between samples 10 and 11 (ticks the model never heard of): 11 is held out
    forces, client = run(0.0, {11: 3})
    assert [k for k, f in enumerate(forces, start=1) if math.isnan(f)] == [11]
    assert client.counts.held_out == 1


def test_without_held_ticks_every_force_is_measured():
    forces, client = run(0.05, {})
    assert forces == [100.0 + k for k in range(1, 21)] and client.counts.held_out == 0
