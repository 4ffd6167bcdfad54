"""`pantohil watch RUN_FOLDER`: a terminal view of a run as its run.mcap is written (no Foxglove needed).

It shows the figures of the Foxglove layout: the span-to-span change, mean and std of each closed span,
the force of the current span over the previous one, and the newest per-step values (actuator height,
link counters on a rig). It reads only the complete records of the growing file; when the file is
finished it waits for the run to release the folder's lock and prints the status from summary.json.
On a terminal the view redraws in place (rich); otherwise it prints one line per closed span.
"""
from __future__ import annotations

import fcntl
import math
import os
import sys
import time
from pathlib import Path

from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

from pantohil.models.case import CaseError
from pantohil.models.input_files import InputFileError, open_regular

from .mcap_follow import McapFollower, McapFollowError
from .run_folder import LOCK_NAME, read_summary, run_is_alive

BARS = "▁▂▃▄▅▆▇█"
SPARK_WIDTH = 60
HISTORY_ROWS = 8
WAIT_FOR_FOLDER_S = 60.0  # a watch started before its run waits this long for the run folder


class RunView:
    """What the log has said so far."""

    def __init__(self):
        self.history: list[dict] = []
        self.latest: dict[str, dict] = {}
        self.span_force: dict | None = None
        self.metadata: dict[str, str] = {}
        self.units: dict[str, dict[str, str]] = {}  # topic -> signal -> unit (from the log's schemas)

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
        times = [m.get("t") for m in self.latest.values()]
        return max((t for t in times if isinstance(t, (int, float)) and math.isfinite(t)), default=0.0)


def _fmt(value, spec: str) -> str:
    """A logged value as `spec` formats it; "-" for null, and "?" for anything that is not a finite number."""
    if value is None:
        return "-"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return "?"
    return format(value, spec)


def _numbers(values) -> list[float] | None:
    """A logged list of finite numbers, or None."""
    if not isinstance(values, list) or not values:
        return None
    ok = all(not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v) for v in values)
    return [float(v) for v in values] if ok else None


def span_line(rec: dict) -> str:
    """One line for a closed span: its change, mean, std, max and min."""
    return (f"span {_fmt(rec.get('span'), 'd' if isinstance(rec.get('span'), int) else 'g')}: change "
            f"{_fmt(rec.get('change'), '.3e')}, mean {_fmt(rec.get('mean_N'), '.2f')} N, std "
            f"{_fmt(rec.get('std_N'), '.2f')} N, max {_fmt(rec.get('max_N'), '.1f')} N, min "
            f"{_fmt(rec.get('min_N'), '.1f')} N")


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
        table.add_row(_fmt(rec.get("span"), "g"), _fmt(rec.get("change"), ".3e"), _fmt(rec.get("mean_N"), ".2f"),
                      _fmt(rec.get("std_N"), ".2f"), _fmt(rec.get("max_N"), ".1f"), _fmt(rec.get("min_N"), ".1f"))
    return table


def _span_force_text(view: RunView) -> Text:
    sf = view.span_force
    if not sf:
        return Text("force of the span: after the first span")
    current, previous = _numbers(sf.get("force_N")), _numbers(sf.get("previous_force_N"))
    if current is None or previous is None:
        return Text("force of the span: not a list of numbers in the log")
    both = current + previous
    low, high = min(both), max(both)
    text = Text(f"force of span {_fmt(sf.get('span'), 'g')} [{low:.0f} .. {high:.0f} N]\n")
    text.append("current  " + sparkline(current, low, high) + "\n", style="bold")
    text.append("previous " + sparkline(previous, low, high), style="dim")
    return text


def _latest_table(view: RunView) -> Table:
    table = Table(title=f"newest step (t = {view.simulated_s:.3f} s)", expand=False)
    table.add_column("signal")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for topic, msg in sorted(view.latest.items()):
        units = view.units.get(topic, {})
        for name, value in msg.items():
            if name != "t":
                table.add_row(f"{topic}.{name}", "null" if value is None else _fmt(value, ".6g"), units.get(name, ""))
    return table


def render(view: RunView, folder: Path, status: str) -> Group:
    """The terminal view of a run: header, span history, the force of the last spans, newest signals."""
    meta = view.metadata
    head = Text(f"{folder}  case {meta.get('case', '?')} ({meta.get('topology', '?')}, master "
                f"{meta.get('master', '?')})  spans {len(view.history)}  {status}", style="bold")
    return Group(head, _history_table(view), _span_force_text(view), _latest_table(view))


def _open_lock(folder: Path) -> int | None:
    """A descriptor of the folder's lock file, or None if there is none (or it is not a regular file)."""
    try:
        return open_regular(folder / LOCK_NAME, "run lock")
    except InputFileError:
        return None


def wait_for_run_end(folder: Path) -> None:
    """Block until the run holding the folder's lock lets go of it (it writes summary.json first)."""
    fd = _open_lock(folder)
    if fd is None:  # no run holds the folder
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_SH)
        fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


class RunGone(Exception):
    """The run writing the folder ended without finishing its log or its summary (killed)."""


def _final_status(folder: Path, finished: bool) -> str:
    summary = folder / "summary.json"
    if finished:
        wait_for_run_end(folder)
    if not summary.exists() and not summary.is_symlink():
        if finished:
            raise RunGone(f"watch: the run in {folder} finished its log but wrote no summary.json: it was killed")
        return "running"
    s = read_summary(folder)
    return f"{s.get('status', '?')}: {s.get('message', '')}"


def log_path(folder: Path) -> Path:
    """The folder's newest log: a resumed run writes run_from_span_NNNN.mcap next to run.mcap."""
    resumed = sorted(folder.glob("run_from_span_*.mcap"))
    return resumed[-1] if resumed else folder / "run.mcap"


class Liveness:
    """Whether the run writing a folder is still there: a process holds the lock that a run took (its lock
    file is there, or was seen). Dead only at two checks in a row, so that a run taking or letting go of its
    lock at that instant is not taken for a killed one."""

    def __init__(self, folder: Path):
        self.folder, self.lock_seen, self.misses = folder, False, 0

    def dead(self, log_started: bool) -> bool:
        """Check once; True at the second check in a row that finds no holder."""
        self.lock_seen = self.lock_seen or (self.folder / LOCK_NAME).exists()
        if not (self.lock_seen or log_started) or run_is_alive(self.folder):
            self.misses = 0
            return False
        self.misses += 1
        return self.misses >= 2


def _gone(folder: Path) -> RunGone:
    return RunGone(f"watch: the run writing {folder} is no longer running (no process holds its lock) and its "
                   "log is unfinished: it was killed")


def _follow(folder: Path, view: RunView, interval_s: float, on_change) -> bool:
    """Poll the log until it is finished; `on_change(closed_spans)` after each poll with news. RunGone when the
    run stops holding the folder's lock before its log is finished."""
    alive = Liveness(folder)
    while not log_path(folder).exists():
        if alive.dead(log_started=False):
            raise _gone(folder)
        on_change([])
        time.sleep(interval_s)
    follower = McapFollower(log_path(folder))
    while not follower.finished:
        dead = alive.dead(log_started=True)  # before the poll: a run that finishes meanwhile is read finished
        try:
            messages = follower.poll()
        except McapFollowError as exc:
            raise CaseError(f"watch: {exc}") from None
        view.metadata = follower.metadata or view.metadata
        view.units = follower.units or view.units
        closed = view.update(messages)
        if messages:
            on_change(closed)
        if not follower.finished:
            if dead:
                raise _gone(folder)
            time.sleep(interval_s)
    return True


def _read_all(path: Path, view: RunView) -> McapFollower:
    """Everything the log holds now, read in bounded polls."""
    follower, offset = McapFollower(path), -1
    while follower.offset != offset and not follower.finished:
        offset = follower.offset
        try:
            view.update(follower.poll())
        except McapFollowError as exc:
            raise CaseError(f"watch: {exc}") from None
    view.metadata = follower.metadata
    view.units = follower.units
    return follower


def watch(folder: Path, interval_s: float = 0.5, once: bool = False, console: Console | None = None) -> int:
    """Follow a run folder's log until the run ends (or, with `once`, show what is there now)."""
    console = console or Console()
    folder = Path(folder)
    if not (math.isfinite(interval_s) and 0 < interval_s <= 3600):
        raise CaseError(f"watch: --interval must be a number of seconds in (0, 3600] (got {interval_s!r})")
    if not once:
        _wait_for_folder(folder, interval_s)
    if not folder.is_dir():
        raise CaseError(f"watch: {folder} is not a run folder (no such directory)")
    view = RunView()
    if once:
        if not log_path(folder).exists():
            raise CaseError(f"watch: no run.mcap in {folder} yet")
        follower = _read_all(log_path(folder), view)
        console.print(render(view, folder, _final_status(folder, False) if follower.finished else "running"))
        return 0
    try:
        return _watch_live(folder, view, interval_s, console)
    except RunGone as exc:
        print(f"pantohil: error: {exc}", file=sys.stderr, flush=True)
        return 1


def _wait_for_folder(folder: Path, interval_s: float) -> None:
    """A watch started before its run: wait up to WAIT_FOR_FOLDER_S for the run to make its folder."""
    deadline = time.monotonic() + WAIT_FOR_FOLDER_S
    if not folder.exists():
        print(f"watch: waiting up to {WAIT_FOR_FOLDER_S:g} s for {folder} (a run about to start)", file=sys.stderr,
              flush=True)
    while not folder.exists() and time.monotonic() < deadline:
        time.sleep(min(interval_s, 0.5))


def _watch_live(folder: Path, view: RunView, interval_s: float, console: Console) -> int:
    """Follow the log to its end: a live view on a terminal, else a line per closed span."""
    if console.is_terminal:
        with Live(render(view, folder, "waiting for run.mcap"), console=console, refresh_per_second=4) as live:
            _follow(folder, view, interval_s, lambda closed: live.update(render(view, folder, "running")))
            live.update(render(view, folder, _final_status(folder, True)))
        return 0
    _follow(folder, view, interval_s, lambda closed: [print(span_line(rec), flush=True) for rec in closed])
    print(_final_status(folder, True), flush=True)
    return 0
