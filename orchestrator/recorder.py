"""MCAP run log: one JSON-schema channel per signal group (Foxglove plots `/topic.field`).

Samples are buffered by the master and handed over a span at a time to a writer process, so that
logging costs the stepping loop almost nothing. `close()` always finishes the file, and the writer
finishes it by itself if the run's process dies, so a run that stops early stays readable.
"""
from __future__ import annotations

import fcntl
import json
import math
import multiprocessing as mp
import os
from pathlib import Path

import numpy as np
from mcap.writer import Writer

from .pacing import background_priority


def _schema(title: str, fields: dict[str, str]) -> bytes:
    props = {"t": {"type": "number", "description": "simulated time [s]"}}
    props.update({name: {"type": "number", "description": desc} for name, desc in fields.items()})
    return json.dumps({"title": title, "type": "object", "properties": props}).encode()


class McapWriter:
    """Writes messages in the calling process."""

    def __init__(self, path: Path, groups: dict[str, dict[str, str]], metadata: dict[str, str] | None = None):
        self._fh = open(path, "wb")
        self._writer = Writer(self._fh)
        self._writer.start(profile="", library="pantohil")
        if metadata:
            self._writer.add_metadata("run", {k: str(v) for k, v in metadata.items()})
        self._channels = {}
        self._templates = {}
        self._fields = {topic: list(fields) for topic, fields in groups.items()}
        for topic, fields in groups.items():
            sid = self._writer.register_schema(topic.strip("/"), "jsonschema", _schema(topic, fields))
            self._channels[topic] = self._writer.register_channel(topic, "json", sid)
            names = ["t", *fields]
            self._templates[topic] = "{" + ",".join(f'"{n}":%.10g' for n in names) + "}"
        self.messages = 0
        self._closed = False

    def write_block(self, topic: str, t: np.ndarray, columns: np.ndarray) -> None:
        """Write rows (t[i], columns[i, :]) as messages of one channel."""
        channel, template, add = self._channels[topic], self._templates[topic], self._writer.add_message
        columns = np.asarray(columns, dtype=float)
        finite = bool(np.isfinite(columns).all())
        keys = ["t", *self._fields[topic]]
        for ti, row in zip(t.tolist(), columns.tolist()):
            ns = int(round(ti * 1e9))
            if finite:
                data = (template % (ti, *row)).encode()
            else:  # JSON has no NaN/inf: write null
                data = json.dumps(dict(zip(keys, [ti, *[v if math.isfinite(v) else None for v in row]]))).encode()
            add(channel, ns, data, ns)
        self.messages += len(t)

    def write_event(self, topic: str, t: float, record: dict) -> None:
        if topic not in self._channels:
            sid = self._writer.register_schema(topic.strip("/"), "jsonschema",
                                               json.dumps({"title": topic, "type": "object"}).encode())
            self._channels[topic] = self._writer.register_channel(topic, "json", sid)
        ns = int(round(t * 1e9))
        self._writer.add_message(self._channels[topic], ns, json.dumps({"t": t, **record}).encode(), ns)
        self.messages += 1

    def close(self) -> None:
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
        try:
            fcntl.fcntl(self._send.fileno(), fcntl.F_SETPIPE_SZ, PIPE_BYTES)
        except (OSError, AttributeError):
            pass  # the default pipe size only makes logging block a little longer
        self._proc = ctx.Process(target=_writer_process, args=(recv, str(path), groups, metadata),
                                 name="pantohil-mcap", daemon=False)
        self._proc.start()
        recv.close()
        self.messages = 0
        self._closed = False

    def write_block(self, topic: str, t: np.ndarray, columns: np.ndarray) -> None:
        self._send.send(("block", topic, np.asarray(t), np.asarray(columns)))
        self.messages += len(t)

    def write_event(self, topic: str, t: float, record: dict) -> None:
        self._send.send(("event", topic, t, record))
        self.messages += 1

    def close(self, timeout_s: float = 120.0) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self._send.send(("close",))
        except (BrokenPipeError, OSError):
            pass
        self._send.close()
        self._proc.join(timeout_s)
        if self._proc.exitcode not in (0, None):
            raise RuntimeError(f"MCAP writer process failed with exit code {self._proc.exitcode}")
