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
    assert ring.fits(np.ones(RING // 64)) and not ring.fits(np.ones(RING // 64 + 1))  # an eighth of the ring


def test_a_span_larger_than_the_ring_is_handed_over_in_parts(tmp_path, monkeypatch):
    """A span's blocks that need more than the whole ring: the recorder hands over what it put before the ring
    could fill with blocks the writer has not heard of (else it would wait for ever), and the log holds every
    row, in order."""
    import threading

    from pantohil.orchestrator import recorder
    from pantohil.orchestrator.mcap_follow import read_log

    monkeypatch.setattr(recorder, "RING_BYTES", 1 << 16)
    path, rows, blocks = tmp_path / "run.mcap", 500, 40  # 12 kB a block, 480 kB a span, a 64 KiB ring
    values = np.random.default_rng(5).normal(size=(3 * blocks * rows, 2))
    log = recorder.McapRecorder(path, {"/g": {"a": "[-]", "b": "[-]"}})

    def spans():
        for k in range(0, len(values), rows):
            log.write_block("/g", np.arange(k, k + rows) * 1e-3, values[k:k + rows])
            if (k // rows + 1) % blocks == 0:
                log.flush()
        log.close()

    worker = threading.Thread(target=spans, daemon=True)
    worker.start()
    worker.join(120)
    assert not worker.is_alive(), "the recorder waited for room in the ring that nothing frees"
    got = np.array([[m["a"], m["b"]] for _, _, m in read_log(path, ("/g",))])
    assert np.array_equal(got, values)
