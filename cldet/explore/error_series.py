"""A method's per-frame error against the truth, by estimate source and over time."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cldet.core.trajectory import rms, trajectory_errors
from cldet.explore.data import Truth
from cldet.stamps import NS_PER_S
from cldet.types import Estimate, Source


@dataclass(frozen=True)
class ErrorSeries:
    """Per-frame error of a method's estimates against the truth."""

    method: str
    stamps_ns: NDArray[np.int64]  # (N,) estimate stamps
    t_s: NDArray[np.float64]  # (N,) seconds since the first estimate
    error_m: NDArray[np.float64]  # (N,) 3D distance to the truth at the estimate's stamp
    source: NDArray[np.int64]  # (N,) cldet.types.Source values

    @property
    def rms_m(self) -> float:
        """RMS 3D error, metres (NaN when empty)."""
        return rms(self.error_m)


def estimate_errors(method: str, estimates: Sequence[Estimate], truth: Truth) -> ErrorSeries:
    """Error of every estimate: distance to the truth interpolated at its stamp.

    Args:
        method: a label (e.g. the configuration's ``method``).
        estimates: one sequence's estimates in stamp order.
        truth: the sequence's truth.

    Returns:
        An :class:`ErrorSeries`.
    """
    stamps = np.array([e.stamp_ns for e in estimates], dtype=np.int64)
    pos = np.array([e.position for e in estimates], dtype=np.float64).reshape(-1, 3)
    err = trajectory_errors(stamps, pos, truth.stamps_ns, truth.positions)
    t0 = stamps[0] if len(stamps) else 0
    return ErrorSeries(
        method=method,
        stamps_ns=stamps,
        t_s=(stamps - t0).astype(np.float64) / NS_PER_S,
        error_m=err,
        source=np.array([int(e.source) for e in estimates], dtype=np.int64),
    )


def error_by_source(series: ErrorSeries) -> dict[str, tuple[int, float]]:
    """Frames and RMS error (metres) per estimate source, for the sources present.

    Returns:
        ``{source name in lower case: (frames, RMS error m)}`` in :class:`Source` order.
    """
    out: dict[str, tuple[int, float]] = {}
    for source in Source:
        sel = series.source == int(source)
        if sel.any():
            out[source.name.lower()] = (int(sel.sum()), rms(series.error_m[sel]))
    return out


def source_runs(sources: ArrayLike) -> list[tuple[int, int, int]]:
    """Runs of equal values: ``(start, stop, value)`` with ``stop`` exclusive, in order."""
    s = np.asarray(sources).reshape(-1)
    if len(s) == 0:
        return []
    cuts = np.flatnonzero(s[1:] != s[:-1]) + 1
    starts = np.concatenate([[0], cuts])
    stops = np.concatenate([cuts, [len(s)]])
    return [(int(a), int(b), int(s[a])) for a, b in zip(starts, stops, strict=True)]
