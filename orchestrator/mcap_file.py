"""An MCAP file written a block of messages at a time (MCAP spec: records, chunks, message indexes, summary).

The per-step messages of a span are fixed-size rows, so their Message records, their message index and their
chunk are built as numpy arrays in one pass, not one call per message; the messages given between two flushes
(a span of every group, interleaved step by step, and its per-span records) make one chunk. Every other record
(header, schema, channel, metadata, statistics, chunk index, summary offsets, footer) is written by the `mcap`
library's record classes; a chunk's head (its fixed fields before its records) is packed here, so that its
records are not copied. A reader of the growing file sees whole records up to its last one, and a file cut
short keeps every chunk before the cut; a failed write cuts the file back to its last whole record and ends
the writing. Chunks carry the CRC of their records, the footer the summary's CRC.
"""
from __future__ import annotations

import contextlib
import os
import struct
import zlib
from pathlib import Path

import numpy as np
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Channel, ChunkIndex, DataEnd, Footer, Header, Metadata, MetadataIndex, Schema,
                          Statistics, SummaryOffset)

MAGIC = b"\x89MCAP0\r\n"
CHUNK_BYTES = 1 << 20  # records per chunk at most (a span of the default case's groups: 200 kB)
COMPRESSION = ""  # a step's doubles compress by about a fifth, for twice the writer's time: chunks stay plain
_RECORD_HEAD = 9  # opcode (1 byte) and content length (uint64)
_CHUNK_FIXED = struct.Struct("<QQQII")  # message start and end time, uncompressed size and CRC, compression's length
_INDEX_HEAD = struct.Struct("<BQHI")  # MessageIndex: opcode, length, channel, its pairs' byte length
_MESSAGE_HEAD = np.dtype([("opcode", "u1"), ("length", "<u8"), ("channel", "<u2"), ("sequence", "<u4"),
                          ("log_time", "<u8"), ("publish_time", "<u8")])  # packed: 31 bytes


def _serialised(*records) -> bytes:
    builder = RecordBuilder()
    for record in records:
        record.write(builder)
    return builder.end()


def message_records(channel: int, first_sequence: int, log_time_ns: np.ndarray, payload: np.ndarray) -> np.ndarray:
    """Message records (MCAP spec, Message) of one channel as a structured array, one record per row: record i
    holds payload[i] (any array of n fixed-size rows, the message's bytes) at log and publish time
    log_time_ns[i]."""
    n = len(payload)
    row = np.dtype((payload.dtype, payload.shape[1:])) if payload.ndim > 1 else payload.dtype
    records = np.empty(n, dtype=np.dtype(_MESSAGE_HEAD.descr + [("payload", row)]))
    records["opcode"] = int(Opcode.MESSAGE)
    records["length"] = records.itemsize - _RECORD_HEAD
    records["channel"] = channel
    records["sequence"] = (first_sequence + np.arange(n)) & 0xFFFFFFFF
    records["log_time"] = log_time_ns
    records["publish_time"] = log_time_ns
    records["payload"] = payload
    return records


def message_index(channel: int, log_time_ns: np.ndarray, offsets: np.ndarray) -> bytes:
    """The MessageIndex record of one channel in a chunk: (log time, offset in the chunk's records) per message."""
    pairs = np.empty((len(log_time_ns), 2), dtype="<u8")
    pairs[:, 0], pairs[:, 1] = log_time_ns, offsets
    body = pairs.tobytes()
    return _INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 2 + 4 + len(body), channel, len(body)) + body


def chunk_head(first_ns: int, last_ns: int, size: int, crc: int) -> bytes:
    """The bytes of a Chunk record before its records (MCAP spec, Chunk: opcode, length, message start and end
    time, uncompressed size and CRC, compression, records' length), for `size` bytes of records stored
    uncompressed whose CRC-32 is `crc`."""
    fixed = _CHUNK_FIXED.pack(first_ns, last_ns, size, crc, len(COMPRESSION))
    tail = COMPRESSION.encode() + size.to_bytes(8, "little")
    return bytes([Opcode.CHUNK]) + (len(fixed) + len(tail) + size).to_bytes(8, "little") + fixed + tail


def _bytes(part):
    """A record array's bytes as a flat uint8 view (bytes as they are)."""
    return part if isinstance(part, bytes) else np.ascontiguousarray(part).reshape(-1).view(np.uint8)


def _interleaved(pending: list) -> list:
    """The gathered (channel, log times, records) as pieces to write in order, each (records, [(channel, log
    times, offsets of its messages in the piece)]): the groups logged for the same steps (equal log times) are
    interleaved step by step, so that the chunk's messages are in time order; the others (a span's records, at
    its end) follow."""
    lone = [(r, [(ch, ns, np.arange(len(r)) * r.itemsize)]) for ch, ns, r in pending]
    steps = next((ns for _, ns, _ in pending if len(ns) > 1), None)
    same = [i for i, (_, ns, _) in enumerate(pending) if steps is not None and len(ns) == len(steps)
            and np.array_equal(ns, steps)]
    if len(same) < 2:
        return lone
    dtype = np.dtype([(f"m{j}", pending[i][2].dtype) for j, i in enumerate(same)])
    combined = np.empty(len(steps), dtype=dtype)
    for j, i in enumerate(same):
        combined[f"m{j}"] = pending[i][2]
    at = np.arange(len(steps)) * dtype.itemsize
    members = [(pending[i][0], pending[i][1], at + dtype.fields[f"m{j}"][1]) for j, i in enumerate(same)]
    return [(combined, members)] + [lone[i] for i in range(len(pending)) if i not in same]


class McapFile:
    """Appends records to a new MCAP file: `schema`, `channel`, `metadata`, `messages` (fixed-size rows of one
    channel, as many chunks as CHUNK_BYTES asks), `flush`, then `close` (data end, summary, footer)."""

    def __init__(self, path: Path, library: str = "pantohil"):
        self._fh = open(path, "wb", buffering=0)  # noqa: SIM115 (closed by close()); no buffer to retry a failure
        self._broken = False  # a write failed: the file ends with its last complete record, and nothing is added
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._counts: dict[int, int] = {}
        self._pending: list[tuple[int, np.ndarray, np.ndarray]] = []  # (channel, log times, records) of the chunk
        self._pending_bytes = 0
        self._closed = False
        self._append(MAGIC + _serialised(Header(profile="", library=library)))

    def _append(self, *parts) -> int:
        """Write `parts` (bytes or arrays) after the last record; their offset. A failed write cuts the file back
        to that offset, so that it ends with whole records, and marks it broken: nothing more is written."""
        if self._broken:
            raise OSError(f"{self._fh.name}: an earlier write failed")
        offset = self._fh.tell()
        try:
            for part in parts:
                view = memoryview(_bytes(part))
                while view:  # a raw file may take part of a write
                    view = view[self._fh.write(view):]
        except OSError:
            self._broken = True
            with contextlib.suppress(OSError):
                os.ftruncate(self._fh.fileno(), offset)
            raise
        return offset

    def schema(self, name: str, encoding: str, data: bytes) -> int:
        """Write a schema record; its id."""
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._append(_serialised(schema))
        return schema.id

    def channel(self, topic: str, schema_id: int, message_encoding: str) -> int:
        """Write a channel record; its id."""
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata={})
        self._channels.append(channel)
        self._counts[channel.id] = 0
        self._append(_serialised(channel))
        return channel.id

    def metadata(self, name: str, values: dict[str, str]) -> None:
        """Write a metadata record (and index it in the summary)."""
        data = _serialised(Metadata(name=name, metadata=values))
        self._metadata_indexes.append(MetadataIndex(offset=self._append(data), length=len(data), name=name))

    def messages(self, channel: int, log_time_ns: np.ndarray, payload: np.ndarray) -> None:
        """Add n messages of one channel to the chunk being gathered: `payload` an array of n fixed-size rows (a
        structured array, or an (n, size) uint8 array), each row a message's bytes. A chunk is written once it
        holds CHUNK_BYTES, and at `flush`."""
        log_time_ns = np.asarray(log_time_ns, dtype=np.int64)
        rows = max(1, CHUNK_BYTES // (_MESSAGE_HEAD.itemsize + payload[:1].nbytes))
        for start in range(0, len(log_time_ns), rows):
            records = message_records(channel, self._counts[channel], log_time_ns[start:start + rows],
                                      payload[start:start + rows])
            if self._pending_bytes + records.nbytes > CHUNK_BYTES:
                self._write_chunk()
            self._pending.append((channel, log_time_ns[start:start + rows], records))
            self._pending_bytes += records.nbytes
            self._counts[channel] += len(records)

    def _write_chunk(self) -> None:
        """Write the gathered messages as one chunk and a message index per channel after it."""
        if not self._pending:
            return
        pieces = _interleaved(self._pending)
        size, crc = 0, 0
        for records, _ in pieces:  # the records are written from the arrays, not copied into bytes
            size, crc = size + records.nbytes, zlib.crc32(_bytes(records), crc)
        first = min(int(ns.min()) for _, ns, _ in self._pending)
        last = max(int(ns.max()) for _, ns, _ in self._pending)
        head = chunk_head(first, last, size, crc)
        offset = self._fh.tell()
        indexes, index_offsets, at = [], {}, 0
        parts: dict[int, list] = {}
        for records, members in pieces:
            for channel, ns, offsets in members:
                parts.setdefault(channel, []).append((ns, at + offsets))
            at += records.nbytes
        for channel, mine in parts.items():
            times, offsets = np.concatenate([m[0] for m in mine]), np.concatenate([m[1] for m in mine])
            if len(times) > 1 and not bool(np.all(times[1:] >= times[:-1])):
                order = np.argsort(times, kind="stable")
                times, offsets = times[order], offsets[order]
            index_offsets[channel] = offset + len(head) + size + sum(len(i) for i in indexes)
            indexes.append(message_index(channel, times, offsets))
        self._pending, self._pending_bytes = [], 0
        self._append(head, *(records for records, _ in pieces), b"".join(indexes))
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=first, message_end_time=last, chunk_start_offset=offset,
            chunk_length=len(head) + size, message_index_offsets=index_offsets,
            message_index_length=sum(len(i) for i in indexes), compression=COMPRESSION, compressed_size=size,
            uncompressed_size=size))

    def flush(self) -> None:
        """Write the gathered messages as a chunk (a reader of the growing file sees it: nothing is buffered)."""
        self._write_chunk()

    def _summary(self, start: int) -> tuple[bytes, bytes]:
        """The summary section starting at byte `start` and its summary offsets."""
        groups = [(Opcode.SCHEMA, self._schemas), (Opcode.CHANNEL, self._channels),
                  (Opcode.STATISTICS, [Statistics(
                      message_count=sum(self._counts.values()), schema_count=len(self._schemas),
                      channel_count=len(self._channels), attachment_count=0,
                      metadata_count=len(self._metadata_indexes), chunk_count=len(self._chunk_indexes),
                      message_start_time=min((c.message_start_time for c in self._chunk_indexes), default=0),
                      message_end_time=max((c.message_end_time for c in self._chunk_indexes), default=0),
                      channel_message_counts=dict(self._counts))]),
                  (Opcode.CHUNK_INDEX, self._chunk_indexes), (Opcode.METADATA_INDEX, self._metadata_indexes)]
        body, offsets = b"", []
        for opcode, records in groups:
            if records:
                data = _serialised(*records)
                offsets.append(SummaryOffset(group_opcode=opcode, group_start=start + len(body),
                                             group_length=len(data)))
                body += data
        return body, _serialised(*offsets)

    def close(self) -> None:
        """Finish the file once: data end, the summary (schemas, channels, statistics, indexes), footer, magic."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._broken:
                return
            self._write_chunk()
            self._append(_serialised(DataEnd(data_section_crc=0)))
            start = self._fh.tell()
            summary, offsets = self._summary(start)
            footer = Footer(summary_start=start, summary_offset_start=start + len(summary), summary_crc=0)
            footer.summary_crc = zlib.crc32(summary + offsets + _serialised(footer)[:-4])  # up to the CRC field
            self._append(summary + offsets + _serialised(footer) + MAGIC)
        finally:
            self._fh.close()
