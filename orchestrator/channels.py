"""The channels of a run, shared by the MCAP log (run.mcap) and the live Foxglove stream, so that both carry
the same topics, schemas and bytes for the same step.

Per-step groups ("/catenary", "/rig", ...) have one float64 per signal, as ROS 2 messages (schema encoding
"ros2msg", message encoding "cdr": the 4-byte CDR header, then the doubles), which Foxglove decodes and which
are built for a whole span at once with numpy. Per-span channels are JSON with a JSON schema:
"/convergence" (the span's figures) and "/span_force" (the force of the span just closed and of the span
before, as whole arrays, for a current-over-previous plot against the sample index).
"""
from __future__ import annotations

import json
import math
import re

import numpy as np

CONVERGENCE_FIELDS = {"span": "span index [-]", "change": "RMS span-to-span change over the std [-] (null: first span)",
                      "mean_N": "mean force of the span [N]", "std_N": "std of the force of the span [N]",
                      "max_N": "largest force of the span [N]", "min_N": "smallest force of the span [N]",
                      "measured": "samples of the span with a measured force (the others kept the span before's) [-]"}


def _number_schema(title: str, fields: dict[str, str]) -> dict:
    props = {"t": {"type": "number", "description": "simulated time [s]"}}
    props.update({name: {"type": "number", "description": desc} for name, desc in fields.items()})
    return {"title": title, "type": "object", "properties": props}


def _array(desc: str) -> dict:
    return {"type": "array", "items": {"type": "number"}, "description": desc}


SPAN_FORCE_SCHEMA = {"title": "/span_force", "type": "object", "properties": {
    "t": {"type": "number", "description": "simulated time at the end of the span [s]"},
    "span": {"type": "integer", "description": "span index [-]"},
    "dt_s": {"type": "number", "description": "time between samples [s]"},
    "force_N": _array("force in use at each sample of the span just closed [N]"),
    "previous_force_N": _array("the same for the span before (empty for the first span) [N]")}}

EVENT_SCHEMAS = {"/convergence": _number_schema("/convergence", CONVERGENCE_FIELDS), "/span_force": SPAN_FORCE_SCHEMA}


GROUP_SCHEMA_ENCODING = "ros2msg"
GROUP_MESSAGE_ENCODING = "cdr"
CDR_HEADER = b"\x00\x01\x00\x00"  # plain CDR, little-endian (ROS 2's encapsulation); the doubles follow unpadded
_FIELD = re.compile(r"^float64 ([A-Za-z][A-Za-z0-9_]*)(?:\s*#\s*(.*))?$")
_ROS2_NAME = re.compile(r"[a-z](?:[a-z0-9]|_(?!_))*(?<!_)")  # a ROS 2 field name, which Foxglove's parser reads


def group_schema(topic: str, fields: dict[str, str]) -> bytes:
    """ROS 2 message definition of a per-step group: simulated time t and one float64 per signal, each with its
    description (and unit) as a comment."""
    bad = [name for name in fields if not _ROS2_NAME.fullmatch(name)]
    if bad:
        raise ValueError(f"{topic}: {bad[0]!r} is not a ROS 2 field name (lower case, digits, single underscores)")
    lines = [f"# {topic}: one message per step", "float64 t  # simulated time [s]"]
    lines += [f"float64 {name}  # {' '.join(desc.split())}" for name, desc in fields.items()]
    return ("\n".join(lines) + "\n").encode()


def group_fields(schema: bytes) -> dict[str, str]:
    """Field -> description of a per-step group's message definition, in message order (a line that is not
    `float64 name  # description`, or a comment line, is not a field)."""
    fields = {}
    for line in schema.decode("utf-8", errors="replace").splitlines():
        found = _FIELD.match(line.strip())
        if found:
            fields[found.group(1)] = found.group(2) or ""
    return fields


def decode_row(keys: list[str], data: bytes) -> dict:
    """One per-step message as {field: value}; a non-finite value as None (what JSON's null was)."""
    if len(data) != len(CDR_HEADER) + 8 * len(keys) or data[:len(CDR_HEADER)] != CDR_HEADER:
        raise ValueError(f"a per-step message of {len(data)} bytes is not {len(keys)} little-endian CDR doubles")
    values = np.frombuffer(data, dtype="<f8", offset=len(CDR_HEADER)).tolist()
    return {k: v if math.isfinite(v) else None for k, v in zip(keys, values, strict=True)}


def event_schema(topic: str) -> bytes:
    """The JSON schema of an event topic, as bytes for MCAP and Foxglove."""
    return json.dumps(EVENT_SCHEMAS.get(topic, {"title": topic, "type": "object"})).encode()


def schema_name(topic: str) -> str:
    """The schema name of a per-span topic (the topic without its slashes)."""
    return topic.strip("/")


def group_schema_name(topic: str) -> str:
    """The ROS 2 type name of a per-step group's messages: "/pantograph_2" -> "pantohil/msg/Pantograph2"."""
    return "pantohil/msg/" + "".join(part.capitalize() for part in re.split(r"[/_]", topic) if part)


class RowEncoder:
    """The messages of one per-step group, one per row (t[i], columns[i, :]): CDR_HEADER and the row's doubles."""

    def __init__(self, fields):
        self.keys = ["t", *fields]
        self._dtype = np.dtype([("header", f"V{len(CDR_HEADER)}"), ("values", "<f8", (len(self.keys),))])

    def rows(self, t: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """The messages of the rows as a structured array (CDR header, doubles), row i the message of step i."""
        t = np.asarray(t, dtype=float)
        out = np.empty(len(t), dtype=self._dtype)
        out["header"] = CDR_HEADER
        out["values"][:, 0] = t
        out["values"][:, 1:] = np.asarray(columns, dtype=float).reshape(len(t), -1)
        return out

    def encode(self, t: np.ndarray, columns: np.ndarray) -> list[bytes]:
        """One message per step from the times and the signal columns."""
        return [row.tobytes() for row in self.rows(t, columns)]


def _finite(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def encode_event(t: float, record: dict) -> bytes:
    """One per-span message: {"t": t, **record}, non-finite numbers as null (valid JSON)."""
    return json.dumps({"t": t, **{k: _finite(v) for k, v in record.items()}}).encode()


def span_force_record(span: int, dt_s: float, force: np.ndarray, previous: np.ndarray | None) -> dict:
    """The /span_force message of a span: its force and the previous span's [N]."""
    return {"span": span, "dt_s": dt_s, "force_N": [float(f) for f in force],
            "previous_force_N": [] if previous is None else [float(f) for f in previous]}
