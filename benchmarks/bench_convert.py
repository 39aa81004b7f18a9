"""Benchmark ``cldet convert``: throughput next to the floor of merely ``np.load``-ing the inputs.

Generates (or takes) a dataset in the challenge layout, then measures in the same run:

* the floor: ``np.load`` of every ``.npy`` file, once, in one process (page cache warm);
* ``convert_dataset`` with 1 and 2 workers and zstd, lz4 and none compression.

Throughput is MB/s of raw ``.npy`` input (what the challenge ships) and frames/s, with each
run's ratio to the floor. Targets: zstd on 1 worker at least 30% of the floor's speed;
2 workers close to twice 1 worker.

    python benchmarks/bench_convert.py                     # generate 4 x 8 s sequences in a temp dir
    python benchmarks/bench_convert.py --data /path/root   # an existing dataset (e.g. the real one)
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from converters.mcap_convert import convert_dataset

MID360_ROWS = (20064, 19968, 19968)
PACKET = 96


def _mid360(rng: np.random.Generator, rows: int) -> np.ndarray:
    """~21% valid rows in 96-row packets, mm-quantized, like the real Mid-360 files."""
    frame = np.zeros((rows, 3))
    packets = rows // PACKET
    valid = rng.random(packets) < 0.21
    n = int(valid.sum()) * PACKET
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    points = direction * rng.uniform(1, 80, (n, 1))
    mask = np.repeat(valid, PACKET)
    frame[: packets * PACKET][mask] = np.round(points, 3)
    return frame


def _avia(rng: np.random.Generator) -> np.ndarray:
    frame = np.tile(np.array([-0.0, -0.0, 0.0]), (24000, 1))
    n = int(rng.integers(0, 179)) if rng.random() > 0.44 else 0
    frame[:n] = np.round(rng.normal(0, 30, (n, 3)), 3)
    return frame


def generate(root: Path, n_sequences: int, seconds: float, seed: int = 0) -> Path:
    """Write ``n_sequences`` train sequences of ``seconds`` each with realistic file sizes."""
    rng = np.random.default_rng(seed)
    for i in range(1, n_sequences + 1):
        seq = root / "train" / f"seq{i:04d}"
        for folder in ("lidar_360", "livox_avia", "radar_enhance_pcl", "ground_truth", "class"):
            (seq / folder).mkdir(parents=True)
        t0_us = 1_706_255_000_000_000 + i * 60_000_000
        stamp = lambda us: f"{us // 1_000_000}.{us % 1_000_000:06d}"  # noqa: E731
        for k in range(int(seconds * 10)):
            us = t0_us + k * 100_000
            np.save(seq / "lidar_360" / f"{stamp(us)}.npy", _mid360(rng, MID360_ROWS[k % 3]))
            np.save(seq / "livox_avia" / f"{stamp(us + 14_000)}.npy", _avia(rng))
        prev = np.empty((0,))
        for k in range(int(seconds * 15)):
            if rng.random() < 0.4:
                frame = np.empty((0,))
            elif rng.random() < 0.7 and prev.size:
                frame = prev
            else:
                frame = rng.normal(0, 5, (int(rng.integers(2, 21)), 3))
            prev = frame
            np.save(seq / "radar_enhance_pcl" / f"{stamp(t0_us + k * 66_667)}.npy", frame)
        for k in range(int(seconds * 20)):
            us = t0_us - 35_000 + k * 50_000
            np.save(seq / "ground_truth" / f"{stamp(us)}.npy", rng.normal(0, 10, 3))
            np.save(seq / "class" / f"{stamp(us)}.npy", np.array([1]))
    return root


def npy_files(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*.npy") if p.parts[-4] in ("train", "val", "test"))


def load_floor(files: list[Path]) -> float:
    """Seconds to np.load every file once."""
    started = time.perf_counter()
    for path in files:
        np.load(path)
    return time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--data", type=Path, help="an existing dataset root (default: generate one)"
    )
    parser.add_argument("--sequences", type=int, default=4, help="sequences to generate")
    parser.add_argument(
        "--seconds", type=float, default=8.0, help="length of each generated sequence"
    )
    parser.add_argument("--repeats", type=int, default=2, help="runs per setting (best is kept)")
    args = parser.parse_args()

    work = Path(tempfile.mkdtemp(prefix="bench_convert_"))
    try:
        if args.data is not None:
            root = args.data
        else:
            started = time.perf_counter()
            root = generate(work / "data", args.sequences, args.seconds)
            print(
                f"generated {args.sequences} x {args.seconds:g} s in {time.perf_counter() - started:.1f} s"
            )
        files = npy_files(root)
        mb = sum(p.stat().st_size for p in files) / 1e6
        frames = len(files)
        load_floor(files)  # warm the page cache
        floor = min(load_floor(files) for _ in range(args.repeats))
        floor_rate = mb / floor
        print(
            f"input: {frames} .npy files, {mb:.0f} MB (no images); CPUs: {os.cpu_count()}, "
            f"load average before: {os.getloadavg()[0]:.2f}"
        )
        with warnings.catch_warnings():  # start the worker server once, outside the timings
            warnings.simplefilter("ignore")
            convert_dataset(root, work / "warmup", workers=2, images=False)
        shutil.rmtree(work / "warmup")
        print(
            f"{'setting':<22}{'seconds':>9}{'MB/s':>9}{'frames/s':>10}{'vs floor':>10}{'out MB':>9}"
        )
        print(
            f"{'np.load floor':<22}{floor:>9.2f}{floor_rate:>9.0f}{frames / floor:>10.0f}{1:>10.2f}{'':>9}"
        )
        one_worker: dict[str, float] = {}
        for compression in ("zstd", "lz4", "none"):
            for workers in (1, 2):
                best = float("inf")
                out_mb = 0.0
                cpu = float("inf")
                for _ in range(args.repeats):
                    out = work / f"out-{compression}-{workers}"
                    shutil.rmtree(out, ignore_errors=True)
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        report = convert_dataset(
                            root, out, workers=workers, compression=compression, images=False
                        )
                    if not report.ok:
                        raise SystemExit(report.describe())
                    best = min(best, report.seconds)
                    cpu = min(cpu, report.cpu_seconds)
                    out_mb = report.bytes_out / 1e6
                    shutil.rmtree(out, ignore_errors=True)
                rate = mb / best
                scaling = ""
                if workers == 1:
                    one_worker[compression] = best
                else:
                    scaling = f"  x{one_worker[compression] / best:.2f} vs 1 worker"
                label = f"{compression}, {workers} worker{'s' if workers > 1 else ''}"
                print(
                    f"{label:<22}{best:>9.2f}{rate:>9.0f}{frames / best:>10.0f}"
                    f"{rate / floor_rate:>10.2f}{out_mb:>9.1f}{cpu:>8.2f}{scaling}"
                )
        print(f"load average after: {os.getloadavg()[0]:.2f} (other processes share the CPUs)")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
