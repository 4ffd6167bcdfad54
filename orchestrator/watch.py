"""`pantohil watch RUN_FOLDER`: a terminal view of a run as its run.mcap is written (no Foxglove needed).

It shows the figures of the Foxglove layout: the span-to-span change, mean and std of each closed span,
the force of the current span over the previous one, and the newest per-step values (actuator height,
link counters on a rig). It reads only the complete records of the growing file; when the file is
finished it waits for the run to release the folder's lock and prints the status from summary.json.
On a terminal the view redraws in place (rich); otherwise it prints one line per closed span.
"""
from __future__ import annotations

import fcntl
import json
import math
import os
import time
from pathlib import Path

from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

from pantohil.models.case import CaseError

from .mcap_follow import McapFollower, McapFollowError
from .run_folder import LOCK_NAME

BARS = "▁▂▃▄▅▆▇█"
SPARK_WIDTH = 60
HISTORY_ROWS = 8


class RunView:
    """What the log has said so far."""

    def __init__(self):
        self.history: list[dict] = []
        self.latest: dict[str, dict] = {}
        self.span_force: dict | None = None
        self.metadata: dict[str, str] = {}

    def update(self, messages) -> list[dict]:
        """Take new messages; return the spans closed among them."""
        closed = []
        for topic, _, msg in messages:
            if topic == "/convergence":
                self.history.append(msg)
                closed.append(msg)
            elif topic == "/span_force":
                self.span_force = msg
            else:
                self.latest[topic] = msg
        return closed

    @property
    def simulated_s(self) -> float:
        """Simulated time of the newest per-step message read [s]."""
        return max((m.get("t", 0.0) for m in self.latest.values()), default=0.0)


def span_line(rec: dict) -> str:
    """One line for a closed span: its change, mean, std, max and min."""
    change = rec.get("change")
    change_s = "-" if change is None or not math.isfinite(change) else f"{change:.3e}"
    return (f"span {rec['span']}: change {change_s}, mean {rec['mean_N']:.2f} N, std {rec['std_N']:.2f} N, "
            f"max {rec['max_N']:.1f} N, min {rec['min_N']:.1f} N")


def sparkline(values: list[float], low: float, high: float, width: int = SPARK_WIDTH) -> str:
    """The values as a row of block characters between `low` and `high`, at most `width` wide."""
    if not values:
        return ""
    step = max(1, math.ceil(len(values) / width))
    picks = [sum(values[i:i + step]) / len(values[i:i + step]) for i in range(0, len(values), step)]
    scale = (len(BARS) - 1) / max(high - low, 1e-12)
    return "".join(BARS[min(len(BARS) - 1, max(0, int((v - low) * scale)))] for v in picks)


def _history_table(view: RunView) -> Table:
    table = Table(title="convergence (per span)", expand=False)
    for name in ("span", "change", "mean [N]", "std [N]", "max [N]", "min [N]"):
        table.add_column(name, justify="right")
    for rec in view.history[-HISTORY_ROWS:]:
        change = rec.get("change")
        table.add_row(str(rec["span"]), "-" if change is None else f"{change:.3e}", f"{rec['mean_N']:.2f}",
                      f"{rec['std_N']:.2f}", f"{rec['max_N']:.1f}", f"{rec['min_N']:.1f}")
    return table


def _span_force_text(view: RunView) -> Text:
    sf = view.span_force
    if not sf:
        return Text("force of the span: after the first span")
    current, previous = sf["force_N"], sf["previous_force_N"]
    both = current + previous
    low, high = min(both), max(both)
    text = Text(f"force of span {sf['span']} [{low:.0f} .. {high:.0f} N]\n")
    text.append("current  " + sparkline(current, low, high) + "\n", style="bold")
    text.append("previous " + sparkline(previous, low, high), style="dim")
    return text


def _latest_table(view: RunView) -> Table:
    table = Table(title=f"newest step (t = {view.simulated_s:.3f} s)", expand=False)
    table.add_column("signal")
    table.add_column("value", justify="right")
    for topic, msg in sorted(view.latest.items()):
        for name, value in msg.items():
            if name != "t":
                table.add_row(f"{topic}.{name}", "null" if value is None else f"{value:.6g}")
    return table


def render(view: RunView, folder: Path, status: str) -> Group:
    """The terminal view of a run: header, span history, the force of the last spans, newest signals."""
    meta = view.metadata
    head = Text(f"{folder}  case {meta.get('case', '?')} ({meta.get('topology', '?')}, master "
                f"{meta.get('master', '?')})  spans {len(view.history)}  {status}", style="bold")
    return Group(head, _history_table(view), _span_force_text(view), _latest_table(view))


def wait_for_run_end(folder: Path) -> None:
    """Block until the run holding the folder's lock lets go of it (it writes summary.json first)."""
    try:
        fd = os.open(folder / LOCK_NAME, os.O_RDONLY)
    except FileNotFoundError:  # no run holds the folder
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_SH)
        fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


def _final_status(folder: Path, finished: bool) -> str:
    summary = folder / "summary.json"
    if finished:
        wait_for_run_end(folder)
    if not summary.exists():
        return "log finished, no summary.json" if finished else "running"
    s = json.loads(summary.read_text())
    return f"{s['status']}: {s['message']}"


def log_path(folder: Path) -> Path:
    """The folder's newest log: a resumed run writes run_from_span_NNNN.mcap next to run.mcap."""
    resumed = sorted(folder.glob("run_from_span_*.mcap"))
    return resumed[-1] if resumed else folder / "run.mcap"


def _follow(folder: Path, view: RunView, interval_s: float, on_change) -> bool:
    """Poll the log until it is finished; `on_change(closed_spans)` after each poll with news."""
    path = log_path(folder)
    while not path.exists():
        on_change([])
        time.sleep(interval_s)
    follower = McapFollower(path)
    while not follower.finished:
        try:
            messages = follower.poll()
        except McapFollowError as exc:
            raise CaseError(f"watch: {exc}") from None
        view.metadata = follower.metadata or view.metadata
        closed = view.update(messages)
        if messages:
            on_change(closed)
        if not follower.finished:
            time.sleep(interval_s)
    return True


def watch(folder: Path, interval_s: float = 0.5, once: bool = False, console: Console | None = None) -> int:
    """Follow a run folder's log until the run ends (or, with `once`, show what is there now)."""
    console = console or Console()
    folder = Path(folder)
    if not folder.is_dir():
        raise CaseError(f"watch: {folder} is not a run folder (no such directory)")
    if interval_s <= 0:
        raise CaseError(f"watch: --interval must be > 0 s (got {interval_s:g})")
    view = RunView()
    if once:
        if not log_path(folder).exists():
            raise CaseError(f"watch: no run.mcap in {folder} yet")
        follower = McapFollower(log_path(folder))
        try:
            view.update(follower.poll())
        except McapFollowError as exc:
            raise CaseError(f"watch: {exc}") from None
        view.metadata = follower.metadata
        console.print(render(view, folder, _final_status(folder, False) if follower.finished else "running"))
        return 0
    if console.is_terminal:
        with Live(render(view, folder, "waiting for run.mcap"), console=console, refresh_per_second=4) as live:
            _follow(folder, view, interval_s, lambda closed: live.update(render(view, folder, "running")))
            live.update(render(view, folder, _final_status(folder, True)))
        return 0
    _follow(folder, view, interval_s, lambda closed: [print(span_line(rec), flush=True) for rec in closed])
    print(_final_status(folder, True), flush=True)
    return 0
