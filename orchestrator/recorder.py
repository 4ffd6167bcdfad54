"""MCAP run log: one JSON-schema channel per signal group (Foxglove plots `/topic.field`).

Samples are buffered by the master and handed over a span at a time to a writer process, so that
logging costs the stepping loop almost nothing. `close()` always finishes the file, and the writer
finishes it by itself if the run's process dies, so a run that stops early stays readable.
"""
from __future__ import annotations

import contextlib
import fcntl
import multiprocessing as mp
from pathlib import Path

import numpy as np
from mcap.writer import Writer

from .channels import EVENT_SCHEMAS, RowEncoder, encode_event, event_schema, group_schema, schema_name
from .pacing import background_priority


CHUNK_BYTES = 1 << 18  # a chunk about every span of the default case: `pantohil watch` reads complete chunks


class McapWriter:
    """Writes messages in the calling process."""

    def __init__(self, path: Path, groups: dict[str, dict[str, str]], metadata: dict[str, str] | None = None):
        self._fh = open(path, "wb")  # noqa: SIM115 (open for the writer's life, closed in close())
        self._writer = Writer(self._fh, chunk_size=CHUNK_BYTES)
        self._writer.start(profile="", library="pantohil")
        if metadata:
            self._writer.add_metadata("run", {k: str(v) for k, v in metadata.items()})
        self._channels = {}
        self._encoders = {}
        for topic, fields in groups.items():
            sid = self._writer.register_schema(schema_name(topic), "jsonschema", group_schema(topic, fields))
            self._channels[topic] = self._writer.register_channel(topic, "json", sid)
            self._encoders[topic] = RowEncoder(fields)
        for topic in EVENT_SCHEMAS:  # per-span channels exist from the start, also in a run that stops early
            self._event_channel(topic)
        self.messages = 0
        self._closed = False

    def write_block(self, topic: str, t: np.ndarray, columns: np.ndarray) -> None:
        """Write rows (t[i], columns[i, :]) as messages of one channel."""
        channel, add = self._channels[topic], self._writer.add_message
        encoded = self._encoders[topic].encode(t, columns)
        for ti, data in zip(np.asarray(t, dtype=float).tolist(), encoded, strict=False):
            ns = int(round(ti * 1e9))
            add(channel, ns, data, ns)
        self.messages += len(t)

    def _event_channel(self, topic: str) -> int:
        if topic not in self._channels:
            sid = self._writer.register_schema(schema_name(topic), "jsonschema", event_schema(topic))
            self._channels[topic] = self._writer.register_channel(topic, "json", sid)
        return self._channels[topic]

    def write_event(self, topic: str, t: float, record: dict) -> None:
        """Log one JSON message (a per-span record or an event) on a topic at simulated time t [s]."""
        ns = int(round(t * 1e9))
        self._writer.add_message(self._event_channel(topic), ns, encode_event(t, record), ns)
        self.messages += 1

    def flush(self) -> None:
        """Hand what is written to the OS, so that a reader of the growing file sees whole records."""
        self._fh.flush()

    def close(self) -> None:
        """Finish the MCAP file (summary and footer) once, so that it stays readable."""
        if not self._closed:
            self._closed = True
            try:
                self._writer.finish()
            finally:
                self._fh.close()


PIPE_BYTES = 1 << 20  # a span of samples fits: handing it over never blocks the stepping loop


def _writer_process(conn, path: str, groups: dict, metadata: dict | None) -> None:
    background_priority()  # the stepping loop and a rig emulator on this machine come first
    writer = McapWriter(Path(path), groups, metadata)
    try:
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):  # the run's process is gone: finish what we have
                break
            if msg[0] == "block":
                writer.write_block(*msg[1:])
            elif msg[0] == "event":
                writer.write_event(*msg[1:])
                writer.flush()
            else:
                break
    finally:
        writer.close()
        conn.close()


class McapRecorder:
    """The same interface as McapWriter, with the writing done by a child process.

    Create it before loading any FMU: the child is forked, and pythonfmu puts each FMU's resources
    folder first on sys.path, which a child should not inherit.
    """

    def __init__(self, path: Path, groups: dict[str, dict[str, str]], metadata: dict[str, str] | None = None):
        ctx = mp.get_context("fork")
        recv, self._send = ctx.Pipe(duplex=False)
        with contextlib.suppress(OSError, AttributeError):  # the default pipe size only blocks logging longer
            fcntl.fcntl(self._send.fileno(), fcntl.F_SETPIPE_SZ, PIPE_BYTES)
        self._proc = ctx.Process(target=_writer_process, args=(recv, str(path), groups, metadata),
                                 name="pantohil-mcap", daemon=False)
        self._proc.start()
        recv.close()
        self.messages = 0
        self._closed = False

    def write_block(self, topic: str, t: np.ndarray, columns: np.ndarray) -> None:
        """Send a block of per-step rows of a topic to the logger process."""
        self._send.send(("block", topic, np.asarray(t), np.asarray(columns)))
        self.messages += len(t)

    def write_event(self, topic: str, t: float, record: dict) -> None:
        """Send one JSON message of a topic to the logger process."""
        self._send.send(("event", topic, t, record))
        self.messages += 1

    def close(self, timeout_s: float = 120.0) -> None:
        """Tell the logger process to finish the MCAP file and wait for it, at most timeout_s."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(BrokenPipeError, OSError):
            self._send.send(("close",))
        self._send.close()
        self._proc.join(timeout_s)
        if self._proc.exitcode not in (0, None):
            raise RuntimeError(f"MCAP writer process failed with exit code {self._proc.exitcode}")
