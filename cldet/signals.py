"""Signals and worker processes: SIGTERM ends a run like Ctrl-C, and workers never outlive it.

- :func:`raise_on_sigterm` makes SIGTERM (what ``kill``, ``timeout``, systemd and Slurm send)
  raise :class:`Terminated`, a ``KeyboardInterrupt``: every ``finally`` runs, so temporary files
  are removed exactly as on Ctrl-C. Should a C callback swallow that exception,
  :func:`check_terminated` raises it again at the next frame or before a result is committed.
- :func:`init_worker` is the initializer of every worker pool: the worker raises on SIGTERM too,
  and stops when the process that started the run dies (even by SIGKILL), before it could rename
  a result into place.
- :func:`stop_workers` asks a pool's running workers to stop (on Ctrl-C or SIGTERM of the
  parent), instead of waiting for their current job.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import threading
import time
from types import FrameType
from typing import Any

__all__ = [
    "Terminated",
    "check_terminated",
    "init_worker",
    "pid_alive",
    "raise_on_sigterm",
    "sigterm_received",
    "stop_workers",
]

_PR_SET_PDEATHSIG = 1
_WATCH_PERIOD_S = 0.25
_GRACE_S = 3.0  # after SIGTERM, a worker that has not exited is ended with os._exit


class Terminated(KeyboardInterrupt):
    """SIGTERM was received; handled like Ctrl-C (temporary files removed), exit code 143."""


_sigterm_received = False


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    global _sigterm_received
    _sigterm_received = True
    raise Terminated(f"terminated by signal {signal.Signals(signum).name}")


def sigterm_received() -> bool:
    """Whether :func:`raise_on_sigterm`'s handler has run in this process.

    For code that calls libraries which turn any ``KeyboardInterrupt`` into a plain one (Ray's
    blocking calls do): a plain ``KeyboardInterrupt`` after SIGTERM was still SIGTERM.
    """
    return _sigterm_received


def check_terminated() -> None:
    """Raise :class:`Terminated` when SIGTERM arrived but its exception went missing.

    The handler's exception can be lost: raised while a C library runs a Python callback (numba
    loading a cached kernel does), it is printed as "Exception ignored" and the run goes on. The
    handler also sets a flag, and this checks it: call it where the work must not go on after
    SIGTERM (at each frame, and before any result is renamed into place).
    """
    if _sigterm_received:
        raise Terminated("terminated by signal SIGTERM")


def raise_on_sigterm() -> None:
    """Make SIGTERM raise :class:`Terminated` in the main thread (no-op elsewhere)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _raise_terminated)


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists and has not exited (a zombie, not yet reaped, is dead)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        pass
    try:
        with open(f"/proc/{pid}/stat", "rb") as stat:
            state = stat.read().rsplit(b")", 1)[1].split()[0]
    except (OSError, IndexError):
        return True  # no /proc: trust kill(pid, 0)
    return state not in (b"Z", b"X")


def _watch_parent(parent_pid: int) -> None:
    """In a worker: when ``parent_pid`` is gone, SIGTERM this process, then end it for sure."""
    while pid_alive(parent_pid) and os.getppid() != 1:
        time.sleep(_WATCH_PERIOD_S)
    os.kill(os.getpid(), signal.SIGTERM)  # the main thread raises Terminated and cleans up
    time.sleep(_GRACE_S)
    os._exit(1)


def _set_parent_death_signal() -> None:
    """Linux: SIGTERM this process when the process that forked it dies."""
    if not sys.platform.startswith("linux"):
        return
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)


def init_worker(parent_pid: int) -> None:
    """Initializer of a worker process of a run started by ``parent_pid``.

    SIGTERM raises :class:`Terminated`; Ctrl-C is left to the parent (which stops the workers);
    the worker stops when ``parent_pid`` dies (a watch thread, plus the kernel's parent-death
    signal where there is one).
    """
    raise_on_sigterm()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _set_parent_death_signal()
    if not pid_alive(parent_pid):
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True).start()


def stop_workers(executor: Any) -> None:
    """SIGTERM every live worker of a ``ProcessPoolExecutor`` (they remove their temporary files)."""
    processes = getattr(executor, "_processes", None) or {}
    for process in list(processes.values()):
        with contextlib.suppress(ProcessLookupError, OSError, AttributeError, ValueError):
            if process.is_alive():
                os.kill(process.pid, signal.SIGTERM)
