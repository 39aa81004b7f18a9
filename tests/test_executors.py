"""``cldet.executors`` with the local executor (in this process and in worker processes), its
errors, and the one-line error of ``--executor ray`` without Ray. The Ray executor runs the same
contract in tests/test_ray.py."""

from __future__ import annotations

import os
import sys
import traceback
from collections.abc import Callable
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cldet.errors import ExecutorError
from cldet.executors import (
    Outcome,
    _check_reachable,
    _ProgressLedger,
    iter_outcomes,
    runs_here,
)
from tests.executor_jobs import pid, square


class CountingProgress:
    def __init__(self) -> None:
        self.done = 0

    def start(self, total: int, description: str) -> None:
        """Not used by the executors."""

    def advance(self, n: int = 1) -> None:
        self.done += n


def check_square_outcomes(outcomes: list[Outcome[int]], progress: CountingProgress) -> None:
    """The contract on the jobs 0..6 of :func:`tests.executor_jobs.square`, for any executor."""
    assert sorted(o.index for o in outcomes) == list(range(7))  # every job, once
    by_index = {o.index: o for o in outcomes}
    assert {i: o.result for i, o in by_index.items() if o.ok} == {0: 0, 1: 1, 2: 4, 4: 16, 6: 36}
    assert by_index[3].message() == "job 3: not an MCAP file"  # a CldetError: its own message
    unexpected = by_index[5].message()
    assert unexpected.startswith("unexpected ZeroDivisionError at ")
    assert "executor_jobs.py:" in unexpected and unexpected.endswith(": division by zero")
    assert "ZeroDivisionError" in by_index[5].trace  # the worker's traceback, for a bug report
    with pytest.raises(ZeroDivisionError) as raised:  # a caller that calls it a crash
        by_index[5].raise_error()
    assert "executor_jobs.py" in "".join(traceback.format_exception(raised.value))
    assert progress.done == sum(range(7))  # every unit the jobs reported, exactly once


@pytest.mark.parametrize("workers", [1, 2])
def test_local_outcomes_all_arrive_with_failures_per_job(workers: int) -> None:
    progress = CountingProgress()
    outcomes = list(iter_outcomes(square, range(7), workers=workers, progress=progress))
    check_square_outcomes(outcomes, progress)


def test_local_workers_are_other_processes_and_one_worker_is_this_one() -> None:
    here = [o.result for o in iter_outcomes(pid, range(3), workers=1)]
    assert here == [os.getpid()] * 3  # in order, in this process
    pool = {o.result for o in iter_outcomes(pid, range(4), workers=2)}
    assert os.getpid() not in pool and 1 <= len(pool) <= 2


@pytest.mark.parametrize("workers", [1, 2])
def test_costliest_jobs_start_first_and_keep_their_index(workers: int) -> None:
    costs = [1.0, 5.0, 2.0, 7.0, 0.0, 3.0, 4.0]  # by cost: 3, 1, 6, 5, 2, 0, 4
    progress = CountingProgress()
    outcomes = list(
        iter_outcomes(square, range(7), workers=workers, progress=progress, costs=costs)
    )
    check_square_outcomes(outcomes, progress)  # each result under the index of its job
    if workers == 1:  # in this process, one after the other: the order they ran in
        assert [o.index for o in outcomes] == [3, 1, 6, 5, 2, 0, 4]
    with pytest.raises(ExecutorError, match="2 costs for 7 jobs"):
        iter_outcomes(square, range(7), costs=[1.0, 2.0])


def test_no_jobs_no_outcomes() -> None:
    assert list(iter_outcomes(square, [], workers=4)) == []


def test_progress_ledger_settles_counts_still_in_transit() -> None:
    """Counts a worker queued but the parent had not read when the outcome came are not lost."""
    progress = CountingProgress()
    ledger = _ProgressLedger(progress)
    ledger.message(0, 64)
    ledger.message(1, 10)
    ledger.settle(0, 100)  # job 0's last 36 were still in the queue
    assert progress.done == 110
    ledger.message(0, 36)  # ... and arrive late: dropped, not counted twice
    ledger.settle(0, 100)
    assert progress.done == 110
    ledger.settle(1, 10)
    ledger.settle(2, 5)  # a job whose messages never arrived at all
    assert progress.done == 115


def test_bad_arguments_are_named() -> None:
    with pytest.raises(ExecutorError, match=r"unknown executor 'dask': expected one of local, ray"):
        iter_outcomes(square, [1], executor="dask")
    with pytest.raises(ExecutorError, match=r"a Ray address goes with the ray executor"):
        iter_outcomes(square, [1], ray_address="auto")
    with pytest.raises(ExecutorError, match=r"workers must be at least 1, not 0"):
        iter_outcomes(square, [1], workers=0)


def test_a_ray_address_nobody_answers_at_fails_at_once() -> None:
    import socket

    with socket.socket() as sock:  # a port that was free a moment ago: nobody listens there
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    for address in (f"127.0.0.1:{port}", f"ray://127.0.0.1:{port}"):
        with pytest.raises(ExecutorError, match=rf"cannot reach Ray at {address}: .*ray status"):
            _check_reachable(address)
    _check_reachable("auto")  # left to Ray


@pytest.fixture
def no_ray(monkeypatch: pytest.MonkeyPatch) -> None:
    """Ray cannot be imported (as without the extra), whether it is installed or not."""
    monkeypatch.setitem(sys.modules, "ray", None)


@pytest.mark.usefixtures("no_ray")
def test_ray_executor_without_ray_says_how_to_install_it() -> None:
    with pytest.raises(
        ExecutorError, match=r'needs Ray, which is not installed: pip install "cldet\[ray\]"'
    ):
        iter_outcomes(square, [1], executor="ray")


@pytest.fixture
def cli() -> Callable[..., object]:
    from cldet.cli import app

    runner = CliRunner()
    return lambda *args: runner.invoke(app, [str(a) for a in args])


@pytest.mark.usefixtures("no_ray")
@pytest.mark.parametrize("command", ["annotate", "convert"])
def test_cli_without_ray_is_one_line_not_a_traceback(
    cli: Callable[..., object], tmp_path: Path, command: str
) -> None:
    if command == "annotate":
        args = ["annotate", tmp_path / "a.mcap", tmp_path / "b.mcap", "--executor", "ray"]
    else:
        (tmp_path / "data" / "val" / "seq0001" / "lidar_360").mkdir(parents=True)
        (tmp_path / "data" / "val" / "seq0001" / "lidar_360" / "1.000000.npy").write_bytes(b"")
        args = ["convert", tmp_path / "data", "-o", tmp_path / "logs", "--executor", "ray"]
    result = cli(*args)
    assert result.exit_code == 1  # type: ignore[attr-defined]
    lines = result.output.strip().splitlines()  # type: ignore[attr-defined]
    assert lines == [
        'ERROR: the ray executor needs Ray, which is not installed: pip install "cldet[ray]"'
    ]


def test_cli_ray_address_goes_with_the_ray_executor(
    cli: Callable[..., object], tmp_path: Path
) -> None:
    result = cli("annotate", tmp_path / "a.mcap", "--ray-address", "auto")
    assert result.exit_code == 1  # type: ignore[attr-defined]
    assert "ERROR: --ray-address goes with --executor ray" in result.output  # type: ignore[attr-defined]


@pytest.mark.parametrize("command", ["annotate", "convert"])
def test_cli_help_teaches_the_executors(cli: Callable[..., object], command: str) -> None:
    result = cli(command, "--help")
    assert result.exit_code == 0  # type: ignore[attr-defined]
    text = " ".join(result.output.split())  # type: ignore[attr-defined]
    for words in ("--executor", "--ray-address", 'pip install "cldet[ray]"', "cluster"):
        assert words in text, words


def test_runs_here_matches_where_iter_outcomes_runs_the_jobs() -> None:
    assert runs_here(5, 1, "local") and runs_here(1, 4, "local") and runs_here(0, None, "local")
    assert not runs_here(3, 2, "local")
    assert runs_here(3, None, "local") == ((os.cpu_count() or 1) <= 1)
    assert not runs_here(1, 1, "ray")  # a Ray task even for one job
