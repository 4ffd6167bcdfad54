"""Progress of long work (models/progress.py): a bar on a terminal, whole lines in a log (a line per
interval and a last one, no carriage return), nothing when disabled."""
from __future__ import annotations

import io

from pantohil.models.progress import LineProgress, progress


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_a_log_gets_whole_lines_and_a_last_one():
    log = io.StringIO()
    with progress(5, "asm_250", "span", interval_s=0.0, stream=log) as bar:
        assert isinstance(bar, LineProgress)
        for _ in range(5):
            bar.update(1)
            bar.set_postfix(change="1.0e-03")
    text = log.getvalue()
    assert "\r" not in text and text.endswith("\n")
    lines = text.splitlines()
    assert len(lines) == 6 and lines[-1].startswith("asm_250: 5/5 span (100 %)") and "change=1.0e-03" in lines[-1]


def test_a_long_interval_writes_the_last_line_only():
    log = io.StringIO()
    bar = progress(100, "sweep", "pt", interval_s=3600.0, stream=log)
    for _ in range(100):
        bar.update(1)
    bar.close()
    bar.close()
    assert log.getvalue().splitlines() == [log.getvalue().splitlines()[0]] and "100/100 pt" in log.getvalue()


def test_a_terminal_gets_a_bar_and_disabled_progress_writes_nothing():
    term = _Terminal()
    with progress(3, "map", "pt", stream=term) as bar:
        bar.update(3)
    assert "\r" in term.getvalue() and "map:" in term.getvalue()  # a bar, redrawn in place
    quiet = io.StringIO()
    with progress(3, "map", "pt", enabled=False, stream=quiet) as bar:
        bar.update(3)
    assert quiet.getvalue() == ""
