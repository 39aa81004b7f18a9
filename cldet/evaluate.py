"""Score a submission against ground truth: position errors, class accuracy, per sequence.

The challenge's "MSE" has no public scorer, so both readings are reported, each labelled:

- ``mse_per_coordinate_m2``: sum of squared coordinate errors / (3 N), the mean over x, y, z;
- ``mean_squared_distance_m2``: sum of squared 3D distances / N (= 3 x the first).

Plus the RMSE of the 3D distance, its median and 95th percentile, and the per-row class accuracy.
Rows are matched by (normalised sequence, stamp in ns) (see :func:`cldet.results.row_key`).
Truth rows without a result are *missing*, result rows repeating an earlier key are *duplicates*
(the first one is scored), result rows without truth are *unmatched*; the metrics cover the
matched rows only and the counts are reported alongside.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cldet.errors import LogError, ResultsError
from cldet.progress import NullProgress, Progress
from cldet.results import (
    ResultRow,
    RowKey,
    TruthRow,
    TruthTable,
    read_log_truth,
    read_results,
    write_atomic,
)
from cldet.stamps import format_stamp

EXAMPLE_KEYS = 5
"""How many example keys of missing / duplicate / unmatched rows an evaluation keeps."""


@dataclass(frozen=True)
class RowErrors:
    """Per-row errors of the matched rows, in truth order (columns of equal length N)."""

    sequence: tuple[str, ...]  # (N,) the truth's sequence names, normalised
    timestamp: tuple[str, ...]  # (N,) the result file's Timestamp strings
    stamp_ns: NDArray[np.int64]  # (N,)
    estimate: NDArray[np.float64]  # (N, 3) metres
    truth: NDArray[np.float64]  # (N, 3) metres
    error_m: NDArray[np.float64]  # (N,) 3D distance, metres
    class_pred: NDArray[np.int64]  # (N,)
    class_true: NDArray[np.int64]  # (N,) -1 where the truth has no class


@dataclass(frozen=True)
class SequenceScore:
    """Scores of one sequence (matched rows only)."""

    sequence: str  # normalised name
    n_truth: int
    n_matched: int
    n_missing: int
    mse_per_coordinate_m2: float  # NaN when nothing matched
    mean_squared_distance_m2: float  # NaN when nothing matched
    rmse_m: float  # NaN when nothing matched
    max_error_m: float  # NaN when nothing matched
    accuracy: float | None  # None when no matched row has a true class


@dataclass(frozen=True)
class Evaluation:
    """The score of one results file against one ground truth."""

    results_path: str
    truth_source: str
    n_truth: int  # truth rows
    n_results: int  # result rows, duplicates included
    n_matched: int  # truth rows with a result
    n_missing: int  # truth rows without a result
    n_duplicate: int  # result rows repeating an earlier (sequence, stamp); not scored
    n_unmatched: int  # distinct result keys with no truth row; not scored
    mse_per_coordinate_m2: float  # sum of squared coordinate errors / (3 N)
    mean_squared_distance_m2: float  # sum of squared 3D distances / N
    rmse_m: float  # sqrt(mean_squared_distance_m2)
    median_error_m: float  # median 3D distance
    p95_error_m: float  # 95th percentile of the 3D distance (linear interpolation)
    max_error_m: float
    accuracy: float | None  # Classification == true class over matched rows with a true class
    n_classified: int  # matched rows with a true class (the accuracy's denominator)
    sequences: tuple[SequenceScore, ...]  # sorted by name
    rows: RowErrors
    missing_examples: tuple[RowKey, ...]  # up to EXAMPLE_KEYS (sequence, stamp ns)
    duplicate_examples: tuple[RowKey, ...]
    unmatched_examples: tuple[RowKey, ...]

    def confusion(self) -> str | None:
        """The confusion matrix of the rows with a true class, as text (None: no such row)."""
        known = self.rows.class_true >= 0
        if not known.any():
            return None
        true, pred = self.rows.class_true[known], self.rows.class_pred[known]
        ids = sorted(set(true.tolist()) | set(pred.tolist()))
        return confusion_text(true.tolist(), pred.tolist(), ids)

    @property
    def warnings(self) -> tuple[str, ...]:
        """Human-readable warnings about missing, duplicate and unmatched rows (empty if none)."""
        out = []
        for count, what, examples in (
            (self.n_missing, "truth rows have no result (missing)", self.missing_examples),
            (
                self.n_duplicate,
                "result rows repeat an earlier row (duplicate, not scored)",
                self.duplicate_examples,
            ),
            (
                self.n_unmatched,
                "result rows match no truth row (unmatched, not scored)",
                self.unmatched_examples,
            ),
        ):
            if count:
                shown = ", ".join(f"{seq}@{format_stamp(ns)}" for seq, ns in examples)
                more = ", ..." if count > len(examples) else ""
                out.append(f"{count} {what}: {shown}{more}")
        return tuple(out)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready summary (no per-row data; NaN becomes None)."""
        return {
            "results": self.results_path,
            "truth": self.truth_source,
            "counts": {
                "truth": self.n_truth,
                "results": self.n_results,
                "matched": self.n_matched,
                "missing": self.n_missing,
                "duplicate": self.n_duplicate,
                "unmatched": self.n_unmatched,
                "classified": self.n_classified,
            },
            "mse_per_coordinate_m2": _num(self.mse_per_coordinate_m2),
            "mean_squared_distance_m2": _num(self.mean_squared_distance_m2),
            "rmse_m": _num(self.rmse_m),
            "median_error_m": _num(self.median_error_m),
            "p95_error_m": _num(self.p95_error_m),
            "max_error_m": _num(self.max_error_m),
            "accuracy": self.accuracy,
            "sequences": [
                {
                    "sequence": s.sequence,
                    "truth": s.n_truth,
                    "matched": s.n_matched,
                    "missing": s.n_missing,
                    "mse_per_coordinate_m2": _num(s.mse_per_coordinate_m2),
                    "mean_squared_distance_m2": _num(s.mean_squared_distance_m2),
                    "rmse_m": _num(s.rmse_m),
                    "max_error_m": _num(s.max_error_m),
                    "accuracy": s.accuracy,
                }
                for s in self.sequences
            ],
            "warnings": list(self.warnings),
        }


def _num(value: float) -> float | None:
    return None if np.isnan(value) else float(value)


def evaluate_results(results_path: Path | str, truth: TruthTable) -> Evaluation:
    """Score a results CSV against a ground truth.

    Args:
        results_path: the submission (``mmaud_results.csv``); duplicates are counted, not fatal.
        truth: the ground truth (:func:`cldet.results.read_truth` or :func:`truth_from_logs`).

    Returns:
        The :class:`Evaluation` over the matched rows, with the counts of the others.

    Raises:
        ResultsError: the results file is malformed, or no result row matches any truth row.
    """
    results = read_results(results_path, allow_duplicates=True)
    return score(results, truth, results_path=str(results_path))


def score(results: Iterable[ResultRow], truth: TruthTable, *, results_path: str = "") -> Evaluation:
    """Score result rows against a ground truth (see :func:`evaluate_results`).

    Raises:
        ResultsError: no result row matches any truth row, or the truth holds a key twice.
    """
    by_key: dict[RowKey, ResultRow] = {}
    n_results = 0
    duplicates: list[RowKey] = []
    for row in results:
        n_results += 1
        if row.key in by_key:
            duplicates.append(row.key)
        else:
            by_key[row.key] = row

    truth_keys: set[RowKey] = set()
    matched: list[tuple[TruthRow, ResultRow]] = []
    missing: list[RowKey] = []
    per_seq_truth: dict[str, int] = {}
    for t in truth.rows:
        if t.key in truth_keys:
            raise ResultsError(f"{truth.source}: the truth holds {t.key[0]}@{t.timestamp} twice")
        truth_keys.add(t.key)
        per_seq_truth[t.key[0]] = per_seq_truth.get(t.key[0], 0) + 1
        r = by_key.get(t.key)
        if r is None:
            missing.append(t.key)
        else:
            matched.append((t, r))
    unmatched = [k for k in by_key if k not in truth_keys]

    if not matched:
        raise ResultsError(
            f"{results_path}: none of its {n_results} rows matches the {len(truth.rows)} truth "
            f"rows of {truth.source}: expected the same sequences and timestamps "
            "(check the split and the sequence names)"
        )

    estimate = np.array([r.position for _, r in matched], dtype=np.float64).reshape(-1, 3)
    true_pos = np.array([t.position for t, _ in matched], dtype=np.float64).reshape(-1, 3)
    diff = estimate - true_pos
    sq = np.sum(diff * diff, axis=1)  # (N,) squared 3D distance, m^2
    error_m = np.sqrt(sq)
    rows = RowErrors(
        sequence=tuple(t.key[0] for t, _ in matched),
        timestamp=tuple(r.timestamp for _, r in matched),
        stamp_ns=np.array([t.stamp_ns for t, _ in matched], dtype=np.int64),
        estimate=estimate,
        truth=true_pos,
        error_m=error_m,
        class_pred=np.array([r.class_id for _, r in matched], dtype=np.int64),
        class_true=np.array(
            [-1 if t.class_id is None else t.class_id for t, _ in matched], dtype=np.int64
        ),
    )

    seq_names = np.array(rows.sequence, dtype=object)
    scores = []
    for seq in sorted(per_seq_truth):
        mask = seq_names == seq
        n = int(mask.sum())
        scores.append(
            SequenceScore(
                sequence=seq,
                n_truth=per_seq_truth[seq],
                n_matched=n,
                n_missing=per_seq_truth[seq] - n,
                mse_per_coordinate_m2=float(sq[mask].mean() / 3) if n else float("nan"),
                mean_squared_distance_m2=float(sq[mask].mean()) if n else float("nan"),
                rmse_m=float(np.sqrt(sq[mask].mean())) if n else float("nan"),
                max_error_m=float(error_m[mask].max()) if n else float("nan"),
                accuracy=_accuracy(rows.class_pred[mask], rows.class_true[mask])[0],
            )
        )

    accuracy, n_classified = _accuracy(rows.class_pred, rows.class_true)
    mean_sq = float(sq.mean())
    return Evaluation(
        results_path=results_path,
        truth_source=truth.source,
        n_truth=len(truth.rows),
        n_results=n_results,
        n_matched=len(matched),
        n_missing=len(missing),
        n_duplicate=len(duplicates),
        n_unmatched=len(unmatched),
        mse_per_coordinate_m2=mean_sq / 3,
        mean_squared_distance_m2=mean_sq,
        rmse_m=float(np.sqrt(mean_sq)),
        median_error_m=float(np.median(error_m)),
        p95_error_m=float(np.percentile(error_m, 95)),
        max_error_m=float(error_m.max()),
        accuracy=accuracy,
        n_classified=n_classified,
        sequences=tuple(scores),
        rows=rows,
        missing_examples=tuple(missing[:EXAMPLE_KEYS]),
        duplicate_examples=tuple(duplicates[:EXAMPLE_KEYS]),
        unmatched_examples=tuple(unmatched[:EXAMPLE_KEYS]),
    )


def confusion_text(
    true: Sequence[int],
    predicted: Sequence[int],
    class_ids: Sequence[int],
    weights: Sequence[float] | None = None,
) -> str:
    """A confusion matrix as text: one row per true class, one column per predicted class,
    counting rows (or summing ``weights``)."""
    from sklearn.metrics import confusion_matrix

    cm = confusion_matrix(true, predicted, labels=list(class_ids), sample_weight=weights)
    width = max(7, *(len(str(int(v))) + 1 for v in cm.ravel()))
    head = "true \\ predicted".ljust(17) + "".join(str(c).rjust(width) for c in class_ids)
    body = [
        str(c).ljust(17) + "".join(str(int(v)).rjust(width) for v in row)
        for c, row in zip(class_ids, cm, strict=True)
    ]
    return "\n".join([head, *body])


def _accuracy(pred: NDArray[np.int64], true: NDArray[np.int64]) -> tuple[float | None, int]:
    """(fraction of rows with pred == true among rows with a true class, or None; that count)."""
    known = true >= 0
    n = int(known.sum())
    if n == 0:
        return None, 0
    return float(np.mean(pred[known] == true[known])), n


def write_errors_parquet(
    evaluation: Evaluation, path: Path | str, *, overwrite: bool = True
) -> None:
    """Write the per-row errors of an evaluation as a Parquet table, atomically.

    Columns: ``sequence``, ``timestamp`` (the result's string), ``timestamp_ns`` (int64),
    ``est_x/est_y/est_z`` and ``true_x/true_y/true_z`` (metres), ``error_m`` (3D distance),
    ``class_pred`` (int64) and ``class_true`` (int64, null when the truth has no class).

    Raises:
        OutputExistsError: ``path`` exists and ``overwrite`` is false.
        ResultsError: the file cannot be written.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows = evaluation.rows
    table = pa.table(
        {
            "sequence": pa.array(rows.sequence, pa.string()),
            "timestamp": pa.array(rows.timestamp, pa.string()),
            "timestamp_ns": pa.array(rows.stamp_ns, pa.int64()),
            "est_x": rows.estimate[:, 0],
            "est_y": rows.estimate[:, 1],
            "est_z": rows.estimate[:, 2],
            "true_x": rows.truth[:, 0],
            "true_y": rows.truth[:, 1],
            "true_z": rows.truth[:, 2],
            "error_m": rows.error_m,
            "class_pred": pa.array(rows.class_pred, pa.int64()),
            "class_true": pa.array(rows.class_true, pa.int64(), mask=rows.class_true < 0),
        }
    )

    def write(tmp: Path) -> None:
        try:
            pq.write_table(table, tmp)
        except pa.ArrowException as err:
            raise ResultsError(f"{path}: cannot write Parquet: {err}") from err

    write_atomic(path, write, overwrite=overwrite)


def truth_from_logs(logs: Iterable[Path | str], progress: Progress | None = None) -> TruthTable:
    """Ground truth from annotated (or converted) MCAP logs with a ``/ground_truth`` channel.

    The sequence name comes from each log's ``cldet.source`` metadata; the class, when the log
    has a ``/class`` channel, is the label at or before each ground-truth stamp (the first label
    for earlier stamps). ``progress`` (optional) is told about each log read.

    Raises:
        LogError: a log cannot be read, has no sequence name or no ground truth.
        ResultsError: two logs hold the same sequence and stamp.
    """
    rows: list[TruthRow] = []
    seen: dict[RowKey, str] = {}
    paths = [Path(p) for p in logs]
    if not paths:
        raise LogError("no logs given: expected annotated MCAP logs with a /ground_truth channel")
    bar: Progress = progress if progress is not None else NullProgress()
    bar.start(len(paths), "reading ground truth")
    for path in paths:
        log_rows = read_log_truth(path)
        bar.advance()
        for row in log_rows:
            if row.key in seen:
                raise ResultsError(
                    f"{path}: sequence {row.key[0]} at {row.timestamp} is also in {seen[row.key]}: "
                    "pass each sequence's log once (one split at a time)"
                )
            seen[row.key] = str(path)
            rows.append(row)
    source = str(paths[0]) if len(paths) == 1 else f"{len(paths)} logs ({paths[0]}, ...)"
    return TruthTable(source=source, rows=tuple(rows))
