"""The Ray executor on a local Ray (started once for this module, 2 CPUs): the executors'
contract, and ``convert`` and ``annotate`` giving the local executor's outputs byte for byte,
with the same per-file failures.

The ``.rrd`` review recordings are left out of the byte comparisons (``write_rrd=False``): Rerun
gives every recording a random id, so two runs of the same executor differ there too.
"""

from __future__ import annotations

import logging
import os
import shutil
import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cldet.executors import iter_outcomes
from cldet.pipeline import annotate_logs
from converters.mcap_convert import ConvertReport, convert_dataset
from tests.executor_jobs import pid, square
from tests.test_executors import CountingProgress, check_square_outcomes

ray = pytest.importorskip("ray", reason='the ray extra is not installed: pip install -e ".[ray]"')

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module", autouse=True)
def local_ray() -> Iterator[None]:
    """One local Ray for the module's tests (the executors use a connection they find)."""
    sigterm = signal.getsignal(signal.SIGTERM)
    ray.init(
        address="local",
        num_cpus=2,
        include_dashboard=False,
        log_to_driver=False,
        logging_level=logging.ERROR,
    )
    signal.signal(signal.SIGTERM, sigterm)  # ray.init replaces it
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three simulated 3 s sequences (no images) and a fourth with a truncated cloud."""
    from cldet.simulate import simulate_sequence

    root = tmp_path_factory.mktemp("ray") / "data"
    for seed, seq in enumerate(["train/seq0001", "train/seq0002", "val/seq0001"]):
        simulate_sequence(root / seq, seed=seed, duration_s=3.0, images=False)
    shutil.copytree(root / "train" / "seq0001", root / "train" / "seq0003")
    bad = sorted((root / "train" / "seq0003" / "lidar_360").iterdir())[5]
    bad.write_bytes(bad.read_bytes()[:100])
    return root


def files(root: Path) -> dict[str, bytes]:
    """Every file under ``root``, by relative path."""
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }


@pytest.fixture(scope="module")
def converted(
    dataset: Path, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, tuple[Path, ConvertReport, int]]:
    """The dataset converted by each executor: (output folder, report, progress units)."""
    root = tmp_path_factory.mktemp("converted")
    out = {}
    for executor in ("local", "ray"):
        progress = CountingProgress()
        report = convert_dataset(
            dataset, root / executor, workers=2, executor=executor, progress=progress
        )
        out[executor] = (root / executor, report, progress.done)
    return out


def test_ray_executor_contract() -> None:
    progress = CountingProgress()
    outcomes = list(iter_outcomes(square, range(7), workers=2, executor="ray", progress=progress))
    check_square_outcomes(outcomes, progress)
    pids = {o.result for o in iter_outcomes(pid, range(4), workers=2, executor="ray")}
    assert os.getpid() not in pids  # Ray's worker processes


def test_convert_on_ray_equals_local_file_for_file(
    converted: dict[str, tuple[Path, ConvertReport, int]],
) -> None:
    local_out, local, local_progress = converted["local"]
    ray_out, on_ray, ray_progress = converted["ray"]
    assert len(local.converted) == 3 and local.frames > 0
    assert [p.relative_to(local_out) for p in local.converted] == [
        p.relative_to(ray_out) for p in on_ray.converted
    ]
    assert files(ray_out) == files(local_out)  # byte for byte, and no leftovers
    # the failing sequence is reported the same way, naming the bad file
    assert local.failed == on_ray.failed and [f.sequence for f in local.failed] == ["train/seq0003"]
    assert "truncated or corrupt" in local.failed[0].message
    assert (local.frames, local.bytes_in, local.bytes_out) == (
        on_ray.frames,
        on_ray.bytes_in,
        on_ray.bytes_out,
    )
    assert ray_progress == local_progress >= local.frames  # the bar moves under Ray too


@pytest.fixture
def logs(
    converted: dict[str, tuple[Path, ConvertReport, int]], tmp_path: Path
) -> Callable[[str], list[Path]]:
    """``logs(name)``: a fresh copy of the converted logs, and a log that is not one."""

    def copy(name: str) -> list[Path]:
        source = converted["local"][0]
        folder = tmp_path / name
        shutil.copytree(source, folder)
        (folder / "bad.mcap").write_bytes(b"not an mcap file")
        return sorted(folder.rglob("*.mcap"))

    return copy


def test_annotate_on_ray_equals_local_file_for_file(logs: Callable[[str], list[Path]]) -> None:
    results = {}
    for executor in ("local", "ray"):
        paths = logs(executor)
        folder = paths[0].parent  # bad.mcap, first
        reports, failures = annotate_logs(
            paths, write_rrd=False, workers=2, executor=executor, progress=CountingProgress()
        )
        results[executor] = (
            files(folder),
            [(r.log.relative_to(folder), r.frames, r.sources, r.rms_error_m) for r in reports],
            [(p.relative_to(folder), m.replace(str(folder), "")) for p, m in failures],
        )
    local, on_ray = results["local"], results["ray"]
    assert len(local[1]) == 3 and all(frames > 0 for _, frames, _, _ in local[1])
    assert on_ray[0] == local[0]  # every annotated log byte for byte (and nothing else written)
    assert on_ray[1] == local[1]  # the reports, but for their wall time
    assert on_ray[2] == local[2] and [str(p) for p, _ in local[2]] == ["bad.mcap"]


def test_cli_on_ray(logs: Callable[[str], list[Path]], dataset: Path, tmp_path: Path) -> None:
    from cldet.cli import app

    runner = CliRunner()
    paths = [p for p in logs("cli") if p.name != "bad.mcap"]
    result = runner.invoke(
        app, ["annotate", *map(str, paths), "--no-rrd", "--executor", "ray", "--workers", "2"]
    )
    assert result.exit_code == 0, result.output
    assert len([line for line in result.output.splitlines() if " frames in " in line]) == 3
    result = runner.invoke(
        app,
        [
            "convert",
            str(dataset),
            "-o",
            str(tmp_path / "out"),
            "--executor",
            "ray",
            "--split",
            "val",
        ],
    )
    assert result.exit_code == 0, result.output
    assert "converted 1 sequence(s)" in result.output


def test_sigterm_mid_convert_on_ray_leaves_nothing_behind(tmp_path: Path) -> None:
    """As tests/test_signals.py for the local executor: exit code 143, one line, no temporary
    file, the inputs untouched, no process of the run left (its own local Ray included)."""
    import subprocess
    import sys
    import time

    from tests.test_signals import (
        SLOW_LOAD,
        build,
        digest,
        hooked_env,
        processes_left,
        temporaries,
    )

    data, out = tmp_path / "data", tmp_path / "logs"
    build(data)
    before = digest(data)
    tag = f"{os.getpid()}ray"
    env = hooked_env(tmp_path, SLOW_LOAD, tag)
    env.pop("RAY_ADDRESS", None)
    command = [sys.executable, "-m", "cldet", "convert", str(data), "-o", str(out)]
    run = subprocess.Popen(
        [*command, "--workers", "2", "--executor", "ray"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 120  # Ray starts in ~10 s on a busy 2-core machine
    while not (out.is_dir() and temporaries(out)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert temporaries(out), "the run never started writing"
    time.sleep(0.5)
    run.send_signal(signal.SIGTERM)
    run.wait(timeout=60)
    assert run.stderr is not None
    err = run.stderr.read()
    assert run.returncode == 143, err
    assert err.strip() == b"terminated (SIGTERM); temporary files removed"
    assert temporaries(out) == [] and digest(data) == before
    assert processes_left(tag, within_s=15) == []
