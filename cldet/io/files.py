"""The file discipline of every output: checked up front, written atomically, never half there.

:func:`check_output` refuses, before any work, an output that could not be written (a missing
folder, a directory in the way, a folder without write access).
"""

from __future__ import annotations

import os
from pathlib import Path

from cldet.errors import OutputError

__all__ = ["check_output"]


def _writable(folder: Path) -> bool:
    return os.access(folder, os.W_OK | os.X_OK)


def check_output(path: str | os.PathLike[str], what: str = "output") -> Path:
    """Check that ``path`` can be written as a file, before any work is done.

    A symbolic link is checked (and later written) at its target.

    Args:
        path: the output file.
        what: what it is, for the message ("annotated log", "review recording").

    Returns:
        The path to write: ``path``, or the file a symbolic link points to.

    Raises:
        OutputError: the folder is missing or not a folder, ``path`` is a directory, or the
            folder is not writable; the message names the path.
    """
    target = Path(path)
    if target.is_symlink():
        target = target.resolve()
    if target.is_dir():
        raise OutputError(f"cannot write the {what} {path}: it is a directory")
    folder = target.parent
    if not folder.exists():
        raise OutputError(f"cannot write the {what} {path}: the folder {folder} does not exist")
    if not folder.is_dir():
        raise OutputError(f"cannot write the {what} {path}: {folder} is not a folder")
    if not _writable(folder):
        raise OutputError(f"cannot write the {what} {path}: the folder {folder} is not writable")
    return target
