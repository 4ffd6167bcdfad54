"""MCAP run log: one channel per signal group (Foxglove plots `/topic.field`): per-step groups as ROS 2
messages of float64 fields (CDR), per-span records as JSON (orchestrator/channels.py).

Samples are buffered by the master and handed over a span at a time to a writer process, so that
logging costs the stepping loop almost nothing: the span's arrays through shared memory
(orchestrator/shared_ring.py), one small message per span through a pipe. The writer turns the span into a
chunk with numpy (orchestrator/mcap_file.py). `close()` always finishes the file, and the writer finishes it
by itself if the run's process dies, so a run that stops early stays readable.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import multiprocessing as mp
import os
import resource
import signal
from pathlib import Path

import numpy as np

from .channels import (EVENT_SCHEMAS, GROUP_MESSAGE_ENCODING, GROUP_SCHEMA_ENCODING, RowEncoder, encode_event,
                       event_schema, group_schema, group_schema_name, schema_name)
from .mcap_file import CHUNK_BYTES, McapFile
from .pacing import background_priority
from .shared_ring import RingClosed, SharedRing
from .stopping import shielded


class McapWriter:
    """Writes a run's log in the calling process. Every channel is written when the writer opens."""

    def __init__(self, path: Path, groups: dict[str, dict[str, str]], metadata: dict[str, str] | None = None):
        self._file = McapFile(Path(path))
        if metadata:
            self._file.metadata("run", {k: str(v) for k, v in metadata.items()})
        self._channels = {}
        self._encoders = {}
        for topic, fields in groups.items():
            schema = self._file.schema(group_schema_name(topic), GROUP_SCHEMA_ENCODING, group_schema(topic, fields))
            self._channels[topic] = self._file.channel(topic, schema, GROUP_MESSAGE_ENCODING)
            self._encoders[topic] = RowEncoder(fields)
        for topic in EVENT_SCHEMAS:
            self._event_channel(topic)
        self.messages = 0
        self._closed = False

    def write_block(self, topic: str, t: np.ndarray, columns: np.ndarray) -> None:
        """Write rows (t[i], columns[i, :]) as messages of one channel, at log time t[i]."""
        t = np.asarray(t, dtype=float)
        self._file.messages(self._channels[topic], np.rint(t * 1e9).astype(np.int64),
                            self._encoders[topic].rows(t, columns))
        self.messages += len(t)

    def _event_channel(self, topic: str) -> int:
        if topic not in self._channels:
            schema = self._file.schema(schema_name(topic), "jsonschema", event_schema(topic))
            self._channels[topic] = self._file.channel(topic, schema, "json")
        return self._channels[topic]

    def write_event(self, topic: str, t: float, record: dict) -> None:
        """Log one JSON message (a per-span record or an event) on a topic at simulated time t [s]."""
        data = np.frombuffer(encode_event(t, record), dtype=np.uint8)
        self._file.messages(self._event_channel(topic), np.array([int(round(t * 1e9))]), data.reshape(1, -1))
        self.messages += 1

    def flush(self) -> None:
        """Write what was logged since the last flush as a chunk, so that a reader of the growing file sees it."""
        self._file.flush()

    def close(self) -> None:
        """Finish the MCAP file (summary and footer) once, so that it stays readable."""
        if not self._closed:
            self._closed = True
            self._file.close()


PIPE_BYTES = 1 << 20  # a span's message fits: handing it over never blocks the stepping loop
RING_BYTES = 16 << 20  # spans of samples waiting for the writer (about 150 spans of the default case)
WRITE_FAILED = 75  # exit code of a writer process whose file could not be written
POLL_S = 0.25  # how often a writer waiting for the next message looks whether its parent is still there


def _detach_from_parent() -> None:
    """The writer outlives a Ctrl-C to the process group: it stops when its parent says so, or dies."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)  # a closed terminal: the parent stops, then closes the file


def _receive(conn, parent_pid: int):
    """The next message; None at "close", at the end of the pipe, or once the parent is dead (this
    process was handed to another) and the pipe holds nothing more. A message is read only once the
    pipe has bytes, and is never interrupted: a signal's exception could drop a message already read."""
    try:
        while not conn.poll(POLL_S):
            if os.getppid() != parent_pid:
                return None
        msg = conn.recv()
    except (EOFError, OSError):  # the run's process is gone: finish what we have
        return None
    return None if msg[0] == "close" else msg


def _write_batch(writer: McapWriter, ring: SharedRing, batch: list, produced: int) -> None:
    """Write a span's entries (blocks in the ring or in the message, events), then free their room in the ring."""
    for kind, topic, *args in batch:
        if kind == "shared":
            writer.write_block(topic, ring.get(*args[:2]), ring.get(*args[2:]))
        elif kind == "block":
            writer.write_block(topic, *args)
        else:
            writer.write_event(topic, *args)
    ring.consume(produced)


def _writer_process(conn, send_end, ring: SharedRing, parent_pid: int, path: str, groups: dict,
                    metadata: dict | None) -> None:
    send_end.close()  # only the parent may hold the writing end: its death is then an end of file here
    _detach_from_parent()
    background_priority()  # the stepping loop and a rig emulator on this machine come first
    writer = None
    try:
        writer = McapWriter(Path(path), groups, metadata)
        while (msg := _receive(conn, parent_pid)) is not None:
            if msg[0] == "batch":
                _write_batch(writer, ring, *msg[1:])
            writer.flush()
        writer.close()
    except Exception:  # a full disk, a size limit: the file keeps its complete chunks; the parent says why
        with contextlib.suppress(Exception):
            writer is not None and writer.close()
        os._exit(WRITE_FAILED)
    finally:
        conn.close()


def _write_error(path: Path) -> OSError:
    """The error of a writer process that could not write `path` (its exit code does not say which): the
    file size limit reached (EFBIG), no room left on its disk (ENOSPC), else an I/O error."""
    code = errno.EIO
    with contextlib.suppress(OSError):
        limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
        st = os.statvfs(path.parent)
        if limit != resource.RLIM_INFINITY and path.stat().st_size + 2 * CHUNK_BYTES >= limit:
            code = errno.EFBIG
        elif st.f_bavail * st.f_frsize < 2 * CHUNK_BYTES:
            code = errno.ENOSPC
    return OSError(code, f"{os.strerror(code)}; {path.name} holds its complete chunks", str(path))


class McapRecorder:
    """The same interface as McapWriter, with the writing done by a child process.

    Create it before loading any FMU: the child is forked, and pythonfmu puts each FMU's resources
    folder first on sys.path, which a child should not inherit.
    """

    def __init__(self, path: Path, groups: dict[str, dict[str, str]], metadata: dict[str, str] | None = None):
        ctx = mp.get_context("fork")
        recv, self._send = ctx.Pipe(duplex=False)
        self._ring = SharedRing(RING_BYTES)
        with contextlib.suppress(OSError, AttributeError):  # the default pipe size only blocks logging longer
            fcntl.fcntl(self._send.fileno(), fcntl.F_SETPIPE_SZ, PIPE_BYTES)
        self._proc = ctx.Process(target=_writer_process,
                                 args=(recv, self._send, self._ring, os.getpid(), str(path), groups, metadata),
                                 name="pantohil-mcap", daemon=False)
        self._proc.start()
        recv.close()
        self._path = Path(path)
        self.messages = 0
        self._batch: list[tuple] = []
        self._batch_messages = 0
        self._handed_over = 0  # the ring's count at the last flush
        self._closed = False

    def _post(self, msg: tuple, messages: int) -> None:
        """Send one message whole, and count its `messages`: a stop signal waits for its end (half a message
        would leave the writer waiting for the rest, and this process waiting for the writer). A writer
        that stopped: its error."""
        try:
            with shielded():
                self._send.send(msg)
                self.messages += messages
        except (BrokenPipeError, ConnectionResetError):
            self._proc.join(10)
            raise _write_error(self._path) from None

    def write_block(self, topic: str, t: np.ndarray, columns: np.ndarray) -> None:
        """Add a block of per-step rows of a topic to what the next `flush` sends: copied into the shared ring
        (waiting while the writer has not freed the room), or in the message if it is larger than the ring."""
        t, columns = np.asarray(t, dtype=float), np.asarray(columns, dtype=float)
        if self._ring.fits(t) and self._ring.fits(columns):
            if not self._ring.unsent_room(self._handed_over, (t, columns)):
                self.flush()  # the writer frees only what it has been told of
            try:
                self._batch.append(("shared", topic, *self._ring.put(t, self._proc.is_alive),
                                    *self._ring.put(columns, self._proc.is_alive)))
            except RingClosed:
                self._proc.join(10)
                raise _write_error(self._path) from None
        else:
            self._batch.append(("block", topic, t, columns))
        self._batch_messages += len(t)

    def write_event(self, topic: str, t: float, record: dict) -> None:
        """Add one JSON message of a topic to what the next `flush` sends."""
        self._batch.append(("event", topic, t, record))
        self._batch_messages += 1

    def flush(self) -> None:
        """Send what was written since the last flush to the logger process in one message (one chunk of the
        file): one hand-over per span, however many groups it logs."""
        if self._batch:
            batch, messages = self._batch, self._batch_messages
            self._batch, self._batch_messages, self._handed_over = [], 0, self._ring.produced
            self._post(("batch", batch, self._ring.produced), messages)

    def close(self, timeout_s: float = 120.0) -> None:
        """Tell the logger process to finish the MCAP file and wait for it, at most timeout_s."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(BrokenPipeError, OSError):
            self.flush()
        with contextlib.suppress(BrokenPipeError, OSError), shielded():
            self._send.send(("close",))
        self._send.close()
        self._proc.join(timeout_s)
        if self._proc.is_alive():  # never left behind: it would hold the file open
            self._proc.kill()
            self._proc.join()
            raise RuntimeError(f"MCAP writer process did not finish {self._path.name} within {timeout_s:g} s")
        if self._proc.exitcode == WRITE_FAILED:
            raise _write_error(self._path)
        if self._proc.exitcode not in (0, None):
            raise RuntimeError(f"MCAP writer process failed with exit code {self._proc.exitcode}")
