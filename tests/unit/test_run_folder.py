"""Run folders (orchestrator/run_folder.py): new or empty, overwrite replaces them whole, one run at a
time (a lock), default names under runs/."""
from __future__ import annotations

import multiprocessing as mp
from datetime import datetime
from pathlib import Path

import pytest
from pantohil.orchestrator.run_folder import (
    LOCK_NAME,
    RunFolderError,
    claimed_run_folder,
    default_run_folder,
    safe_name,
)


def test_a_new_folder_is_made_and_left_without_its_lock(tmp_path):
    with claimed_run_folder(tmp_path / "a" / "b") as folder:
        assert (folder / LOCK_NAME).exists()
        (folder / "x.txt").write_text("x")
    assert sorted(p.name for p in folder.iterdir()) == ["x.txt"]


def test_a_used_folder_is_refused_and_kept(tmp_path):
    (tmp_path / "old.csv").write_text("1")
    with pytest.raises(RunFolderError, match="exists and is not empty"), claimed_run_folder(tmp_path):
        pass
    assert (tmp_path / "old.csv").read_text() == "1"


def test_overwrite_replaces_the_folder_whole(tmp_path):
    (tmp_path / "old.csv").write_text("1")
    (tmp_path / "plots").mkdir()
    (tmp_path / "plots" / "a.png").write_text("")
    with claimed_run_folder(tmp_path, overwrite=True) as folder:
        assert [p.name for p in folder.iterdir()] == [LOCK_NAME]


def _hold(folder: str, locked, release) -> None:
    with claimed_run_folder(Path(folder)):
        locked.set()
        release.wait()


def test_a_second_run_into_a_locked_folder_is_refused(tmp_path):
    ctx = mp.get_context("spawn")
    locked, release = ctx.Event(), ctx.Event()
    holder = ctx.Process(target=_hold, args=(str(tmp_path / "run"), locked, release))
    holder.start()
    try:
        assert locked.wait(120)
        with pytest.raises(RunFolderError, match="another run is writing into it"), \
                claimed_run_folder(tmp_path / "run", overwrite=True):
            pass
    finally:
        release.set()
        holder.join(120)
    assert holder.exitcode == 0
    with claimed_run_folder(tmp_path / "run"):  # free again
        pass


def test_a_file_is_not_a_run_folder(tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(RunFolderError, match="exists and is not a folder"), claimed_run_folder(tmp_path / "f"):
        pass


@pytest.mark.parametrize("name,expected", [("../../etc", "etc"), ("/abs/path", "abs_path"), ("..", "case"),
                                           ("a b/c", "a_b_c"), (".hidden", "hidden"), ("asm_250", "asm_250")])
def test_default_folder_names_stay_under_runs(tmp_path, name, expected):
    now = datetime(2026, 1, 2, 3, 4, 5)
    folder = default_run_folder(name, tmp_path / "runs", now)
    assert safe_name(name) == expected
    assert folder == tmp_path / "runs" / f"{expected}-20260102-030405"
    folder.mkdir(parents=True)
    assert default_run_folder(name, tmp_path / "runs", now).name == f"{expected}-20260102-030405-2"


HOLDERS = "holders"


def _contend(folder: str, rounds: int, start, doubles) -> None:
    """Take the folder's lock `rounds` times; inside, mark the hold with an O_EXCL file: finding another
    holder's mark is a double hold."""
    import os

    start.wait()
    marker = Path(folder) / HOLDERS
    taken = 0
    while taken < rounds:
        try:
            with claimed_run_folder(Path(folder), resume=True):
                taken += 1
                try:
                    fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
                except FileExistsError:
                    with doubles.get_lock():
                        doubles.value += 1
                    continue
                os.close(fd)
                os.unlink(marker)
        except RunFolderError:
            pass  # held by another: try again


def test_the_lock_is_exclusive_under_contention(tmp_path):
    """Eight processes take one folder's lock 150 times each: never two holders at once (the lock file
    used to be unlinked before it was closed: 177 double holders in 841 contended acquisitions)."""
    ctx = mp.get_context("fork")
    start, doubles = ctx.Event(), ctx.Value("i", 0)
    folder = tmp_path / "run"
    folder.mkdir()
    procs = [ctx.Process(target=_contend, args=(str(folder), 150, start, doubles)) for _ in range(8)]
    for p in procs:
        p.start()
    start.set()
    for p in procs:
        p.join(600)
    assert [p.exitcode for p in procs] == [0] * 8
    assert doubles.value == 0
    assert not (folder / LOCK_NAME).exists()
