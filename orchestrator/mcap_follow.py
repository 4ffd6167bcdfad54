"""Follow a growing MCAP file (run.mcap while its writer process adds to it): each poll returns the
messages of the records that are complete in the file, and remembers where the next record starts.

The framing of MCAP records (opcode: 1 byte, length: uint64 little-endian, then the content) tells
where a complete record ends; the records themselves (chunks, schemas, channels, messages) are read
by the mcap library. pantohil's writer appends a chunk's head, records and indexes in turn, with its final
length in the head (a reader waits for the rest); a writer that writes a chunk with
placeholders (length and sizes all ones) and then patches its length and its header field by field (the
mcap crate's, foxglove-sdk's) can leave a chunk whose length is final but whose compressed size does not yet
agree with it at the end of what is in the file: it is not complete yet.

Per-step messages are decoded by their channel's schema (orchestrator/channels.py: CDR rows of float64, a
non-finite value read as None), per-span messages as JSON objects.
"""
from __future__ import annotations

import io
import json
import re
import struct
from pathlib import Path

from mcap.exceptions import EndOfFile
from mcap.records import Channel, Chunk, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from pantohil.models.errors import InputError
from pantohil.models.input_files import InputFileError, read_input_chunk

from .channels import GROUP_MESSAGE_ENCODING, GROUP_SCHEMA_ENCODING, decode_row, group_fields

MAGIC = b"\x89MCAP0\r\n"
_HEADER = struct.Struct("<BQ")
_CHUNK = 0x06
_CHUNK_FIXED = 8 + 8 + 8 + 4  # message start and end time, uncompressed size and CRC
# A record (a chunk of at most CHUNK_BYTES, compressed) is far smaller than MAX_RECORD_BYTES. A growing file
# may show a huge length for a while (the writer patches a record's length once it is written), so a length
# is not refused by itself: a poll that reads a whole window of MAX_POLL_BYTES without one complete record is.
MAX_RECORD_BYTES = 32 * 1024 * 1024
MAX_POLL_BYTES = 2 * MAX_RECORD_BYTES  # read per poll: always room for one whole record
MAX_POLLS = 1_000_000
_UNIT = re.compile(r"\[([^\]]*)\]\s*$")


class McapFollowError(InputError):
    """The file being followed is not an MCAP file, or a record in it cannot be read."""
    pass


def chunk_header_settled(data: bytes, offset: int, length: int) -> bool:
    """Whether the chunk record at `offset` (content `length` bytes) has its header patched: its
    compression name and compressed size account for exactly its length (MCAP spec, Chunk)."""
    body = offset + _HEADER.size
    if length < _CHUNK_FIXED + 4 + 8:
        return False
    (name_bytes,) = struct.unpack_from("<I", data, body + _CHUNK_FIXED)
    size_at = body + _CHUNK_FIXED + 4 + name_bytes
    if size_at + 8 > body + length:
        return False
    (compressed,) = struct.unpack_from("<Q", data, size_at)
    return size_at + 8 + compressed == body + length


def complete_records_end(data: bytes, start: int) -> tuple[int, bool]:
    """Offset after the last complete record of data[start:], and whether the footer is among them. A
    chunk at the end of the data whose header is still being patched is not complete; followed by more
    data, it is what the writer left (a damaged one is refused when it is read)."""
    offset, footer = start, False
    while offset + _HEADER.size <= len(data):
        opcode, length = _HEADER.unpack_from(data, offset)
        end = offset + _HEADER.size + length
        if end > len(data):
            break
        if opcode == _CHUNK and end == len(data) and not chunk_header_settled(data, offset, length):
            break
        offset, footer = end, footer or opcode == 0x02
    return offset, footer


def _message(data: bytes) -> dict:
    """A logged message: a JSON object (its values are shown only where they are numbers)."""
    msg = json.loads(data)
    if not isinstance(msg, dict):
        raise ValueError(f"a message is not a JSON object ({type(msg).__name__})")
    return msg


def _descriptions(encoding: str, data: bytes) -> dict[str, str]:
    """Field -> description of a channel's schema (a JSON schema's, or a per-step group's message definition)."""
    if encoding == GROUP_SCHEMA_ENCODING:
        return group_fields(data)
    try:
        properties = json.loads(data).get("properties", {})
    except (ValueError, AttributeError):
        return {}
    return {name: str(spec.get("description", "")) for name, spec in properties.items() if isinstance(spec, dict)} \
        if isinstance(properties, dict) else {}


def schema_units(encoding: str, data: bytes) -> dict[str, str]:
    """Field -> unit of a channel's schema, from each description's closing `[unit]` ("[-]": none)."""
    units = {}
    for name, description in _descriptions(encoding, data).items():
        found = _UNIT.search(description)
        if found and found.group(1) != "-":
            units[name] = found.group(1)
    return units


def channel_decoder(message_encoding: str, schema: Schema | None):
    """data -> message dict for a channel: a per-step group's CDR rows by its schema's fields, else JSON."""
    if message_encoding == GROUP_MESSAGE_ENCODING and schema is not None and schema.encoding == GROUP_SCHEMA_ENCODING:
        keys = list(group_fields(schema.data))
        return lambda data: decode_row(keys, data)
    if message_encoding == "json":
        return _message
    raise ValueError(f"channel encoding {message_encoding!r} is not one pantohil writes")


class McapFollower:
    """`poll()` -> [(topic, log_time_ns, decoded JSON message)] new since the last poll."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.offset = 0
        self.finished = False
        self.metadata: dict[str, str] = {}
        self.units: dict[str, dict[str, str]] = {}  # topic -> field -> unit, from the channels' JSON schemas
        self._topics: dict[int, str] = {}
        self._decoders: dict[int, object] = {}
        self._schemas: dict[int, Schema] = {}

    def poll(self) -> list[tuple[str, int, dict]]:
        """The messages of the records completed since the last poll, as (topic, log time ns, JSON)."""
        if self.finished:
            return []
        try:  # a regular file only (not a FIFO or a device), a bounded read per poll
            data = read_input_chunk(self.path, "run log", self.offset, MAX_POLL_BYTES)
        except InputFileError as exc:
            raise McapFollowError(str(exc)) from None
        start = 0
        if self.offset == 0:
            if len(data) < len(MAGIC):
                return []
            if not data.startswith(MAGIC):
                raise McapFollowError(f"{self.path} is not an MCAP file")
            start = len(MAGIC)
        end, footer = complete_records_end(data, start)
        if end == start and len(data) >= MAX_POLL_BYTES:  # a whole window without one complete record
            raise McapFollowError(f"{self.path}: a record at byte {self.offset + start} is larger than the limit "
                                  f"of {MAX_RECORD_BYTES} bytes")
        if end == start:
            self.offset += start
            return []
        messages = self._read(data[start:end])
        self.offset += end
        self.finished = footer
        return messages

    def _read(self, records: bytes) -> list[tuple[str, int, dict]]:
        out = []
        try:
            for record in StreamReader(io.BytesIO(records), skip_magic=True).records:
                if isinstance(record, Schema):
                    self._schemas[record.id] = record
                elif isinstance(record, Channel):
                    schema = self._schemas.get(record.schema_id)
                    self._topics[record.id] = record.topic
                    self._decoders[record.id] = channel_decoder(record.message_encoding, schema)
                    self.units[record.topic] = schema_units(schema.encoding, schema.data) if schema else {}
                elif isinstance(record, Message) and record.channel_id in self._topics:
                    decoded = self._decoders[record.channel_id](record.data)
                    out.append((self._topics[record.channel_id], record.log_time, decoded))
                elif isinstance(record, Metadata) and record.name == "run":
                    self.metadata = dict(record.metadata)
                elif isinstance(record, (Footer, Chunk)):
                    continue
        except EndOfFile:  # the stream of complete records ends without the file's closing magic
            pass
        except Exception as exc:  # McapError, a decompressor's error, a bad struct or JSON: a damaged record
            detail = " ".join(str(exc).split())[:200] or type(exc).__name__
            raise McapFollowError(f"{self.path}: a record cannot be read ({detail})") from None
        return out


def read_log(path: Path, topics: tuple[str, ...] | None = None) -> list[tuple[str, int, dict]]:
    """Every message of a finished log as (topic, log time ns, decoded message), of `topics` if given; an
    unfinished log (its writer still at work, or killed) is refused."""
    follower, out = McapFollower(path), []
    for _ in range(MAX_POLLS):
        offset = follower.offset
        batch = follower.poll()
        out.extend(m for m in batch if topics is None or m[0] in topics)
        if follower.finished:
            return out
        if follower.offset == offset:  # nothing more is complete
            raise McapFollowError(f"{path} is unfinished (its run is still writing it, or was killed)")
    raise McapFollowError(f"{path} has more records than {MAX_POLLS} reads take")
