"""Simulated data for the benchmarks: seed ranges and labelled MCAP logs, made once and reused."""

from __future__ import annotations

import shutil
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from cldet.simulate.dataset import simulate_sequence
from cldet.simulate.randomized import write_world_sequence
from converters.mcap_convert import convert_dataset


def parse_seeds(text: str) -> list[int]:
    """``"100-103"`` -> [100, 101, 102, 103]; ``"7"`` -> [7]; ``"1-3,9"`` -> [1, 2, 3, 9];
    ``"none"`` -> []."""
    seeds: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if part in ("", "none"):
            continue
        lo, _, hi = part.partition("-")
        seeds.extend(range(int(lo), int(hi or lo) + 1))
    return seeds


def _simulate(job: tuple[Path, int, float, bool]) -> int:
    seq_dir, seed, duration, randomize = job
    if not seq_dir.exists():  # simulated aside and renamed: an interrupted run leaves no half
        partial = seq_dir.parent / f".{seq_dir.name}.partial"
        shutil.rmtree(partial, ignore_errors=True)
        if randomize:
            write_world_sequence(partial, seed, duration, labels=True, images=False)
        else:
            simulate_sequence(partial, seed=seed, duration_s=duration, images=False)
        partial.rename(seq_dir)
    return seed


@dataclass(frozen=True)
class SimData:
    """A simulated dataset in the challenge layout and its MCAP logs."""

    dataset: Path  # holds train/seq<seed>/ (.npy folders)
    logs: list[Path]  # <root>/logs/train/seq<seed>.mcap, in the order of the seeds


def simulated_logs(
    root: Path, seeds: list[int], duration: float, workers: int, randomize: bool = False
) -> SimData:
    """Simulate ``seeds`` (labelled; the ``mixed`` scenario, or randomised worlds) under
    ``root/data/train/seq<seed>`` (at least 4 digits, as convert names it) and convert them to
    ``root/logs/train/seq<seed>.mcap``.

    What an earlier run left complete under ``root`` is reused.
    """
    dataset = root / "data"
    if not seeds:
        return SimData(dataset, [])
    jobs = [(dataset / "train" / f"seq{seed:04d}", seed, duration, randomize) for seed in seeds]
    with ProcessPoolExecutor(workers) as pool:
        list(pool.map(_simulate, jobs))
    convert_dataset(dataset, root / "logs", splits=["train"], workers=workers, images=False)
    return SimData(dataset, [root / "logs" / "train" / f"seq{seed:04d}.mcap" for seed in seeds])
