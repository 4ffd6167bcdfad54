"""The channels of a run, shared by the MCAP log (run.mcap) and the live Foxglove stream: JSON schemas
and JSON encodings, so that both carry the same topics, schemas and bytes for the same step.

Per-step groups ("/catenary", "/rig", ...) have one number per signal; per-span channels are
"/convergence" (the span's figures) and "/span_force" (the force of the span just closed and of the
span before, as whole arrays, for a current-over-previous plot against the sample index).
"""
from __future__ import annotations

import json
import math

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


def group_schema(topic: str, fields: dict[str, str]) -> bytes:
    """JSON schema of a per-step group: simulated time t and one number per signal."""
    return json.dumps(_number_schema(topic, fields)).encode()


def event_schema(topic: str) -> bytes:
    """The JSON schema of an event topic, as bytes for MCAP and Foxglove."""
    return json.dumps(EVENT_SCHEMAS.get(topic, {"title": topic, "type": "object"})).encode()


def schema_name(topic: str) -> str:
    """The schema name of a topic (the topic without its slashes)."""
    return topic.strip("/")


class RowEncoder:
    """JSON messages of one per-step group, one per row (t[i], columns[i, :]); JSON has no NaN: null."""

    def __init__(self, fields):
        self.keys = ["t", *fields]
        self._template = "{" + ",".join(f'"{n}":%.10g' for n in self.keys) + "}"

    def encode(self, t: np.ndarray, columns: np.ndarray) -> list[bytes]:
        """One JSON message per step from the times and the signal columns (non-finite values as null)."""
        columns = np.asarray(columns, dtype=float)
        t = np.asarray(t, dtype=float)
        if bool(np.isfinite(columns).all()):  # every row formatted by one call, split at the newlines
            if not len(t):
                return []
            values = np.column_stack([t, columns.reshape(len(t), -1)]).ravel().tolist()
            return ((self._template + "\n") * len(t) % tuple(values)).encode().split(b"\n")[:-1]
        rows = zip(t.tolist(), columns.tolist(), strict=False)
        return [
            json.dumps(
                dict(zip(self.keys, [ti, *[v if math.isfinite(v) else None for v in row]], strict=False))
            ).encode()
            for ti, row in rows
        ]


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
