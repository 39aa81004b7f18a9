"""Jobs for the executor tests: module-level functions, so that workers can import them."""

from __future__ import annotations

import os
import time

from cldet.errors import LogError
from cldet.progress import Progress


def square(job: int, progress: Progress) -> int:
    """``job ** 2``, reporting ``job`` progress units; job 3 fails as a file would."""
    for _ in range(job):
        progress.advance()
    if job == 3:
        raise LogError("job 3: not an MCAP file")
    if job == 5:
        raise ZeroDivisionError("division by zero")
    time.sleep(0.05 * (job % 3))  # completion order differs from the order given
    return job * job


def pid(job: int, progress: Progress) -> int:
    """The worker's process id."""
    time.sleep(0.2)
    return os.getpid()
