"""Export a challenge submission (``mmaud_results.csv``) from annotated MCAP logs.

Each log names its sequence in its ``cldet.source`` metadata and carries the estimator's
trajectory on ``/cldet/estimate`` (``cldet.Estimate``). For every query row the sequence's
trajectory is evaluated at the row's stamp by
:func:`cldet.core.trajectory.evaluate_trajectory`: linear interpolation between estimates, the
track's own constant-velocity motion before the first and after the last one, for at most
:data:`DEFAULT_MAX_EXTRAPOLATION_NS` (then held), unless told otherwise.

Rules, all reported in the returned :class:`ExportReport`:

- Estimates whose source is ``FALLBACK`` (a fallback rule, not the track) are ignored when the
  log also has estimates from the track; the track's motion then bridges those stretches.
- A query sequence with no log, or whose log was never annotated (or has no usable estimate),
  is an error; with ``allow_fallback`` (``--allow-fallback``) it gets the global constant
  :data:`FALLBACK_POSITION_M` (the training-set mean position) on every row, and a warning.
- ``Classification`` is the log's final ``/cldet/class`` estimate (written by
  ``cldet annotate --model``), else the constant :data:`DEFAULT_CLASS_ID`; a class id given
  explicitly is written on every row instead.
- Without a query file, the rows are each log's ``/ground_truth`` stamps (to score a split that
  has ground truth); logs without ground truth are skipped with a warning.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np
from numpy.typing import NDArray

from cldet.config import TRAINING_MEAN_POSITION_M
from cldet.core.trajectory import evaluate_trajectory
from cldet.errors import LogError, OutputExistsError, ResultsError
from cldet.io import topics
from cldet.io.mcap_read import open_log
from cldet.progress import NullProgress, Progress
from cldet.results import (
    QueryRow,
    ResultRow,
    normalise_sequence,
    read_log_truth,
    read_timestamps,
    write_results,
)
from cldet.types import Source

FALLBACK_POSITION_M: Final[tuple[float, float, float]] = TRAINING_MEAN_POSITION_M
"""Position (metres, Mid-360 frame) for a sequence without any estimate: the training-set mean
(the estimator's default ``tracking.fallback_position`` too)."""
DEFAULT_CLASS_ID: Final = 0
"""Classification written for a log without a ``/cldet/class`` estimate (no model used)."""
DEFAULT_MAX_EXTRAPOLATION_NS: Final = 1_000_000_000
"""How far beyond its first or last estimate a track's motion is followed by default (1 s); a
query further out gets the position reached there. A drone at 10 m/s is 10 m away after 1 s:
following a straight line for longer is a guess, not an estimate."""


@dataclass(frozen=True)
class LogTrack:
    """The estimated trajectory of one annotated log."""

    path: Path
    sequence: str  # as in the log's cldet.source metadata
    split: str  # "" when the metadata does not say
    stamps_ns: NDArray[np.int64]  # (K,) ascending; K = 0 when the log has no usable estimate
    positions: NDArray[np.float64]  # (K, 3) metres, Mid-360 frame
    n_fallback_dropped: int  # FALLBACK estimates ignored because the track has its own
    annotated: bool = True  # the log has a /cldet/estimate channel (was annotated)
    class_id: int | None = None  # the final /cldet/class estimate (None: no model was used)


@dataclass(frozen=True)
class ExportReport:
    """What :func:`export_results` wrote, and every row it had to fill without a track."""

    out: Path
    n_rows: int
    n_sequences: int
    n_interpolated: int  # rows inside their sequence's estimate span
    n_extrapolated: int  # rows before the first or after the last estimate (track's motion)
    n_fallback_rows: int  # rows given FALLBACK_POSITION_M
    fallback_sequences: tuple[str, ...]  # sequences (as in the rows) with no estimate at all
    unused_logs: tuple[str, ...]  # logs whose sequence has no row
    warnings: tuple[str, ...]

    def describe(self) -> str:
        """A short human-readable summary."""
        return (
            f"wrote {self.out}: {self.n_rows} rows in {self.n_sequences} sequences "
            f"({self.n_interpolated} interpolated, {self.n_extrapolated} extrapolated by the "
            f"track's motion, {self.n_fallback_rows} at the global fallback position)"
        )


def read_log_track(path: Path | str) -> LogTrack:
    """Read a log's sequence name and estimated trajectory (``/cldet/estimate``).

    The trajectory is sorted by stamp; non-finite estimates are dropped, and so are ``FALLBACK``
    estimates when the log has other ones. A log without the channel gives an empty track.

    Raises:
        LogError: the log cannot be read, or has no sequence name in its metadata.
    """
    with open_log(path) as log:
        sequence, split = log.source()
        stamps: list[int] = []
        positions: list[NDArray[np.float64]] = []
        fallback: list[bool] = []
        annotated = topics.ESTIMATE in log.list_topics()
        class_id = None
        if log.list_topics().get(topics.CLASS_ESTIMATE, 0) > 0:
            for estimate_class in log.iter_class_estimates(topics.CLASS_ESTIMATE):
                class_id = estimate_class.class_id  # the last one holds all the evidence
        if log.list_topics().get(topics.ESTIMATE, 0) > 0:
            for estimate, _track_id in log.iter_estimates(topics.ESTIMATE):
                if np.all(np.isfinite(estimate.position)):
                    stamps.append(estimate.stamp_ns)
                    positions.append(estimate.position)
                    fallback.append(estimate.source == Source.FALLBACK)
    stamps_ns = np.array(stamps, dtype=np.int64)
    pos = np.array(positions, dtype=np.float64).reshape(-1, 3)
    is_fallback = np.array(fallback, dtype=bool)
    n_dropped = 0
    if is_fallback.any() and not is_fallback.all():
        n_dropped = int(is_fallback.sum())
        stamps_ns, pos = stamps_ns[~is_fallback], pos[~is_fallback]
    order = np.argsort(stamps_ns, kind="stable")
    return LogTrack(
        Path(path), sequence, split, stamps_ns[order], pos[order], n_dropped, annotated, class_id
    )


def export_results(
    logs: Iterable[Path | str],
    out: Path | str,
    timestamps: Path | str | None = None,
    class_id: int | None = None,
    *,
    overwrite: bool = False,
    max_extrapolation_ns: int | None = DEFAULT_MAX_EXTRAPOLATION_NS,
    allow_fallback: bool = False,
    progress: Progress | None = None,
) -> ExportReport:
    """Write a submission CSV from annotated logs, one row per query row, atomically.

    Args:
        logs: annotated MCAP logs, at most one per sequence.
        out: the results CSV to write (``mmaud_results.csv``).
        timestamps: the query file (``test_timestamps.csv``); rows are written in its order with
            its Sequence and Timestamp strings. ``None``: a row at every ``/ground_truth`` stamp
            of every log, in log order.
        class_id: the Classification of every row; ``None``: each log's final ``/cldet/class``
            estimate, else :data:`DEFAULT_CLASS_ID`.
        overwrite: replace an existing ``out``.
        max_extrapolation_ns: follow the track's motion at most this far beyond its first or
            last estimate, then hold (see :func:`~cldet.core.trajectory.evaluate_trajectory`);
            default :data:`DEFAULT_MAX_EXTRAPOLATION_NS`, ``None``: no limit.
        allow_fallback: write :data:`FALLBACK_POSITION_M` for a sequence without a log or
            without estimates (with a warning) instead of raising.
        progress: told about each log read (``None``: silent).

    Returns:
        The :class:`ExportReport`, with the sequences that got the fallback constant.

    Raises:
        LogError: a log cannot be read or has no sequence name.
        ResultsError: a malformed query file, two logs of the same sequence, no row at all, or
            (without ``allow_fallback``) a query sequence without a log or without estimates.
        OutputExistsError: ``out`` exists and ``overwrite`` is false.
    """
    out_path = Path(out)
    if out_path.exists() and not overwrite:  # fail before reading every log
        raise OutputExistsError(
            f"{out_path} already exists: pass overwrite (--overwrite) to replace it"
        )
    queries: Sequence[QueryRow] | None = None
    if timestamps is not None:
        try:
            queries = read_timestamps(timestamps)
        except ResultsError as err:
            raise ResultsError(f"the query file (--timestamps) is not usable: {err}") from err
    tracks: dict[str, LogTrack] = {}
    warnings: list[str] = []
    paths = [Path(p) for p in logs]
    bar: Progress = progress if progress is not None else NullProgress()
    bar.start(len(paths), "reading estimates")
    for path in paths:
        log_track = read_log_track(path)
        bar.advance()
        key = normalise_sequence(log_track.sequence)
        if key in tracks:
            raise ResultsError(
                f"two logs hold sequence {key}: {tracks[key].path} and {log_track.path}: "
                "pass one split's logs at a time"
            )
        tracks[key] = log_track
        if log_track.n_fallback_dropped:
            warnings.append(
                f"{log_track.path}: ignored {log_track.n_fallback_dropped} FALLBACK estimates; "
                "the track's own motion bridges them"
            )

    if queries is None:
        queries = _truth_queries(tracks.values(), warnings)
    if not queries:
        where = (
            f"the query file {timestamps} (--timestamps) has no row"
            if timestamps is not None
            else "no query file (--timestamps) was given and no log has ground truth to use instead"
        )
        raise ResultsError(f"nothing to export: {where}")

    by_sequence: dict[str, list[int]] = {}
    for i, query in enumerate(queries):
        by_sequence.setdefault(query.key[0], []).append(i)

    positions = np.empty((len(queries), 3), dtype=np.float64)
    n_inside = n_outside = n_fallback = 0
    fallback_sequences: list[str] = []
    missing = [
        (queries[indices[0]].sequence, len(indices), tracks.get(key))
        for key, indices in by_sequence.items()
        if tracks.get(key) is None or tracks[key].stamps_ns.size == 0
    ]
    if missing and not allow_fallback:
        shown = "; ".join(_why_no_estimate(name, n, track) for name, n, track in missing[:5])
        more = f"; and {len(missing) - 5} more" if len(missing) > 5 else ""
        raise ResultsError(
            f"no estimate for {len(missing)} query sequence(s): {shown}{more}; annotate their "
            "logs (`cldet annotate`), or pass allow_fallback (--allow-fallback) to write the "
            f"training-set mean position {list(FALLBACK_POSITION_M)} for them"
        )
    for key, indices in by_sequence.items():
        query_ns = np.array([queries[i].stamp_ns for i in indices], dtype=np.int64)
        track = tracks.get(key)
        if track is None or track.stamps_ns.size == 0:
            positions[indices] = FALLBACK_POSITION_M
            n_fallback += len(indices)
            name = queries[indices[0]].sequence
            fallback_sequences.append(name)
            why = "no log" if track is None else f"no estimate in {track.path}"
            warnings.append(
                f"sequence {name}: {why}; its {len(indices)} rows get the global fallback "
                f"position {list(FALLBACK_POSITION_M)}"
            )
            continue
        positions[indices] = evaluate_trajectory(
            track.stamps_ns, track.positions, query_ns, max_extrapolation_ns=max_extrapolation_ns
        )
        outside = (query_ns < track.stamps_ns[0]) | (query_ns > track.stamps_ns[-1])
        n_outside += int(outside.sum())
        n_inside += int((~outside).sum())

    if n_fallback == len(queries):
        warnings.append(
            f"no row has an estimate: every row is at the global fallback position; "
            f"were the logs annotated (`cldet annotate`, channel {topics.ESTIMATE})?"
        )
    unused = tuple(str(t.path) for k, t in tracks.items() if k not in by_sequence)
    if unused:
        warnings.append(f"{len(unused)} logs have no query row: {', '.join(unused)}")

    def row_class(sequence_key: str) -> int:
        if class_id is not None:
            return int(class_id)
        track = tracks.get(sequence_key)
        return DEFAULT_CLASS_ID if track is None or track.class_id is None else track.class_id

    rows = [
        ResultRow(q.sequence, q.timestamp, q.stamp_ns, (p[0], p[1], p[2]), row_class(q.key[0]))
        for q, p in zip(queries, positions.tolist(), strict=True)
    ]
    write_results(out_path, rows, overwrite=overwrite)
    return ExportReport(
        out=out_path,
        n_rows=len(rows),
        n_sequences=len(by_sequence),
        n_interpolated=n_inside,
        n_extrapolated=n_outside,
        n_fallback_rows=n_fallback,
        fallback_sequences=tuple(fallback_sequences),
        unused_logs=unused,
        warnings=tuple(warnings),
    )


def _why_no_estimate(name: str, n_rows: int, track: LogTrack | None) -> str:
    if track is None:
        return f"{name} ({n_rows} rows) has no log among those given"
    if not track.annotated:
        return f"{name} ({n_rows} rows): {track.path} was never annotated (no {topics.ESTIMATE})"
    return f"{name} ({n_rows} rows): {track.path} has no usable estimate"


def _truth_queries(tracks: Iterable[LogTrack], warnings: list[str]) -> Sequence[QueryRow]:
    """Query rows at every ``/ground_truth`` stamp of the logs (logs without it: a warning)."""
    queries: list[QueryRow] = []
    for track in tracks:
        try:
            truth = read_log_truth(track.path)
        except LogError as err:
            warnings.append(f"skipped: {err}")
            continue
        queries.extend(QueryRow(track.sequence, t.timestamp, t.stamp_ns) for t in truth)
    return queries
