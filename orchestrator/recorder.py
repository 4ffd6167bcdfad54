"""MCAP run log: one JSON-schema channel per signal group (Foxglove plots `/topic.field`).

Samples are buffered by the master and handed over a span at a time to a writer process, so that
logging costs the stepping loop almost nothing. `close()` always finishes the file, and the writer
finishes it by itself if the run's process dies, so a run that stops early stays readable.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import logging
import multiprocessing as mp
import os
import resource
import signal
from pathlib import Path

import foxglove
import numpy as np
from foxglove.mcap import MCAPCompression, MCAPWriteOptions

from .channels import EVENT_SCHEMAS, RowEncoder, encode_event, event_schema, group_schema, schema_name
from .pacing import background_priority
from .stopping import shielded


def _quiet_sdk() -> None:
    """foxglove-sdk prints one line per message it fails to log (a full disk: one per remaining message of
    the block, hundreds); the writer's flush and close raise the failure once, which is what is reported.
    Its own log goes below CRITICAL, without the root handler its set-up would add."""
    root = logging.getLogger()
    handlers = list(root.handlers)
    foxglove.set_log_level(logging.CRITICAL)
    for handler in [h for h in root.handlers if h not in handlers]:
        root.removeHandler(handler)


_quiet_sdk()
CHUNK_BYTES = 1 << 16  # small chunks: a file cut short loses at most one; `pantohil watch` reads complete chunks


class McapWriter:
    """Writes messages in the calling process, through foxglove-sdk's MCAP writer (zstd chunks).

    Every channel is registered when the writer opens; a channel appears in the file with its first
    message (foxglove-sdk writes a channel's records lazily)."""

    def __init__(self, path: Path, groups: dict[str, dict[str, str]], metadata: dict[str, str] | None = None):
        self._context = foxglove.Context()  # this file's own channels, apart from a live server's
        options = MCAPWriteOptions(compression=MCAPCompression.Zstd, compression_threads=0, chunk_size=CHUNK_BYTES,
                                   profile="")
        self._writer = foxglove.open_mcap(Path(path), allow_overwrite=True, context=self._context,
                                          writer_options=options)
        if metadata:
            self._writer.write_metadata("run", {k: str(v) for k, v in metadata.items()})
        self._channels = {}
        self._encoders = {}
        for topic, fields in groups.items():
            self._channels[topic] = self._channel(topic, group_schema(topic, fields))
            self._encoders[topic] = RowEncoder(fields)
        for topic in EVENT_SCHEMAS:
            self._event_channel(topic)
        self.messages = 0
        self._closed = False

    def _channel(self, topic: str, schema: bytes):
        return foxglove.Channel(topic, message_encoding="json", context=self._context,
                                schema=foxglove.Schema(name=schema_name(topic), encoding="jsonschema", data=schema))

    def write_block(self, topic: str, t: np.ndarray, columns: np.ndarray) -> None:
        """Write rows (t[i], columns[i, :]) as messages of one channel, at log time t[i]."""
        log = self._channels[topic].log
        encoded = self._encoders[topic].encode(t, columns)
        for ns, data in zip(np.rint(np.asarray(t, dtype=float) * 1e9).astype(np.int64).tolist(), encoded,
                            strict=False):
            log(data, log_time=ns)
        self.messages += len(t)

    def _event_channel(self, topic: str):
        if topic not in self._channels:
            self._channels[topic] = self._channel(topic, event_schema(topic))
        return self._channels[topic]

    def write_event(self, topic: str, t: float, record: dict) -> None:
        """Log one JSON message (a per-span record or an event) on a topic at simulated time t [s]."""
        self._event_channel(topic).log(encode_event(t, record), log_time=int(round(t * 1e9)))
        self.messages += 1

    def flush(self) -> None:
        """Close the current chunk and hand the file's bytes to the OS, so that a reader of the growing
        file sees whole records."""
        self._writer.flush()

    def close(self) -> None:
        """Finish the MCAP file (summary and footer) once, so that it stays readable."""
        if not self._closed:
            self._closed = True
            self._writer.close()


PIPE_BYTES = 1 << 20  # a span of samples fits: handing it over never blocks the stepping loop
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


def _writer_process(conn, send_end, parent_pid: int, path: str, groups: dict, metadata: dict | None) -> None:
    send_end.close()  # only the parent may hold the writing end: its death is then an end of file here
    _detach_from_parent()
    background_priority()  # the stepping loop and a rig emulator on this machine come first
    writer = None
    try:
        writer = McapWriter(Path(path), groups, metadata)
        while (msg := _receive(conn, parent_pid)) is not None:
            if msg[0] == "block":
                writer.write_block(*msg[1:])
            elif msg[0] == "event":
                writer.write_event(*msg[1:])
            writer.flush()
        writer.close()
    except Exception:  # a full disk, a size limit: the file keeps its complete chunks; the parent says why
        with contextlib.suppress(Exception):
            writer is not None and writer.close()
        os._exit(WRITE_FAILED)
    finally:
        conn.close()


def _write_error(path: Path) -> OSError:
    """The error of a writer process that could not write `path` (foxglove-sdk does not say which): the
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
        with contextlib.suppress(OSError, AttributeError):  # the default pipe size only blocks logging longer
            fcntl.fcntl(self._send.fileno(), fcntl.F_SETPIPE_SZ, PIPE_BYTES)
        self._proc = ctx.Process(target=_writer_process,
                                 args=(recv, self._send, os.getpid(), str(path), groups, metadata),
                                 name="pantohil-mcap", daemon=False)
        self._proc.start()
        recv.close()
        self._path = Path(path)
        self.messages = 0
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
        """Send a block of per-step rows of a topic to the logger process."""
        self._post(("block", topic, np.asarray(t), np.asarray(columns)), len(t))

    def write_event(self, topic: str, t: float, record: dict) -> None:
        """Send one JSON message of a topic to the logger process."""
        self._post(("event", topic, t, record), 1)

    def flush(self) -> None:
        """Nothing to do: the logger process flushes after every message it writes."""

    def close(self, timeout_s: float = 120.0) -> None:
        """Tell the logger process to finish the MCAP file and wait for it, at most timeout_s."""
        if self._closed:
            return
        self._closed = True
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
