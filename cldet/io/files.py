"""The file discipline of every output: checked up front, written atomically, never half there.

- :func:`check_output` refuses, before any work, an output that could not be written (a missing
  folder, a directory in the way, a folder without write access, a read-only file).
- :func:`atomic_path` / :func:`atomic_output` write into ``.<name>.tmp-<pid>`` beside the target,
  then flush it to disk (fsync), give it the target's mode (or the umask's default for a new
  file) and rename it over the target. A symbolic link is written through: its target is
  replaced and the link stays. An exception, Ctrl-C or SIGTERM (see :mod:`cldet.signals`)
  removes the temporary file; temporary files left by processes that died (SIGKILL, power
  loss) are removed by the next write into the same folder.
- :func:`lock_file` takes an exclusive ``fcntl`` lock so that two runs never rewrite one file
  at once.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from cldet.errors import OutputError, OutputExistsError
from cldet.signals import check_terminated, pid_alive

__all__ = [
    "atomic_output",
    "atomic_path",
    "check_output",
    "lock_file",
    "commit",
    "remove_stale_temporaries",
    "resolve_link",
    "temporary_path",
]

# ".<name>.tmp-<pid>" (and ".<name>.clean-<pid>", annotate's intermediate copy)
_TEMPORARY = re.compile(r"^\..+\.(?:tmp|clean)-(\d+)$")


def _writable(folder: Path) -> bool:
    return os.access(folder, os.W_OK | os.X_OK)


def resolve_link(path: str | os.PathLike[str]) -> Path:
    """``path``, or the file it finally points to when it is a symbolic link."""
    target = Path(path)
    return target.resolve() if target.is_symlink() else target


def check_output(path: str | os.PathLike[str], what: str = "output", *, force: bool = True) -> Path:
    """Check that ``path`` can be written as a file, before any work is done.

    A symbolic link is checked (and later written) at its target.

    Args:
        path: the output file.
        what: what it is, for the message ("annotated log", "recording").
        force: also allow replacing an existing file without write permission (read-only).

    Returns:
        The path to write: ``path``, or the file a symbolic link points to.

    Raises:
        OutputError: the folder is missing or not a folder, ``path`` is a directory, the folder
            is not writable, or ``path`` is read-only and ``force`` is false; the message names
            the path.
    """
    target = resolve_link(path)
    if target.is_dir():
        raise OutputError(f"cannot write the {what} {path}: it is a directory")
    folder = target.parent
    if not folder.exists():
        raise OutputError(f"cannot write the {what} {path}: the folder {folder} does not exist")
    if not folder.is_dir():
        raise OutputError(f"cannot write the {what} {path}: {folder} is not a folder")
    if not _writable(folder):
        raise OutputError(f"cannot write the {what} {path}: the folder {folder} is not writable")
    if not force and target.exists():
        mode = stat.S_IMODE(target.stat().st_mode)
        if not mode & 0o222:
            raise OutputError(
                f"the {what} {path} is read-only (mode {mode:04o}): pass --force to rewrite it "
                "(its mode is kept)"
            )
    return target


def temporary_path(target: Path, kind: str = "tmp") -> Path:
    """``.<name>.<kind>-<pid>`` beside ``target``: where it is written before the rename."""
    return target.with_name(f".{target.name}.{kind}-{os.getpid()}")


def remove_stale_temporaries(folder: Path) -> list[Path]:
    """Remove the temporary files in ``folder`` whose writing process no longer exists.

    Only names of the form ``.<name>.tmp-<pid>`` / ``.<name>.clean-<pid>`` are considered, and
    only when no process ``pid`` exists (a live process's files are never touched).

    Returns:
        The files removed.
    """
    removed: list[Path] = []
    try:
        with os.scandir(folder) as entries:
            names = [e.name for e in entries if e.name.startswith(".")]
    except OSError:
        return removed
    for name in names:
        match = _TEMPORARY.match(name)
        if match is None:
            continue
        pid = int(match.group(1))
        if pid == os.getpid() or pid_alive(pid):
            continue
        path = folder / name
        with contextlib.suppress(FileNotFoundError, IsADirectoryError, PermissionError):
            path.unlink()
            removed.append(path)
    return removed


def file_size(path: str | os.PathLike[str]) -> int:
    """A file's size in bytes, 0 when it cannot be read (whoever opens it says why)."""
    try:
        return os.stat(path).st_size
    except OSError:
        return 0


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def commit(tmp: Path, target: Path, mode: int | None = None) -> None:
    """Flush ``tmp`` to disk, give it ``mode`` and rename it over ``target`` (then sync the folder).

    Args:
        tmp: the complete temporary file, in ``target``'s folder.
        target: the final name.
        mode: permission bits; default: ``target``'s when it exists, else ``0o666`` less the umask.
    """
    check_terminated()  # a SIGTERM whose exception a C callback swallowed: no result
    if mode is None:
        try:
            mode = stat.S_IMODE(target.stat().st_mode)
        except FileNotFoundError:
            mode = 0o666 & ~_umask()
    with open(tmp, "rb") as stream:
        os.fsync(stream.fileno())
    os.chmod(tmp, mode)
    os.replace(tmp, target)
    with contextlib.suppress(OSError):  # the rename itself, on file systems that allow it
        folder = os.open(target.parent, os.O_RDONLY)
        try:
            os.fsync(folder)
        finally:
            os.close(folder)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], *, overwrite: bool = False) -> Iterator[Path]:
    """A temporary path beside ``path`` to write; renamed over ``path`` once the block succeeds.

    The temporary file is removed on any exception, KeyboardInterrupt (and so SIGTERM, see
    :mod:`cldet.signals`) included, so a crash never leaves half a file and never touches an
    existing ``path``. A symbolic link ``path`` is kept: the file it points to is replaced. The
    result keeps an existing file's mode, or gets the umask's default; it is synced to disk
    before the rename.

    Raises:
        OutputExistsError: ``path`` exists and ``overwrite`` is false.
    """
    target = resolve_link(path)
    if target.exists() and not overwrite:
        raise OutputExistsError(
            f"{path} already exists: pass overwrite (--overwrite) to replace it"
        )
    remove_stale_temporaries(target.parent)
    tmp = temporary_path(target)
    done = False
    try:
        yield tmp
        commit(tmp, target)
        done = True
    finally:
        if not done:
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike[str], *, overwrite: bool = False) -> Iterator[IO[bytes]]:
    """Open a temporary file beside ``path`` for writing; rename it to ``path`` once complete.

    See :func:`atomic_path` for the guarantees.

    Raises:
        OutputExistsError: ``path`` exists and ``overwrite`` is false.
    """
    with atomic_path(path, overwrite=overwrite) as tmp, open(tmp, "wb") as stream:
        yield stream


@contextlib.contextmanager
def lock_file(path: str | os.PathLike[str], what: str = "file") -> Iterator[None]:
    """Hold an exclusive lock on ``path`` (its target, for a link) for the block; never waits.

    The lock is an ``fcntl.flock`` on the file itself (no lock file is left behind); it goes
    with the process, so a killed run never leaves a file locked. When the file was replaced
    (renamed over) between opening and locking, the new file is locked instead.

    Raises:
        OutputError: another process holds the lock (the message says what to do); the file
            cannot be opened.
    """
    target = resolve_link(path)
    for _ in range(10):
        try:
            fd = os.open(target, os.O_RDONLY)
        except OSError as err:
            raise OutputError(f"cannot open the {what} {path}: {err.strerror or err}") from err
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as err:
                if err.errno in (errno.EWOULDBLOCK, errno.EACCES):
                    raise OutputError(
                        f"the {what} {path} is being rewritten by another process (another "
                        "`cldet annotate`?): wait for it to finish, then run again"
                    ) from err
                raise
            try:
                same = os.fstat(fd).st_ino == os.stat(target).st_ino
            except FileNotFoundError:
                same = False
            if same:
                yield
                return
        finally:
            os.close(fd)
    raise OutputError(f"the {what} {path} keeps being replaced by another process")
