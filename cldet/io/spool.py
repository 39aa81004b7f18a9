"""A list kept on disk: per-frame results held until the end of a pass without filling memory.

``annotate`` needs every frame's foreground and clusters once more at the end (to write the
``/cldet/foreground`` and ``/cldet/clusters`` channels with the refined choice), but holding them
grows memory with the sequence: a 30-minute log has 18,000 frames. A :class:`Spool` keeps each
item pickled in an anonymous temporary file (deleted by the system when closed, even after a
crash) and reads one back on demand.

Only items this process wrote are ever unpickled: the file is private to it and never named.
"""

from __future__ import annotations

import pickle
import tempfile
from collections.abc import Iterator, Sequence
from typing import TypeVar, overload

from cldet.errors import CldetError

__all__ = ["Spool"]

T = TypeVar("T")


class Spool(Sequence[T]):
    """An append-only sequence whose items live in a temporary file; :meth:`close` deletes it
    (``contextlib.closing`` for a block).

    Args:
        folder: where the temporary file goes (default: the system's temporary folder).
    """

    def __init__(self, folder: str | None = None) -> None:
        try:
            self._file = tempfile.TemporaryFile(dir=folder)  # noqa: SIM115 (closed by close())
        except OSError as err:
            where = folder or tempfile.gettempdir()
            raise CldetError(f"cannot create a temporary file in {where}: {err}") from err
        self._offsets = [0]

    def append(self, item: T) -> None:
        """Store ``item`` at the end."""
        data = pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL)
        try:
            self._file.seek(self._offsets[-1])
            self._file.write(data)
        except OSError as err:
            raise CldetError(f"cannot write the temporary spool file: {err}") from err
        self._offsets.append(self._offsets[-1] + len(data))

    def __len__(self) -> int:
        return len(self._offsets) - 1

    @overload
    def __getitem__(self, index: int) -> T: ...

    @overload
    def __getitem__(self, index: slice) -> list[T]: ...

    def __getitem__(self, index: int | slice) -> T | list[T]:
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        n = len(self)
        if not -n <= index < n:
            raise IndexError(f"spool index {index} out of range ({n} items)")
        index %= n
        start, end = self._offsets[index], self._offsets[index + 1]
        self._file.seek(start)
        item: T = pickle.loads(self._file.read(end - start))
        return item

    def __iter__(self) -> Iterator[T]:
        for i in range(len(self)):
            yield self[i]

    def close(self) -> None:
        """Delete the file (the items are gone)."""
        self._file.close()
