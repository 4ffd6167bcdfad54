"""`pantohil export RUN_FOLDER`: the per-step history of a run as a table, steps.parquet (and steps.csv with
`--csv`), from its run.mcap (and, after a resume, its run_from_span_NNNN.mcap): one row per step, a column
`t_s` and one column per logged signal, `topic.signal` (`catenary.contact_force`, `rig.actuator_height`...),
in the units of the log's schemas. The logs are read as hostile input (regular files, bounded records)."""
from __future__ import annotations

import math
from pathlib import Path

from pantohil.models.case import CaseError
from pantohil.models.storage import atomic_path

from .mcap_follow import McapFollowError, read_log

SPAN_TOPICS = ("/convergence", "/span_force")  # one message per span, not per step


def _log_messages(path: Path) -> list[tuple[str, int, dict]]:
    """Every message of a finished log."""
    try:
        return read_log(path)
    except McapFollowError as exc:
        raise CaseError(f"export: {exc}") from None


def step_table(folder: Path):
    """The per-step signals of a run folder's logs as a pandas DataFrame (rows in time order)."""
    import pandas as pd

    folder = Path(folder)
    logs = [folder / "run.mcap", *sorted(folder.glob("run_from_span_*.mcap"))]
    if not logs[0].exists():
        raise CaseError(f"export: {folder} has no run.mcap (not a run folder of pantohil run)")
    columns: dict[str, dict[float, float]] = {}
    for log in logs:
        for topic, _, msg in _log_messages(log):
            if topic in SPAN_TOPICS or not isinstance(msg, dict) or not isinstance(msg.get("t"), (int, float)):
                continue
            t = float(msg["t"])
            for name, value in msg.items():
                if name != "t" and isinstance(value, (int, float, type(None))):
                    columns.setdefault(f"{topic.lstrip('/')}.{name}", {})[t] = \
                        math.nan if value is None else float(value)
    if not columns:
        raise CaseError(f"export: {folder}: its logs hold no per-step signal")
    frame = pd.DataFrame(columns).sort_index()
    frame.index.name = "t_s"
    return frame.reset_index()


def export_run(folder: Path, csv: bool = False) -> list[Path]:
    """Write steps.parquet (and steps.csv) into the run folder, each atomically; the paths written."""
    frame = step_table(folder)
    written = []
    with atomic_path(Path(folder) / "steps.parquet") as part:
        frame.to_parquet(part, index=False)
    written.append(Path(folder) / "steps.parquet")
    if csv:
        with atomic_path(Path(folder) / "steps.csv") as part:
            frame.to_csv(part, index=False, float_format="%.12g")
        written.append(Path(folder) / "steps.csv")
    return written
