"""The shared ring between a run and its MCAP writer process (orchestrator/shared_ring.py): with a real forked
consumer, blocks of many sizes wrap around a small ring and arrive whole and in order; a producer facing a
full ring waits for the consumer, and stops when it is gone."""
from __future__ import annotations

import multiprocessing as mp

import numpy as np
import pytest

from pantohil.orchestrator.shared_ring import RingClosed, SharedRing

RING = 4096  # bytes: a block of up to 256 doubles fits, and the blocks below wrap around it many times


def _consumer(ring: SharedRing, descriptors, answers) -> None:
    """Echo each block back (a copy), then free its room."""
    while (msg := descriptors.recv()) is not None:
        offset, shape, produced = msg
        answers.send(ring.get(offset, shape).copy())
        ring.consume(produced)


def test_blocks_wrap_around_the_ring_and_arrive_whole_and_in_order():
    ctx = mp.get_context("fork")
    ring = SharedRing(RING)
    (d_recv, d_send), (a_recv, a_send) = ctx.Pipe(duplex=False), ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_consumer, args=(ring, d_recv, a_send))
    proc.start()
    rng = np.random.default_rng(3)
    blocks = [rng.normal(size=(int(n), 2)) for n in rng.integers(1, 128, size=400)]
    for block in blocks:  # one block in flight at a time: the ring's room is freed in between
        offset, shape = ring.put(block, proc.is_alive)
        d_send.send((offset, shape, ring.produced))
        assert np.array_equal(a_recv.recv(), block)
    d_send.send(None)
    proc.join(30)
    assert proc.exitcode == 0
    assert ring.produced > 20 * RING  # it went round many times


def test_a_full_ring_waits_for_the_consumer_and_stops_once_it_is_gone():
    ring = SharedRing(RING)
    block = np.ones(RING // 8 // 2)  # half the ring
    ring.put(block, lambda: True)
    ring.put(block, lambda: True)  # full now
    looks = []

    def alive():
        looks.append(1)
        if len(looks) == 3:
            ring.consume(ring.produced - block.nbytes)  # the consumer frees the first block
        return True

    offset, _ = ring.put(block, alive)  # waits until the first block is consumed, then takes its room
    assert offset == 0 and len(looks) == 3
    with pytest.raises(RingClosed):
        ring.put(block, lambda: False)
    assert not ring.fits(np.ones(RING // 8)) and ring.fits(block)
