"""Reading a challenge sequence for the notebooks: paired frames and the best truth known."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cldet.core.frames import pair_frames
from cldet.core.trajectory import evaluate_trajectory
from cldet.results import normalise_sequence, read_truth
from cldet.types import LidarFrame
from converters.mmaud import SequenceRef, iter_clouds, iter_ground_truth, iter_positions


def sequence_frames(
    seq: SequenceRef, max_gap_ns: int = 50_000_000
) -> Callable[[], Iterator[LidarFrame]]:
    """A re-iterable source of a challenge sequence's paired Mid-360/Avia frames.

    Each call of the returned function streams the sequence from disk again (the estimator
    reads a sequence twice), pairing every Mid-360 frame with its nearest Avia frame
    (:func:`cldet.core.frames.pair_frames`); a sequence without ``livox_avia`` gives frames with
    an empty Avia cloud.

    Args:
        seq: a sequence found by :func:`converters.mmaud.find_sequences`; needs ``lidar_360``.
        max_gap_ns: largest |Avia - Mid-360| stamp difference paired, ns.

    Returns:
        A function returning a fresh iterator of :class:`LidarFrame` in stamp order.
    """

    def frames() -> Iterator[LidarFrame]:
        avia = iter_clouds(seq, "livox_avia") if "livox_avia" in seq.modalities else iter(())
        return pair_frames(iter_clouds(seq, "lidar_360"), avia, max_gap_ns)

    return frames


@dataclass(frozen=True)
class Truth:
    """The drone's positions over a sequence, and what they are."""

    kind: str  # "ground truth" or "reference estimate" (another method's output, not truth)
    stamps_ns: NDArray[np.int64]  # (K,) ascending
    positions: NDArray[np.float64]  # (K, 3) metres, Mid-360 frame


def load_truth(seq: SequenceRef, root: Path | None = None) -> Truth | None:
    """The best positions known for a sequence: ground truth, else a reference estimate.

    Looked up in this order: the sequence's ``ground_truth/`` folder (train); the split's
    truth CSV ``ROOT/<split>_truth.csv`` (written by ``cldet simulate`` for val and test); a
    reference track ``ROOT/reference/<seq>/`` (the real sample ships the 1st-place team's
    estimate there: kind ``"reference estimate"``).

    Args:
        seq: the sequence.
        root: the dataset root (default: two levels above the sequence folder).

    Returns:
        A :class:`Truth`, or None when nothing is found (or the CSV has no row of the sequence).

    Raises:
        DatasetError, ResultsError: a truth file exists but is malformed.
    """
    root = Path(root) if root is not None else seq.path.parent.parent
    if "ground_truth" in seq.modalities:
        samples = list(iter_ground_truth(seq))
        if samples:
            return _truth(
                "ground truth", [s.stamp_ns for s in samples], [s.position for s in samples]
            )
    csv = root / f"{seq.split}_truth.csv"
    if csv.is_file():
        rows = [r for r in read_truth(csv).rows if normalise_sequence(r.sequence) == seq.name]
        if rows:
            return _truth("ground truth", [r.stamp_ns for r in rows], [r.position for r in rows])
    for name in (seq.name, seq.path.name):
        folder = root / "reference" / name
        if folder.is_dir():
            samples = list(iter_positions(folder))
            if samples:
                return _truth(
                    "reference estimate",
                    [s.stamp_ns for s in samples],
                    [s.position for s in samples],
                )
    return None


def _truth(kind: str, stamps: Sequence[int], positions: Sequence[ArrayLike]) -> Truth:
    s = np.asarray(stamps, dtype=np.int64)
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    order = np.argsort(s, kind="stable")
    return Truth(kind=kind, stamps_ns=s[order], positions=p[order])


def truth_at(truth: Truth, stamps_ns: ArrayLike) -> NDArray[np.float64]:
    """The truth's positions at the given stamps (linear inside, its own motion outside).

    Args:
        truth: the positions to evaluate.
        stamps_ns: (N,) integer ns.

    Returns:
        (N, 3) metres (:func:`cldet.core.trajectory.evaluate_trajectory`).
    """
    query = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    return evaluate_trajectory(truth.stamps_ns, truth.positions, query)
