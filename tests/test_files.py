"""``cldet.io.files``: atomic outputs (mode, links, fsync, stale temporaries) and the lock."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from cldet.errors import OutputError, OutputExistsError
from cldet.io import files
from cldet.io.files import atomic_output, check_output, lock_file, remove_stale_temporaries
from cldet.results import ResultRow, write_results


def _mode(path: Path) -> int:
    return path.stat().st_mode & 0o7777


@pytest.fixture
def umask_027() -> object:
    old = os.umask(0o027)
    yield
    os.umask(old)


def test_a_new_output_honours_the_umask(tmp_path: Path, umask_027: object) -> None:
    with atomic_output(tmp_path / "a.mcap") as out:
        out.write(b"x")
    assert _mode(tmp_path / "a.mcap") == 0o640
    csv = tmp_path / "r.csv"  # was 0600 from mkstemp
    write_results(csv, [ResultRow("seq1", "1.000000", 10**9, (0.0, 0.0, 0.0), 0)])
    assert _mode(csv) == 0o640


def test_a_replaced_output_keeps_its_mode(tmp_path: Path) -> None:
    target = tmp_path / "log.mcap"
    target.write_bytes(b"old")
    target.chmod(0o444)
    with atomic_output(target, overwrite=True) as out:
        out.write(b"new")
    assert target.read_bytes() == b"new" and _mode(target) == 0o444


def test_a_symbolic_link_is_written_through_and_kept(tmp_path: Path) -> None:
    real = tmp_path / "data" / "log.mcap"
    real.parent.mkdir()
    real.write_bytes(b"old")
    link = tmp_path / "link.mcap"
    link.symlink_to(real)
    with atomic_output(link, overwrite=True) as out:
        out.write(b"new")
    assert link.is_symlink() and real.read_bytes() == b"new"
    assert sorted(p.name for p in real.parent.iterdir()) == ["log.mcap"]


def test_the_file_is_synced_before_the_rename(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    synced: list[int] = []
    real_fsync = os.fsync
    monkeypatch.setattr(files.os, "fsync", lambda fd: (synced.append(fd), real_fsync(fd)))
    with atomic_output(tmp_path / "a.bin") as out:
        out.write(b"x")
    assert len(synced) >= 1


def test_an_existing_output_is_not_replaced_by_accident(tmp_path: Path) -> None:
    (tmp_path / "a.bin").write_bytes(b"keep")
    with (
        pytest.raises(OutputExistsError, match=r"a\.bin already exists: pass overwrite"),
        atomic_output(tmp_path / "a.bin"),
    ):
        pass
    assert (tmp_path / "a.bin").read_bytes() == b"keep"


def test_stale_temporaries_of_dead_processes_are_removed(tmp_path: Path) -> None:
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)  # fmt: skip
    dead_pid = int(dead.stdout)
    stale = tmp_path / f".seq0001.mcap.tmp-{dead_pid}"
    stale_clean = tmp_path / f".seq0001.mcap.clean-{dead_pid}"
    live = tmp_path / f".seq0002.mcap.tmp-{os.getppid()}"  # a live process: kept
    other = tmp_path / ".notes.tmp"  # not ours: kept
    for path in (stale, stale_clean, live, other):
        path.write_bytes(b"half")
    with atomic_output(tmp_path / "seq0003.mcap") as out:
        out.write(b"x")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [live.name, other.name, "seq0003.mcap"]
    )
    assert remove_stale_temporaries(tmp_path) == []


def test_a_read_only_output_is_refused_unless_forced(tmp_path: Path) -> None:
    log = tmp_path / "ro.mcap"
    log.write_bytes(b"x")
    log.chmod(0o444)
    with pytest.raises(
        OutputError, match=r"the annotated log .*ro\.mcap is read-only \(mode 0444\): pass --force"
    ):
        check_output(log, "annotated log", force=False)
    assert check_output(log, "annotated log", force=True) == log


def test_a_second_lock_refuses_with_a_clear_message(tmp_path: Path) -> None:
    log = tmp_path / "log.mcap"
    log.write_bytes(b"x")
    with (
        lock_file(log, "log"),
        pytest.raises(OutputError, match=r"the log .*log\.mcap is being rewritten by another"),
        lock_file(log, "log"),
    ):
        pass
    with lock_file(log, "log"):  # released
        pass


def test_a_lock_follows_a_file_replaced_meanwhile(tmp_path: Path) -> None:
    log = tmp_path / "log.mcap"
    log.write_bytes(b"x")
    with lock_file(log, "log"):
        (tmp_path / "new").write_bytes(b"y")
        os.replace(tmp_path / "new", log)  # what an annotate run does at its end
        with lock_file(log, "log"):  # the new file is not locked
            pass
