"""Output paths of the commands (orchestrator/output_paths.py): checked before any work, written as a part
folder renamed into place, removed when interrupted, part folders of dead processes swept."""
from __future__ import annotations

import errno
import os
import subprocess
import sys

import pytest
from pantohil.orchestrator.output_paths import (
    atomic_output_folder,
    check_output_file,
    check_output_folder,
    sweep_dead_parts,
    write_failure,
)
from pantohil.orchestrator.run_folder import RunFolderError, claimed_run_folder
from pantohil.orchestrator.stopping import Interrupted


def test_a_folder_is_made_whole_or_not_at_all(tmp_path):
    with atomic_output_folder(tmp_path / "a" / "out") as part:
        assert part.name.startswith(".out.part-") and not (tmp_path / "a" / "out").exists()
        (part / "summary.json").write_text("{}")
    assert [p.name for p in (tmp_path / "a").iterdir()] == ["out"]
    with pytest.raises(Interrupted), atomic_output_folder(tmp_path / "b") as part:
        (part / "half.csv").write_text("1,")
        raise Interrupted(15)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a"]


def test_a_used_folder_is_refused_and_overwrite_replaces_it_once_complete(tmp_path):
    used = tmp_path / "run"
    used.mkdir()
    (used / "summary.json").write_text("{}")
    with pytest.raises(RunFolderError, match="holds a finished run"):
        check_output_folder(used, "--out")
    with pytest.raises(RuntimeError), atomic_output_folder(used, overwrite=True) as part:
        (part / "new.txt").write_text("new")
        raise RuntimeError("failed before the end")
    assert [p.name for p in used.iterdir()] == ["summary.json"]  # a failed replacement keeps the old folder
    with atomic_output_folder(used, overwrite=True) as part:
        (part / "new.txt").write_text("new")
    assert [p.name for p in used.iterdir()] == ["new.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_folder_a_run_is_writing_into_is_never_replaced(tmp_path):
    with claimed_run_folder(tmp_path / "run") as folder:
        (folder / "run.mcap").write_text("")
        with pytest.raises(RunFolderError, match="a run is writing into it"):
            check_output_folder(folder, "--out", overwrite=True)


@pytest.mark.parametrize("make,needle", [
    (lambda p: (p / "f").write_text(""), "is a file, not a folder"),
    (lambda p: None, None),
])
def test_paths_through_a_file_are_refused(tmp_path, make, needle):
    make(tmp_path)
    if needle is None:
        assert check_output_folder(tmp_path / "new" / "deeper", "--out") == tmp_path / "new" / "deeper"
        return
    with pytest.raises(RunFolderError, match=needle):
        check_output_folder(tmp_path / "f" / "x", "--out")


def test_output_files(tmp_path):
    (tmp_path / "dir").mkdir()
    for path, needle in ((tmp_path / "dir", "is a folder"), (tmp_path / "none" / "x.json", "does not exist")):
        with pytest.raises(RunFolderError, match=needle):
            check_output_file(path, "--stats")
    assert check_output_file(tmp_path / "x.json", "--stats") == tmp_path / "x.json"


def test_part_folders_of_dead_processes_are_swept(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True)
    (tmp_path / f".out.part-{int(dead.stdout)}").mkdir()
    (tmp_path / f".out.part-{os.getppid()}").mkdir()  # a live process's: kept
    (tmp_path / ".other").mkdir()
    sweep_dead_parts(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".other", f".out.part-{os.getppid()}"]


def test_write_failures_are_recognised_through_their_causes():
    try:
        try:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        except OSError as exc:
            raise RuntimeError("writer failed") from exc
    except RuntimeError as exc:
        assert "the disk is full" in write_failure(exc)
    assert "file size limit" in write_failure(OSError(errno.EFBIG, "File too large"))
    assert write_failure(OSError(errno.EACCES, "Permission denied")) is None
