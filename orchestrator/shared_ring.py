"""Arrays handed from the run's process to its MCAP writer process through shared memory, not a pipe: the run
copies a block in (`put`) and sends only where it lies; the writer reads it in place (`get`) and, once it has
taken what it needs, marks everything up to a position consumed (`consume`), which frees the room for the run.

One producer, one consumer, blocks consumed in the order they were put. The producer hands over what it put
before the blocks it has not handed over could fill the ring (`unsent_room`), else it would wait for room
that only the consumer, which has not heard of them, can free. The memory is an anonymous shared
mapping made before the writer is forked; its first 8 bytes count the bytes consumed, written by the writer
only. A block that does not fit before the end of the ring starts again at its beginning.
"""
from __future__ import annotations

import mmap
import time
from collections.abc import Callable

import numpy as np
from pantohil.models.errors import PantohilError

_HEAD = 8  # bytes consumed so far (uint64), written by the consumer
WAIT_S = 0.0005  # between two looks at the consumer's count while the ring is full


class RingClosed(PantohilError, RuntimeError):
    """The consumer stopped while the producer waited for room (the recorder reports its writer's error)."""


class SharedRing:
    """A ring of `size_bytes` in shared memory; `put` in the producer, `get` and `consume` in the consumer."""

    def __init__(self, size_bytes: int):
        self.size = int(size_bytes)
        self._memory = mmap.mmap(-1, _HEAD + self.size)  # MAP_SHARED: the forked writer sees the same pages
        self._consumed = np.frombuffer(self._memory, dtype="<u8", count=1)
        self._data = np.frombuffer(self._memory, dtype=np.uint8, offset=_HEAD)
        self.produced = 0  # bytes put so far (the producer's count), block padding included

    def fits(self, array: np.ndarray) -> bool:
        """Whether a block of this array's size goes through the ring (at most an eighth of it; else it goes
        another way), so that the producer's blocks not yet handed over never need the whole ring."""
        return np.asarray(array).size * 8 <= self.size // 8

    def put(self, array: np.ndarray, alive: Callable[[], bool]) -> tuple[int, tuple[int, ...]]:
        """Copy a float64 array into the ring, waiting while the consumer has not freed the room (RingClosed
        if `alive()` turns false meanwhile); where it lies: (offset, shape)."""
        block = np.ascontiguousarray(array, dtype="<f8")
        start = self.produced % self.size
        if start + block.nbytes > self.size:  # not before the end: the padding is consumed with the block
            self.produced += self.size - start
            start = 0
        while self.produced + block.nbytes - int(self._consumed[0]) > self.size:
            if not alive():
                raise RingClosed("the MCAP writer process stopped")
            time.sleep(WAIT_S)
        self._data[start:start + block.nbytes] = block.reshape(-1).view(np.uint8)
        self.produced += block.nbytes
        return start, block.shape

    def unsent_room(self, handed_over: int, arrays) -> bool:
        """Whether `arrays` can be put after the blocks put since the producer's count `handed_over` without those
        blocks (with the worst padding) filling the ring."""
        need = sum(np.asarray(a).size * 8 for a in arrays)
        return self.produced - handed_over + 2 * need <= self.size

    def get(self, offset: int, shape: tuple[int, ...]) -> np.ndarray:
        """The block put at `offset` with `shape`, read in place (valid until `consume` passes it)."""
        count = int(np.prod(shape, dtype=np.int64))
        return np.frombuffer(self._memory, dtype="<f8", count=count, offset=_HEAD + offset).reshape(shape)

    def consume(self, upto: int) -> None:
        """Free everything put up to the producer's count `upto`."""
        self._consumed[0] = upto
