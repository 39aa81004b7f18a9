"""Executors: run one function over many jobs (one per file), in worker processes or on Ray.

:func:`iter_outcomes` takes a picklable module-level function ``fn(job, progress) -> result``
and a list of picklable jobs, and yields one :class:`Outcome` per job as it completes (in no
particular order; ``Outcome.index`` says which job it was). Two executors run it:

- ``local``: worker processes on this machine (``forkserver``: no inherited threads or open
  files); one worker, or one job, runs in this process. Workers raise on SIGTERM, stop when the
  process that started them dies, and are stopped (not waited for) on Ctrl-C or SIGTERM.
- ``ray``: one Ray task per job (one CPU each), on a local Ray started for the run (``workers``
  CPUs, no dashboard, worker logs not forwarded) or on a cluster joined at ``ray_address`` (or
  ``$RAY_ADDRESS``). Every node needs cldet installed and the files at the same paths (a shared
  file system): the tasks receive paths, not data. Ctrl-C or SIGTERM cancels the running tasks
  (they remove their temporary files) and a Ray started here is shut down. Needs
  ``pip install "cldet[ray]"``.

Both executors report the same outcomes for the same jobs: an exception raised by ``fn`` is that
job's failure (``Outcome.error``), the other jobs go on; a caller that treats some errors as a
crash raises them (``Outcome.raise_error``), which stops the jobs still running. The progress
units ``fn`` reports reach the caller's progress while the job runs, each exactly once.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing as mp
import os
import pickle
import signal
import threading
import time
import traceback
from collections.abc import Callable, Generator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace
from queue import Empty
from typing import Any, Generic, NoReturn, TypeVar

from cldet.errors import CldetError, ExecutorError
from cldet.progress import NullProgress, Progress
from cldet.signals import Terminated, init_worker, sigterm_received, stop_workers

__all__ = ["EXECUTORS", "RAY_INSTALL", "Outcome", "iter_outcomes", "runs_here"]

EXECUTORS: tuple[str, ...] = ("local", "ray")
RAY_INSTALL = 'pip install "cldet[ray]"'
_POLL_S = 0.2  # how often progress is forwarded while jobs run
_CANCEL_GRACE_S = 5.0  # cancelled Ray tasks get this long to remove their temporary files
_CONNECT_TIMEOUT_S = 5.0  # a Ray address that does not answer within this is an error

J = TypeVar("J")
R = TypeVar("R")


@dataclass(frozen=True)
class Outcome(Generic[R]):
    """What became of one job."""

    index: int  # the job's position in the list given
    result: R | None = None  # what the function returned (None when it raised)
    error: BaseException | None = None  # what it raised: this job's failure
    trace: str = ""  # the formatted traceback of ``error``, from the worker

    @property
    def ok(self) -> bool:
        """True when the function returned."""
        return self.error is None

    def message(self) -> str:
        """One line for a failure: a :class:`CldetError`'s own message; an ``OSError``'s file
        and reason; anything else (a bug) with its type and where it was raised."""
        err = self.error
        if err is None:
            return ""
        if isinstance(err, CldetError):
            return str(err)
        if isinstance(err, OSError) and err.strerror:
            names = [str(n) for n in (err.filename, err.filename2) if n is not None]
            return f"{' -> '.join(names)}: {err.strerror}" if names else err.strerror
        where = _innermost_frame(self.trace)
        text = str(err).strip().splitlines()
        return f"unexpected {type(err).__name__}{where}: {text[-1] if text else ''}".rstrip(": ")

    def raise_error(self) -> NoReturn:
        """Raise the job's error here (a caller's way to treat it as a crash, not a failure);
        from a worker process, with the worker's traceback as its cause."""
        err = self.error
        if err is None:
            raise ValueError(f"job {self.index} did not fail")
        if err.__traceback__ is None and err.__cause__ is None and self.trace:
            err.__cause__ = _WorkerTraceback(self.trace)
        raise err


class _WorkerTraceback(Exception):
    """The traceback of an error raised in a worker process, shown as its cause."""

    def __str__(self) -> str:
        return f'\n"""\n{self.args[0]}"""'


def _innermost_frame(trace: str) -> str:
    """`` at FILE:LINE`` of the last frame of a formatted traceback ('' without one)."""
    frames = [line.strip() for line in trace.splitlines() if line.strip().startswith('File "')]
    if not frames:
        return ""
    parts = frames[-1].split('"')
    line = frames[-1].split(", line ")[-1].split(",")[0]
    return f" at {parts[1]}:{line}" if len(parts) > 2 else ""


def iter_outcomes(
    fn: Callable[[J, Progress], R],
    jobs: Sequence[J],
    *,
    workers: int | None = None,
    executor: str = "local",
    ray_address: str | None = None,
    progress: Progress | None = None,
    costs: Sequence[float] | None = None,
) -> Generator[Outcome[R], None, None]:
    """Run ``fn(job, progress)`` on every job; yield each job's :class:`Outcome` as it completes.

    Close the iterator (``contextlib.closing``) to stop the workers early: leaving it, by an
    exception or Ctrl-C, stops the jobs still running, which remove their temporary files.

    Args:
        fn: a module-level function (pickled by reference) taking a job and a :class:`Progress`.
        jobs: picklable jobs (paths, frozen dataclasses of them).
        workers: jobs run at once (default: every CPU here, or every CPU of the Ray cluster).
            ``local`` with one worker, or one job, runs in this process.
        executor: ``local`` (worker processes here) or ``ray`` (Ray tasks).
        ray_address: with ``ray``, the cluster to join (``auto``: the one ``ray start`` ran on
            this machine; ``HOST:PORT``; ``ray://HOST:10001``). Default: ``$RAY_ADDRESS`` when
            set (``ray job submit`` sets it), else a local Ray started for the run and shut down
            after it; a process connected to Ray already keeps its connection (left open).
        progress: receives the units ``fn`` reports, while each job runs.
        costs: each job's expected cost (e.g. its file's size): the costliest start first, so
            that the run does not end with one long job on one worker while the others idle
            (longest-processing-time-first). Default: in the order given.

    Yields:
        One :class:`Outcome` per job, in the order they complete.

    Raises:
        ExecutorError: an unknown executor; Ray not installed or not reachable; a local worker
            process died (killed, out of memory).
    """
    if executor not in EXECUTORS:
        raise ExecutorError(
            f"unknown executor {executor!r}: expected one of {', '.join(EXECUTORS)}"
        )
    if ray_address is not None and executor != "ray":
        raise ExecutorError("a Ray address goes with the ray executor")
    if workers is not None and workers < 1:
        raise ExecutorError(f"workers must be at least 1, not {workers}")
    if costs is not None and len(costs) != len(jobs):
        raise ExecutorError(f"{len(costs)} costs for {len(jobs)} jobs")
    progress = progress or NullProgress()
    # the costliest first (stable: equal costs keep their order)
    order = list(range(len(jobs)))
    if costs is not None:
        order.sort(key=lambda i: -costs[i])
    ordered = [jobs[i] for i in order]
    if executor == "ray":
        ray = _import_ray()  # before any work: a missing Ray is one line, at once
        if not jobs:
            return _iter_here(fn, [], progress)
        return _as_given(_iter_ray(ray, fn, ordered, workers, ray_address, progress), order)
    if runs_here(len(jobs), workers, executor):
        return _as_given(_iter_here(fn, ordered, progress), order)
    return _as_given(_iter_pool(fn, ordered, _local_workers(len(jobs), workers), progress), order)


def _local_workers(n_jobs: int, workers: int | None) -> int:
    """Worker processes the local executor starts for ``n_jobs`` (None: one per CPU)."""
    return min(workers or os.cpu_count() or 1, n_jobs)


def runs_here(n_jobs: int, workers: int | None, executor: str) -> bool:
    """Whether :func:`iter_outcomes` runs these jobs one after another in this process (the
    local executor with one worker or one job): the caller may then run them itself, with
    progress finer than one unit per job."""
    return executor == "local" and _local_workers(n_jobs, workers) <= 1


def _as_given(
    outcomes: Generator[Outcome[R], None, None], order: list[int]
) -> Generator[Outcome[R], None, None]:
    """The outcomes of jobs run in ``order``, each with its index in the list given."""
    try:
        for outcome in outcomes:
            yield replace(outcome, index=order[outcome.index])
    finally:
        outcomes.close()  # stop the workers when the caller stops early


# --- in a worker: call the function, keep what it raised ------------------------------------
@dataclass(frozen=True)
class _Done:
    result: Any = None
    error: BaseException | None = None
    trace: str = ""
    counted: int = 0  # progress units the job reported, in all


def _portable(err: BaseException) -> BaseException:
    """``err`` if it survives pickling (to cross to the parent), else a RuntimeError naming it."""
    try:
        pickle.loads(pickle.dumps(err))
    except Exception:
        return RuntimeError(f"{type(err).__name__}: {err}")
    return err


def _call(fn: Callable[[Any, Progress], Any], job: Any, progress: Progress) -> _Done:
    """``fn(job, progress)``; an ``Exception`` it raises becomes the job's error."""
    try:
        return _Done(result=fn(job, progress))
    except Exception as err:
        return _Done(error=err, trace=traceback.format_exc())


class _ForwardingProgress:
    """A worker's progress, sent to the parent in batches of ``(job index, n)`` messages.

    The messages only make the bar move while a job runs: the job's :class:`_Done` carries its
    total (``counted``), which the parent's :class:`_ProgressLedger` settles exactly.
    """

    def __init__(self, queue: Any, index: int) -> None:
        self._queue = queue
        self._index = index
        self._pending = 0
        self.counted = 0
        self._last = time.monotonic()

    def start(self, total: int, description: str) -> None:
        """Totals are announced by the parent."""

    def advance(self, n: int = 1) -> None:
        """Count ``n`` units; send the count every 64 units or 0.2 s."""
        self._pending += n
        self.counted += n
        now = time.monotonic()
        if self._pending >= 64 or now - self._last > _POLL_S:
            self.flush()
            self._last = now

    def flush(self) -> None:
        """Send what has been counted (a lost message only delays the bar)."""
        if self._pending and self._queue is not None:
            with contextlib.suppress(Exception):
                self._queue.put((self._index, self._pending))
            self._pending = 0


def _call_forwarding(fn: Callable[[Any, Progress], Any], job: Any, index: int, queue: Any) -> _Done:
    progress = _ForwardingProgress(queue, index)
    done = _call(fn, job, progress)
    progress.flush()
    if done.error is not None:
        done = _Done(error=_portable(done.error), trace=done.trace)
    return _Done(done.result, done.error, done.trace, counted=progress.counted)


class _ProgressLedger:
    """The parent's side: forwards workers' counts once each, whatever order they arrive in.

    Messages still in the queue when a job's outcome arrives are not lost: the outcome's total
    settles the job (the difference is advanced at once) and its late messages are dropped.
    """

    def __init__(self, progress: Progress) -> None:
        self._progress = progress
        self._received: dict[int, int] = {}
        self._settled: set[int] = set()

    def message(self, index: int, n: int) -> None:
        """A count from the queue."""
        if index in self._settled:
            return
        self._received[index] = self._received.get(index, 0) + n
        self._progress.advance(n)

    def settle(self, index: int, total: int) -> None:
        """The job is done and counted ``total`` in all."""
        if index in self._settled:
            return
        self._settled.add(index)
        rest = total - self._received.pop(index, 0)
        if rest > 0:
            self._progress.advance(rest)

    def drain(self, queue: Any) -> None:
        """Forward the counts waiting in ``queue`` (those in transit come with the outcomes)."""
        while True:
            try:
                index, n = queue.get_nowait()
            except Empty:  # ray.util.queue.Empty is one too
                return
            self.message(index, n)


# --- local: this process, or a pool of worker processes --------------------------------------
def _iter_here(
    fn: Callable[[J, Progress], R], jobs: list[J], progress: Progress
) -> Generator[Outcome[R], None, None]:
    for index, job in enumerate(jobs):
        done = _call(fn, job, progress)  # the caller's progress, unit by unit
        yield Outcome(index, done.result, done.error, done.trace)


_worker_queue: Any = None


def _init_pool_worker(queue: Any, parent_pid: int) -> None:
    global _worker_queue
    _worker_queue = queue
    init_worker(parent_pid)  # SIGTERM cleans up; the worker stops when the run's process dies


def _pool_task(fn: Callable[[Any, Progress], Any], job: Any, index: int) -> _Done:
    return _call_forwarding(fn, job, index, _worker_queue)


def _mp_context(fn: Callable[..., Any]) -> Any:
    """forkserver (fresh workers, forked from a server that has imported ``fn``'s module once,
    so they start in milliseconds); spawn where there is none. Like spawn, it imports the
    caller's ``__main__`` in the workers: scripts need a main guard."""
    if "forkserver" in mp.get_all_start_methods():
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload([__name__, fn.__module__])
        return ctx
    return mp.get_context("spawn")


def _iter_pool(
    fn: Callable[[J, Progress], R], jobs: list[J], workers: int, progress: Progress
) -> Generator[Outcome[R], None, None]:
    ctx = _mp_context(fn)
    queue = ctx.Queue()
    pool = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=ctx,
        initializer=_init_pool_worker,
        initargs=(queue, os.getpid()),
    )
    ledger = _ProgressLedger(progress)
    try:
        futures: dict[Future[_Done], int] = {
            pool.submit(_pool_task, fn, job, index): index for index, job in enumerate(jobs)
        }
        pending = set(futures)
        while pending:
            finished, pending = wait(pending, timeout=_POLL_S, return_when=FIRST_COMPLETED)
            ledger.drain(queue)
            for future in finished:
                index = futures[future]
                try:
                    done = future.result()
                except BrokenProcessPool as err:
                    raise ExecutorError(
                        f"a worker process died ({err}); was it killed, or out of memory?"
                    ) from err
                ledger.settle(index, done.counted)
                yield Outcome(index, done.result, done.error, done.trace)
    except BaseException:
        # Ctrl-C, SIGTERM, the caller leaving early or an unexpected error: stop the running
        # workers (they remove their temporary files) rather than wait for their jobs
        stop_workers(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        queue.close()
        queue.join_thread()


# --- Ray: one task per job ------------------------------------------------------------------
def _import_ray() -> Any:
    try:
        import ray
    except ImportError as err:
        raise ExecutorError(
            f"the ray executor needs Ray, which is not installed: {RAY_INSTALL}"
        ) from err
    return ray


def _check_reachable(address: str) -> None:
    """Fail at once on a ``HOST:PORT`` (or ``ray://HOST:PORT``) nobody listens at, instead of
    letting Ray retry for minutes."""
    import socket

    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit():
        return  # "auto", or a form Ray checks itself
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=_CONNECT_TIMEOUT_S).close()
    except OSError as err:
        raise ExecutorError(
            f"cannot reach Ray at {address}: {err.strerror or err}; is the cluster running "
            "(`ray status` on its head node)?"
        ) from err


def _connect_ray(ray: Any, address: str | None, workers: int | None) -> bool:
    """Connect this process to Ray (starting a local one without ``address``); True when this
    call connected it (and the caller shuts it down), False when it was connected already."""
    if ray.is_initialized():
        return False
    address = address or os.environ.get("RAY_ADDRESS") or None  # as `ray job submit` sets it
    main = threading.current_thread() is threading.main_thread()
    sigterm = signal.getsignal(signal.SIGTERM) if main else None
    quiet = {"log_to_driver": False, "logging_level": logging.ERROR}
    try:
        if address:
            _check_reachable(address)
            ray.init(address=address, **quiet)
        else:  # "local": a new Ray for this run, even where RAY_ADDRESS is set
            ray.init(address="local", num_cpus=workers, include_dashboard=False, **quiet)
    except (ConnectionError, ValueError, RuntimeError) as err:
        where = f"at {address}" if address else "locally"
        raise ExecutorError(f"cannot start or join Ray {where}: {err}") from err
    finally:
        if main and sigterm is not None:  # ray.init replaces the SIGTERM handler: restore ours
            signal.signal(signal.SIGTERM, sigterm)
    return True


def _ray_task(fn: Callable[[Any, Progress], Any], job: Any, index: int, queue: Any) -> _Done:
    return _call_forwarding(fn, job, index, queue)


def _ray_failure(err: BaseException) -> BaseException:
    """What a Ray task that did not return (a dead worker, a job Ray could not unpickle) is
    reported as: an :class:`ExecutorError` naming Ray's reason in one line."""
    lines = [line.strip() for line in str(err).strip().splitlines() if line.strip()]
    return ExecutorError(f"Ray task failed ({type(err).__name__}): {lines[-1] if lines else err}")


def _iter_ray(
    ray: Any,
    fn: Callable[[J, Progress], R],
    jobs: list[J],
    workers: int | None,
    address: str | None,
    progress: Progress,
) -> Generator[Outcome[R], None, None]:
    started_here = _connect_ray(ray, address, workers)
    from ray.util.queue import Queue

    queue: Any = None
    in_flight: dict[Any, int] = {}
    try:
        queue = Queue(actor_options={"num_cpus": 0})
        task = ray.remote(_ray_task).options(num_cpus=1, max_retries=0)
        ledger = _ProgressLedger(progress)
        limit = workers or len(jobs)  # with no limit Ray schedules them on its free CPUs
        waiting = list(enumerate(jobs))[::-1]
        while waiting or in_flight:
            while waiting and len(in_flight) < limit:
                index, job = waiting.pop()
                in_flight[task.remote(fn, job, index, queue)] = index
            ready, _ = ray.wait(list(in_flight), num_returns=1, timeout=_POLL_S)
            if ready:  # and every other one done by now
                ready, _ = ray.wait(list(in_flight), num_returns=len(in_flight), timeout=0)
            ledger.drain(queue)
            for ref in ready:
                index = in_flight.pop(ref)
                try:
                    done = ray.get(ref)
                except ray.exceptions.RayError as err:
                    done = _Done(error=_ray_failure(err), trace="")
                ledger.settle(index, done.counted)
                yield Outcome(index, done.result, done.error, done.trace)
    except BaseException as err:
        # Ctrl-C, SIGTERM, the caller leaving early: cancel the running tasks (KeyboardInterrupt
        # in them: they remove their temporary files) and give them a moment to do so
        for ref in in_flight:
            with contextlib.suppress(Exception):
                ray.cancel(ref)
        if in_flight:
            with contextlib.suppress(Exception):
                ray.wait(list(in_flight), num_returns=len(in_flight), timeout=_CANCEL_GRACE_S)
        if type(err) is KeyboardInterrupt and sigterm_received():
            # a blocking Ray call turned our Terminated into a plain KeyboardInterrupt
            raise Terminated("terminated by signal SIGTERM") from err
        raise
    finally:
        if queue is not None:
            with contextlib.suppress(Exception):
                queue.shutdown()
        if started_here:
            ray.shutdown()
