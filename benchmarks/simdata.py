"""Simulated data for the benchmarks: seed ranges and labelled MCAP logs, made once and reused."""

from __future__ import annotations

import shutil
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from cldet.simulate.dataset import simulate_sequence
from converters.mcap_convert import convert_dataset


def parse_seeds(text: str) -> list[int]:
    """``"100-103"`` -> [100, 101, 102, 103]; ``"7"`` -> [7]; ``"1-3,9"`` -> [1, 2, 3, 9]."""
    seeds: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.strip().partition("-")
        seeds.extend(range(int(lo), int(hi or lo) + 1))
    return seeds


def _simulate(job: tuple[Path, int, float]) -> int:
    seq_dir, seed, duration = job
    if not (seq_dir / "ground_truth").exists():  # a sequence finished by an earlier run is kept
        shutil.rmtree(seq_dir, ignore_errors=True)
        simulate_sequence(seq_dir, seed=seed, duration_s=duration, images=False)
    return seed


def simulated_logs(root: Path, seeds: list[int], duration: float, workers: int) -> list[Path]:
    """Simulate ``seeds`` (``mixed`` scenario, labelled) under ``root/train/seq<seed>`` and
    convert them to ``root/logs/train/seq<seed>.mcap``; the logs' paths.

    What an earlier run left complete under ``root`` is reused.
    """
    jobs = [(root / "train" / f"seq{seed}", seed, duration) for seed in seeds]
    with ProcessPoolExecutor(workers) as pool:
        list(pool.map(_simulate, jobs))
    convert_dataset(root, root / "logs", splits=["train"], workers=workers, images=False)
    return [root / "logs" / "train" / f"seq{seed}.mcap" for seed in seeds]
