"""Benchmark: scaling over workers, per-core speed against merely reading, memory on a long log.

One run, on the same simulated data (``mixed`` scenario, labelled, no images):

1. **The reading floor.** Every Mid-360 and Avia cloud of the logs read with the ``mcap``
   library's reader and decoded (protobuf, then a numpy view of the points), in this process.
2. **Per-core speed.** ``cldet annotate --no-rrd --workers 1`` as a whole process (start-up
   included), and the per-frame work alone (``annotate_log`` in this process after a warm-up
   log: imports and compilation excluded); each as a ratio of the floor's speed.
3. **Scaling.** ``cldet convert`` and ``cldet annotate --no-rrd`` as whole processes with
   1, 2, 4, ... workers (to the machine's cores), and with ``--executor ray`` (a local Ray
   started by the command) when Ray is installed; speed-up and efficiency against 1 worker.
   The disk's own write speed (fsync'd) is measured beside convert, which is mostly writing.
4. **Memory.** A long log (default 30 minutes, 18,000 Mid-360 frames) made by replaying one
   simulated log's messages back to back with their stamps shifted, then
   ``cldet annotate --no-rrd --workers 1``: its peak resident memory.

    python benchmarks/bench_scale.py                       # 24 logs of 20 s; workers 1, 2, 4, ...
    python benchmarks/bench_scale.py --logs 48 --ray       # also the Ray executor
    python benchmarks/bench_scale.py --long-minutes 0      # skip the memory run
    python benchmarks/bench_scale.py --work /tmp/scale     # keep (and reuse) the data

Timings on a shared machine are noisy: compare ratios within one run.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from machine import cpu_model  # benchmarks/machine.py (the script's folder is on the path)
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from simdata import parse_seeds, simulated_logs

from cldet.io import topics
from cldet.pipeline import annotate_log

CLOUD_TOPICS = (topics.LIDAR_360, topics.LIVOX_AVIA)


@dataclass
class Floor:
    """Reading and decoding every cloud of the logs."""

    seconds: float
    clouds: int
    frames: int  # Mid-360 clouds: annotate's frames


def read_floor(logs: Sequence[Path]) -> Floor:
    """Read and decode every Mid-360 and Avia cloud of ``logs`` with the mcap reader."""
    clouds = frames = 0
    started = time.perf_counter()
    for log in logs:
        with open(log, "rb") as stream:
            for _, channel, message in make_reader(stream).iter_messages(topics=CLOUD_TOPICS):
                cloud = PointCloud()
                cloud.ParseFromString(message.data)
                points = np.frombuffer(cloud.data, dtype=np.float32)
                points.reshape(-1, cloud.point_stride // 4)
                clouds += 1
                frames += channel.topic == topics.LIDAR_360
    return Floor(time.perf_counter() - started, clouds, frames)


@dataclass
class Run:
    """One command: wall seconds and the peak resident memory of its own process."""

    seconds: float
    peak_mb: float


def run_command(args: Sequence[str]) -> Run:
    """Run ``python -m cldet ARGS`` to the end; fail loudly if it fails."""
    started = time.perf_counter()
    process = subprocess.Popen(
        [sys.executable, "-m", "cldet", *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    assert process.stderr is not None
    errors = process.stderr.read()
    _, status, usage = os.wait4(process.pid, 0)
    process.returncode = os.waitstatus_to_exitcode(status)
    seconds = time.perf_counter() - started
    if process.returncode != 0:
        raise SystemExit(f"cldet {' '.join(args[:2])} ... failed:\n{errors.decode()[-2000:]}")
    return Run(seconds, usage.ru_maxrss / 1024)  # Linux: kilobytes


def fresh_copies(logs: Sequence[Path], folder: Path) -> list[Path]:
    """Copies of ``logs`` in an empty ``folder`` (annotate rewrites its logs in place)."""
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    return [Path(shutil.copy2(log, folder / log.name)) for log in logs]


def disk_write_gb_s(folder: Path, n_bytes: int) -> float:
    """The disk's own write speed: ``n_bytes`` in 8 MiB blocks, fsync'd, in GB/s."""
    block = os.urandom(8 << 20)
    path = folder / "disk-probe.bin"
    started = time.perf_counter()
    with open(path, "wb") as stream:
        for _ in range(max(1, n_bytes // len(block))):
            stream.write(block)
        stream.flush()
        os.fsync(stream.fileno())
    seconds = time.perf_counter() - started
    path.unlink()
    return max(1, n_bytes // len(block)) * len(block) / seconds / 1e9


def loop_log(source: Path, target: Path, minutes: float) -> int:
    """Replay ``source``'s messages back to back, stamps shifted, for ``minutes``; frames written.

    Every message's log and publish times move by whole multiples of the source's span; a
    message whose protobuf has a ``timestamp`` (every Foxglove schema) has it moved too.
    The static frame tree (``/tf``) is written once.
    """
    with open(source, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        first, last = summary.statistics.message_start_time, summary.statistics.message_end_time
        messages = list(reader.iter_messages())
    span = last - first + 100_000_000  # one frame period after the last message
    loops = max(1, round(minutes * 60e9 / span))
    decoders: dict[str, type[Any]] = {
        "foxglove.PointCloud": PointCloud,
        "foxglove.PoseInFrame": PoseInFrame,
    }
    frames = 0
    with open(target, "wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start()
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        for schema, channel, _ in messages:
            if schema is not None and schema.id not in schema_ids:
                schema_ids[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channel_ids:
                channel_ids[channel.id] = writer.register_channel(
                    channel.topic,
                    channel.message_encoding,
                    schema_ids.get(channel.schema_id, 0),
                    dict(channel.metadata),
                )
        for k in range(loops):
            shift = k * span
            for schema, channel, message in messages:
                if channel.topic == topics.TF and k:
                    continue
                data = message.data
                decoder = decoders.get(schema.name) if schema is not None else None
                if decoder is not None and shift:
                    decoded = decoder()
                    decoded.ParseFromString(data)
                    stamp = decoded.timestamp.ToNanoseconds() + shift
                    decoded.timestamp.FromNanoseconds(stamp)
                    data = decoded.SerializeToString()
                writer.add_message(
                    channel_ids[channel.id],
                    message.log_time + shift,
                    data,
                    message.publish_time + shift,
                )
                frames += channel.topic == topics.LIDAR_360
        writer.finish()
    return frames


def _row(name: str, seconds: float, base: float, workers: int) -> str:
    speedup = base / seconds
    return f"  {name:<22s} {seconds:8.2f} s   {speedup:6.2f}x   efficiency {speedup / workers:5.0%}"


def main() -> None:
    """Run the benchmark and print its tables."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    cores = os.cpu_count() or 1
    default_workers = ",".join(str(w) for w in (1, 2, 4, 8, 16, 32, 64) if w <= cores)
    parser.add_argument("--logs", type=int, default=24, help="simulated logs (default 24)")
    parser.add_argument("--duration", type=float, default=20.0, help="seconds per log")
    parser.add_argument("--seed", type=int, default=80000, help="first seed (default 80000)")
    parser.add_argument("--workers", default=default_workers, help="e.g. 1,2,4,8,16")
    parser.add_argument("--ray", action="store_true", help="also the Ray executor (local Ray)")
    parser.add_argument("--long-minutes", type=float, default=30.0, help="0 skips the memory run")
    parser.add_argument("--work", type=Path, help="keep (and reuse) the data here")
    args = parser.parse_args()
    workers = [int(w) for w in args.workers.split(",")]
    if args.ray and importlib.util.find_spec("ray") is None:
        raise SystemExit('--ray needs Ray: pip install -e ".[ray]"')

    work = args.work or Path(tempfile.mkdtemp(prefix="cldet-bench-scale-"))
    work.mkdir(parents=True, exist_ok=True)
    seeds = parse_seeds(f"{args.seed}-{args.seed + args.logs - 1}")
    t0 = time.perf_counter()
    data = simulated_logs(work, seeds, args.duration, cores)
    logs = data.logs
    print(f"machine: {cpu_model()}, {cores} cores; python {sys.version.split()[0]}")
    print(
        f"data: {len(logs)} simulated logs of {args.duration:.0f} s, seeds {seeds[0]}-{seeds[-1]}"
        f" ({time.perf_counter() - t0:.0f} s to make or find)"
    )

    # -- 1 + 2: the floor and per-core speed ----------------------------------------------------
    read_floor(logs)  # the page cache and the reader's imports, as for every run below
    floor = read_floor(logs)
    whole = run_command(
        [
            "annotate",
            *map(str, fresh_copies(logs, work / "ann1")),
            "--no-rrd",
            "--workers",
            "1",
        ]
    )
    copies = fresh_copies(logs, work / "ann-inproc")
    annotate_log(copies[0], write_rrd=False)  # warm-up: imports, numba, caches
    copies = fresh_copies(logs, work / "ann-inproc")
    started = time.perf_counter()
    for copy in copies:
        annotate_log(copy, write_rrd=False)
    per_frame = time.perf_counter() - started
    print(f"\n== per-core speed ({floor.frames} frames, {floor.clouds} clouds) ==")
    print(
        f"  read + decode (mcap reader)   {floor.seconds:7.2f} s   {floor.frames / floor.seconds:8.0f} frames/s"
    )
    for name, seconds in (
        ("annotate, whole process", whole.seconds),
        ("annotate, per-frame work", per_frame),
    ):
        print(
            f"  {name:<29s} {seconds:7.2f} s   {floor.frames / seconds:8.0f} frames/s"
            f"   {floor.seconds / seconds:5.3f}x the floor's speed"
        )

    # -- 3: scaling -------------------------------------------------------------------------------
    executors = ["local", "ray"] if args.ray else ["local"]
    convert_bytes = 0
    warm = work / "convert-warm-up"  # the .npy files into the page cache, as the logs are
    shutil.rmtree(warm, ignore_errors=True)
    run_command(["convert", str(data.dataset), "-o", str(warm), "--no-images"])
    shutil.rmtree(warm)
    print("\n== scaling (whole processes, same data) ==")
    for command in ("convert", "annotate"):
        base = 0.0
        for executor in executors:
            for n in workers:
                extra = ["--executor", executor] if executor != "local" else []
                if command == "convert":
                    out = work / f"convert-{executor}-{n}"
                    shutil.rmtree(out, ignore_errors=True)
                    cmd = [str(data.dataset), "-o", str(out), "--no-images", "--workers", str(n)]
                else:
                    out = work / f"annotate-{executor}-{n}"
                    cmd = [*map(str, fresh_copies(logs, out)), "--no-rrd", "--workers", str(n)]
                run = run_command([command, *cmd, *extra])
                if command == "convert":
                    convert_bytes = sum(p.stat().st_size for p in out.rglob("*.mcap"))
                shutil.rmtree(out, ignore_errors=True)
                base = base or run.seconds
                print(_row(f"{command} {executor} {n:>2d}", run.seconds, base, n))
        if command == "convert" and convert_bytes:
            speed = disk_write_gb_s(work, convert_bytes)
            print(
                f"  disk: writing the {convert_bytes / 1e9:.2f} GB convert writes, fsync'd, takes"
                f" {convert_bytes / 1e9 / speed:.2f} s ({speed:.2f} GB/s)"
            )

    # -- 4: memory --------------------------------------------------------------------------------
    if args.long_minutes > 0:
        long_log = work / "long" / "long.mcap"
        long_log.parent.mkdir(exist_ok=True)
        frames = loop_log(logs[0], long_log, args.long_minutes)
        run = run_command(["annotate", str(long_log), "--no-rrd", "--workers", "1"])
        print(f"\n== memory: one {args.long_minutes:.0f}-minute log ({frames} frames) ==")
        print(
            f"  annotate --no-rrd: {run.seconds:.1f} s, peak resident memory {run.peak_mb:.0f} MB"
        )
        long_log.unlink()


if __name__ == "__main__":
    main()
