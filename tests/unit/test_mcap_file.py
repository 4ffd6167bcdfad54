"""run.mcap as written a block at a time (orchestrator/mcap_file.py, orchestrator/recorder.py): what the `mcap`
library's readers make of it, record by record, and what pantohil's follower decodes."""
from __future__ import annotations

import errno
import io
import math
import struct
import zlib

import numpy as np
import pytest
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import Chunk, Message, MessageIndex, Statistics
from mcap.stream_reader import StreamReader

from pantohil.orchestrator.channels import RowEncoder, decode_row, group_fields, group_schema
from pantohil.orchestrator import mcap_file
from pantohil.orchestrator.mcap_file import CHUNK_BYTES
from pantohil.orchestrator.mcap_follow import McapFollower, read_log
from pantohil.orchestrator.recorder import McapWriter

GROUPS = {"/catenary": {"height_command": "commanded height [m]", "contact_force": "force received [N]"},
          "/rig": {"actuator_height": "actuator height [m]"}}
STEPS = 3000  # several chunks per group at CHUNK_BYTES


def _write(path, dt_s=1e-3):
    """A log of STEPS steps in blocks of 936, a NaN force every 7th step, and one /convergence per block."""
    rng = np.random.default_rng(7)
    writer = McapWriter(path, GROUPS, {"case": "blocks"})
    columns = {"/catenary": rng.normal(size=(STEPS, 2)), "/rig": rng.normal(size=(STEPS, 1))}
    columns["/catenary"][::7, 1] = math.nan
    for start in range(0, STEPS, 936):
        stop = min(start + 936, STEPS)
        t = np.arange(start, stop) * dt_s
        for topic in GROUPS:
            writer.write_block(topic, t, columns[topic][start:stop])
        writer.write_event("/convergence", stop * dt_s, {"span": start // 936, "change": math.inf})
        writer.flush()
    writer.close()
    return columns


def test_the_mcap_library_reads_every_message_with_crcs_checked(tmp_path):
    path = tmp_path / "run.mcap"
    columns = _write(path)
    with open(path, "rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        summary = reader.get_summary()
        stats = summary.statistics
        counts = {summary.channels[i].topic: n for i, n in stats.channel_message_counts.items()}
        assert counts == {"/catenary": STEPS, "/rig": STEPS, "/convergence": 4, "/span_force": 0}
        assert stats.message_count == 2 * STEPS + 4 and stats.chunk_count == len(summary.chunk_indexes)
        assert (stats.message_start_time, stats.message_end_time) == (0, STEPS * 1_000_000)
        assert reader.get_header().library == "pantohil"
        assert dict(next(reader.iter_metadata()).metadata) == {"case": "blocks"}
        rows = [(ch.topic, m.log_time, m.data) for _, ch, m in reader.iter_messages(log_time_order=True)]
    assert len(rows) == 2 * STEPS + 4
    assert [t for _, t, _ in rows] == sorted(t for _, t, _ in rows)
    keys = ["t", *GROUPS["/catenary"]]
    catenary = [decode_row(keys, d) for topic, _, d in rows if topic == "/catenary"]
    got = np.array([[r["height_command"], math.nan if r["contact_force"] is None else r["contact_force"]]
                    for r in catenary])
    assert np.array_equal(got, columns["/catenary"], equal_nan=True)  # the doubles, exact; NaN read as None
    assert sum(r["contact_force"] is None for r in catenary) == len(range(0, STEPS, 7))


@pytest.mark.parametrize("chunk_bytes", [CHUNK_BYTES, 4096])
def test_every_record_is_whole_and_every_message_index_points_at_its_message(tmp_path, monkeypatch, chunk_bytes):
    """Read as a stream with CRCs checked: a flush's messages make one chunk, split where it would pass
    CHUNK_BYTES (4096 here: 40 rows of /catenary), and the message indexes after a chunk give each of its
    messages' log time and offset in the chunk's records, one index per channel, in time order."""
    monkeypatch.setattr(mcap_file, "CHUNK_BYTES", chunk_bytes)
    path = tmp_path / "run.mcap"
    _write(path)
    records = list(StreamReader(io.BytesIO(path.read_bytes()), emit_chunks=True, validate_crcs=True).records)
    chunks, indexed = 0, 0
    for i, record in enumerate(records):
        if not isinstance(record, Chunk):
            continue
        chunks += 1
        assert record.compression == "" and len(record.data) == record.uncompressed_size <= chunk_bytes
        assert record.uncompressed_crc == zlib.crc32(record.data)
        j = i + 1
        while isinstance(records[j], MessageIndex):
            index = records[j]
            assert [t for t, _ in index.records] == sorted(t for t, _ in index.records)
            for log_time, offset in index.records:
                message = next(iter(StreamReader(io.BytesIO(record.data[offset:]), skip_magic=True).records))
                assert isinstance(message, Message) and message.log_time == log_time
                assert message.channel_id == index.channel_id
                indexed += 1
            j += 1
    assert indexed == 2 * STEPS + 4
    in_file = [r.log_time for r in StreamReader(io.BytesIO(path.read_bytes())).records if isinstance(r, Message)]
    assert len(in_file) == 2 * STEPS + 4
    if chunk_bytes == CHUNK_BYTES:  # a span's groups interleaved step by step (split chunks overlap in time)
        assert in_file == sorted(in_file)
    record_bytes = STEPS * ((31 + 4 + 8 * 3) + (31 + 4 + 8 * 2))  # a Message record: 31 bytes and its message's
    assert chunks == 4 if chunk_bytes == CHUNK_BYTES else chunks >= record_bytes // chunk_bytes > 4
    assert isinstance(next(r for r in records if isinstance(r, Statistics)), Statistics)
    whole = path.read_bytes()  # the footer's CRC: from the summary's start through its summary_offset_start
    _, length, summary_start, _, crc = struct.unpack("<BQQQI", whole[-8 - 29:-8])
    assert length == 20 and crc == zlib.crc32(whole[summary_start:-8 - 4])


def test_the_follower_decodes_the_groups_and_reads_their_units(tmp_path):
    path = tmp_path / "run.mcap"
    _write(path)
    follower = McapFollower(path)
    messages = []
    while not follower.finished:
        messages += follower.poll()
    assert follower.units["/catenary"] == {"t": "s", "height_command": "m", "contact_force": "N"}
    assert follower.metadata == {"case": "blocks"}
    assert messages == read_log(path)
    convergence = [m for topic, _, m in messages if topic == "/convergence"]
    assert [c["span"] for c in convergence] == [0, 1, 2, 3] and convergence[0]["change"] is None


def test_a_group_schema_is_a_ros2_message_definition_with_its_fields_in_order():
    schema = group_schema("/catenary", GROUPS["/catenary"])
    assert schema.decode().splitlines()[1:] == ["float64 t  # simulated time [s]",
                                                "float64 height_command  # commanded height [m]",
                                                "float64 contact_force  # force received [N]"]
    assert list(group_fields(schema)) == ["t", "height_command", "contact_force"]
    rows = RowEncoder(GROUPS["/catenary"]).encode(np.array([0.5]), np.array([[1.0, -2.0]]))
    assert rows == [b"\x00\x01\x00\x00" + np.array([0.5, 1.0, -2.0], "<f8").tobytes()]
    with pytest.raises(ValueError, match="not 3 little-endian CDR doubles"):
        decode_row(["t", "a", "b"], rows[0][:-1])
    for name in ("mean_N", "two__bars", "end_", "1st"):
        with pytest.raises(ValueError, match="not a ROS 2 field name"):
            group_schema("/x", {name: "[-]"})


class _FailingFile:
    """A file whose writes fail (ENOSPC) once `room` bytes are written, the last write only partly done."""

    def __init__(self, fh, room: int):
        self._fh, self.room = fh, room

    def write(self, view):
        if len(view) > self.room:
            self._fh.write(view[:self.room])
            self.room = 0
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= len(view)
        return self._fh.write(view)

    def __getattr__(self, name):
        return getattr(self._fh, name)


def test_a_failed_write_leaves_the_file_at_its_last_whole_record_and_adds_nothing(tmp_path):
    path = tmp_path / "run.mcap"
    writer = McapWriter(path, GROUPS, {"case": "full disk"})
    t = np.arange(936) * 1e-3
    for topic, fields in GROUPS.items():
        writer.write_block(topic, t, np.ones((936, len(fields))))
    writer.flush()
    whole = path.stat().st_size
    writer._file._fh = _FailingFile(writer._file._fh, room=1000)  # the next chunk fails in its records
    for topic, fields in GROUPS.items():
        writer.write_block(topic, t + 1, np.ones((936, len(fields))))
    with pytest.raises(OSError):
        writer.flush()
    writer.close()  # nothing more: no summary after a cut chunk
    assert path.stat().st_size == whole
    messages = 0
    with pytest.raises(EndOfFile):  # every record whole up to the end of the file, which has no footer
        for record in StreamReader(io.BytesIO(path.read_bytes()), validate_crcs=True).records:
            messages += isinstance(record, Message)
    assert messages == 2 * 936
