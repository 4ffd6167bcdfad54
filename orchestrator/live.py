"""Live view of a run: a Foxglove WebSocket server (foxglove-sdk) publishing the channels of run.mcap.

The stepping loop does no publishing. A background thread wakes every POLL_S (0.1 s) of wall time, reads the
steps the master has completed since its last wake from the master's records (rows that are never
written again), and publishes every `decimation`-th step (LIVE_RATE_HZ of simulated time: 10 x
fewer messages than the log at dt = 1 ms). Span figures are handed over with one deque append per
span. Every queue is bounded and drops the oldest: at most MAX_ROWS_PER_POLL rows per group and
wake (a run much faster than real time shows the newest ones of each wake), SPAN_QUEUE spans, and the server's
per-client backlog of BACKLOG_MESSAGES messages, so a slow or vanished viewer costs the run nothing.
"""
from __future__ import annotations

import collections
import functools
import logging
import threading
from collections.abc import Callable

import numpy as np

from .channels import (EVENT_SCHEMAS, GROUP_MESSAGE_ENCODING, GROUP_SCHEMA_ENCODING, RowEncoder, encode_event,
                       event_schema, group_schema, group_schema_name, schema_name, span_force_record)

LIVE_RATE_HZ = 100.0     # per-step channels, in simulated time (the log keeps every step)
POLL_S = 0.1             # wall time between two wakes of the publisher thread (each wake takes the GIL
                         # from the stepping thread: few wakes keep the run's step time unchanged)
MAX_ROWS_PER_POLL = 12   # per group and wake: at most 120 rows/s of wall time, whatever the run's speed;
                         # a real-time run at 100 Hz needs 10 per wake (a wake 20 ms late loses nothing)
SPAN_QUEUE = 8           # spans waiting to be published
BACKLOG_MESSAGES = 1024  # per client, in the server (foxglove-sdk drops the oldest when full)
DEFAULT_PORT = 8765      # Foxglove's usual port

Block = Callable[[str, int, int], np.ndarray]  # (topic, start, stop) -> columns of steps start..stop-1


@functools.cache
def _quiet_sdk() -> None:
    """foxglove-sdk's own log goes below CRITICAL (a viewer that drops its connection is not the run's news),
    without the root handler its set-up would add."""
    import foxglove

    root = logging.getLogger()
    handlers = list(root.handlers)
    foxglove.set_log_level(logging.CRITICAL)
    for handler in [h for h in root.handlers if h not in handlers]:
        root.removeHandler(handler)


def parse_live(value: str | None) -> tuple[str, int]:
    """--live [HOST:PORT]: loopback and Foxglove's port by default; port 0 picks a free one."""
    if value is None or value == "":
        return "127.0.0.1", DEFAULT_PORT
    host, sep, port = value.rpartition(":")
    if not sep:
        host, port = value, str(DEFAULT_PORT)
    try:
        number = int(port)
    except ValueError:
        raise ValueError(f"--live: expected HOST:PORT, got {value!r}") from None
    if not 0 <= number <= 65535:
        raise ValueError(f"--live: port must be 0-65535 (got {number})")
    return host or "127.0.0.1", number


class _Viewers:
    """foxglove-sdk server listener: notes the first subscription (a viewer is ready)."""

    def __init__(self):
        self.subscribed = threading.Event()

    def on_subscribe(self, client, channel) -> None:
        self.subscribed.set()

    def on_unsubscribe(self, client, channel) -> None:
        """A viewer that leaves changes nothing in the run (the server calls this for each channel)."""


class LivePublisher:
    """Publishes a run's groups while it steps. `completed()` is the number of steps whose records are
    final; `block(topic, start, stop)` their columns for a group."""

    def __init__(self, endpoint: tuple[str, int], groups: dict[str, dict[str, str]], dt_s: float,
                 completed: Callable[[], int], block: Block, name: str = "pantohil"):
        import foxglove

        _quiet_sdk()
        self._context = foxglove.Context()
        self._viewers = _Viewers()
        self._server = foxglove.start_server(name=name, host=endpoint[0], port=endpoint[1], context=self._context,
                                             server_listener=self._viewers, message_backlog_size=BACKLOG_MESSAGES)
        self.host, self.port = endpoint[0], self._server.port
        self._channels = {topic: self._channel(foxglove, topic, group_schema_name(topic), GROUP_SCHEMA_ENCODING,
                                               group_schema(topic, fields), GROUP_MESSAGE_ENCODING)
                          for topic, fields in groups.items()}
        self._channels.update({topic: self._channel(foxglove, topic, schema_name(topic), "jsonschema",
                                                    event_schema(topic), "json") for topic in EVENT_SCHEMAS})
        self._encoders = {topic: RowEncoder(fields) for topic, fields in groups.items()}
        self.dt_s = dt_s
        self.decimation = max(1, int(round(1.0 / (LIVE_RATE_HZ * dt_s))))
        self._completed, self._block = completed, block
        self._spans = collections.deque(maxlen=SPAN_QUEUE)
        self._next_step = 0
        self.published = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="pantohil-live", daemon=True)
        self._thread.start()

    def _channel(self, foxglove, topic: str, name: str, schema_encoding: str, schema: bytes, message_encoding: str):
        return foxglove.Channel(topic, schema=foxglove.Schema(name=name, encoding=schema_encoding, data=schema),
                                message_encoding=message_encoding, context=self._context)

    @property
    def url(self) -> str:
        """The WebSocket URL viewers connect to."""
        return f"ws://{self.host}:{self.port}"

    def wait_for_viewer(self, stopped: Callable[[], bool] = lambda: False) -> None:
        """Block until a client subscribes to a channel, or `stopped()` (a stop request of the run)."""
        while not self._viewers.subscribed.wait(0.2) and not stopped():
            pass

    def span_closed(self, t_s: float, record: dict, force: np.ndarray, previous: np.ndarray | None) -> None:
        """O(1) in the stepping thread: the arrays are the master's records, read by the publisher."""
        self._spans.append((t_s, record, force, previous))

    def _loop(self) -> None:
        while not self._stop.wait(POLL_S):
            self._publish()
        self._publish()  # what the run completed last

    def _publish(self) -> None:
        self._publish_steps(self._completed())
        while self._spans:
            t_s, record, force, previous = self._spans.popleft()
            self._log("/convergence", t_s, encode_event(t_s, record))
            self._log("/span_force", t_s, encode_event(t_s, span_force_record(record["span"], self.dt_s, force,
                                                                              previous)))

    def _publish_steps(self, stop: int) -> None:
        """Every decimation-th step in [next, stop), at most MAX_ROWS_PER_POLL of the newest."""
        d = self.decimation
        first = -(-self._next_step // d) * d
        if first >= stop:
            return
        first = max(first, (-(-stop // d) - MAX_ROWS_PER_POLL) * d)
        steps = np.arange(first, stop, d)
        t = steps * self.dt_s
        for topic, encoder in self._encoders.items():
            columns = self._block(topic, first, stop)[::d]
            for ti, data in zip(t.tolist(), encoder.encode(t, columns), strict=False):
                self._log(topic, ti, data)
        self._next_step = stop

    def _log(self, topic: str, t_s: float, data: bytes) -> None:
        self._channels[topic].log(data, log_time=int(round(t_s * 1e9)))
        self.published += 1

    def summary(self) -> dict:
        """The live part of summary.json: URL, decimation and rate, messages published, whether a viewer subscribed."""
        return {"url": self.url, "every_steps": self.decimation, "rate_hz": 1.0 / (self.decimation * self.dt_s),
                "published_messages": self.published, "viewer_subscribed": self._viewers.subscribed.is_set()}

    def close(self) -> None:
        """Publish what is left, then stop the server (clients see the connection close)."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join()
        self._server.stop()
