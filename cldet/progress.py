"""Progress reporting: library code reports work done; the CLI decides whether a bar is drawn."""

from __future__ import annotations

import sys
from types import TracebackType
from typing import Any, Protocol


class Progress(Protocol):
    """Receives progress from long-running library calls."""

    def start(self, total: int, description: str) -> None:
        """Announce ``total`` units of work (sets or replaces the total)."""

    def advance(self, n: int = 1) -> None:
        """Report ``n`` more units done."""


class NullProgress:
    """A progress sink that does nothing (tests, libraries, non-interactive use)."""

    def start(self, total: int, description: str) -> None:
        """Ignore the announcement."""

    def advance(self, n: int = 1) -> None:
        """Ignore the report."""


class BarProgress:
    """A rich progress bar on stderr, drawn only when stderr is a terminal (quiet in CI and pipes)."""

    def __init__(self, enabled: bool | None = None) -> None:
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self._progress: Any = None  # rich.progress.Progress once entered and enabled
        self._task: Any = None  # its task id

    def __enter__(self) -> BarProgress:
        if self.enabled:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )
            from rich.progress import (
                Progress as RichProgress,
            )

            self._progress = RichProgress(
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                TimeRemainingColumn(),
                console=Console(stderr=True),
                transient=False,
            )
            self._progress.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._progress is not None:
            self._progress.stop()

    def start(self, total: int, description: str) -> None:
        """Start (or restart) the bar with a new total and description."""
        if self._progress is None:
            return
        if self._task is None:
            self._task = self._progress.add_task(description, total=total)
        else:
            self._progress.reset(self._task, total=total, description=description)

    def advance(self, n: int = 1) -> None:
        """Move the bar forward by ``n``."""
        if self._progress is not None and self._task is not None:
            self._progress.advance(self._task, n)
