"""Evaluate a sampled 3D trajectory at arbitrary query stamps: interpolation inside, motion outside.

A trajectory is K samples ``(stamp_ns, position)``. Inside its span the position is interpolated
linearly between the two neighbouring samples. Before the first and after the last sample the
track keeps its own motion: a constant velocity fitted by least squares to the samples of the
first (or last) ``velocity_window_ns`` of the trajectory, applied from the end sample itself (so
the result is continuous at the ends). A single-sample trajectory is held constant.

Times are integer nanoseconds at the boundary; internally they become float seconds relative to
the first sample, so a Unix-epoch stamp never loses its microseconds to a float.
Pure numpy: no I/O, no file formats.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cldet.stamps import NS_PER_S


def evaluate_trajectory(
    stamps_ns: ArrayLike,
    positions: ArrayLike,
    query_ns: ArrayLike,
    *,
    velocity_window_ns: int = NS_PER_S,
    max_extrapolation_ns: int | None = None,
) -> NDArray[np.float64]:
    """Positions of a trajectory at the query stamps (linear inside, constant velocity outside).

    Args:
        stamps_ns: (K,) integer ns, the samples' stamps, K >= 1; any order. Samples sharing a
            stamp are averaged.
        positions: (K, 3) metres, finite.
        query_ns: (Q,) integer ns, any order, any range; Q may be 0.
        velocity_window_ns: length of the trajectory's start (end) used to fit the velocity by
            least squares for queries before (after) it. When that window holds a single sample,
            the nearest other sample is used too, so two or more samples always give a velocity.
        max_extrapolation_ns: if given, extrapolate at most this far beyond an end; a query
            further out gets the position reached at that distance (held). ``None``: no limit.

    Returns:
        (Q, 3) float64 metres, finite, in the order of ``query_ns``.

    Raises:
        ValueError: empty trajectory, mismatched or wrongly shaped arrays, non-finite positions,
            a negative window or extrapolation limit.
    """
    stamps = np.asarray(stamps_ns)
    pos = np.asarray(positions, dtype=np.float64)
    query = np.asarray(query_ns)
    if stamps.ndim != 1 or stamps.size == 0:
        raise ValueError(f"stamps_ns must be a non-empty 1-D array, got shape {stamps.shape}")
    if pos.shape != (stamps.size, 3):
        raise ValueError(f"positions must have shape ({stamps.size}, 3), got {pos.shape}")
    if query.ndim != 1:
        raise ValueError(f"query_ns must be 1-D, got shape {query.shape}")
    for name, arr in (("stamps_ns", stamps), ("query_ns", query)):
        if arr.size and not np.issubdtype(arr.dtype, np.integer):
            raise ValueError(f"{name} must hold integer nanoseconds, got dtype {arr.dtype}")
    if not np.all(np.isfinite(pos)):
        raise ValueError("positions must be finite (found NaN or inf)")
    if velocity_window_ns < 0:
        raise ValueError(f"velocity_window_ns must be >= 0, got {velocity_window_ns}")
    if max_extrapolation_ns is not None and max_extrapolation_ns < 0:
        raise ValueError(f"max_extrapolation_ns must be >= 0, got {max_extrapolation_ns}")

    stamps = stamps.astype(np.int64)
    query = query.astype(np.int64)
    stamps, pos = _sorted_unique(stamps, pos)
    out = np.empty((query.size, 3), dtype=np.float64)
    if query.size == 0:
        return out

    ref = int(stamps[0])
    t = (stamps - ref).astype(np.float64) / NS_PER_S  # seconds since the first sample
    q = (query - ref).astype(np.float64) / NS_PER_S

    for axis in range(3):  # inside the span (and clamped outside, overwritten below)
        out[:, axis] = np.interp(q, t, pos[:, axis])

    window_s = velocity_window_ns / NS_PER_S
    limit_s = None if max_extrapolation_ns is None else max_extrapolation_ns / NS_PER_S

    before = q < t[0]
    if np.any(before):
        n = _window_count(t - t[0], window_s)
        velocity = _fit_velocity(t[:n], pos[:n])
        dt = q[before] - t[0]  # negative
        if limit_s is not None:
            dt = np.maximum(dt, -limit_s)
        out[before] = pos[0] + dt[:, None] * velocity

    after = q > t[-1]
    if np.any(after):
        n = _window_count(t[-1] - t[::-1], window_s)
        velocity = _fit_velocity(t[-n:], pos[-n:])
        dt = q[after] - t[-1]  # positive
        if limit_s is not None:
            dt = np.minimum(dt, limit_s)
        out[after] = pos[-1] + dt[:, None] * velocity

    return out


def trajectory_errors(
    stamps_ns: ArrayLike,
    positions: ArrayLike,
    reference_stamps_ns: ArrayLike,
    reference_positions: ArrayLike,
) -> NDArray[np.float64]:
    """3D distance of each position to a reference trajectory evaluated at its stamp.

    The one error against a trajectory (the truth, or an estimate): the reference is evaluated
    by :func:`evaluate_trajectory` (linear inside, its own motion outside).

    Args:
        stamps_ns: (N,) integer ns; N may be 0.
        positions: (N, 3) metres.
        reference_stamps_ns: (K,) integer ns, K >= 1.
        reference_positions: (K, 3) metres.

    Returns:
        (N,) metres.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if stamps.size == 0:
        return np.zeros(0)
    reference = evaluate_trajectory(reference_stamps_ns, reference_positions, stamps)
    return np.asarray(np.linalg.norm(pos - reference, axis=1), dtype=np.float64)


def rms(errors: ArrayLike) -> float:
    """Root mean square of ``errors`` (metres); NaN when there is none."""
    e = np.asarray(errors, dtype=np.float64)
    return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")


def _sorted_unique(
    stamps: NDArray[np.int64], pos: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Sort by stamp; average the positions of samples sharing a stamp."""
    order = np.argsort(stamps, kind="stable")
    stamps, pos = stamps[order], pos[order]
    unique, inverse, counts = np.unique(stamps, return_inverse=True, return_counts=True)
    if unique.size == stamps.size:
        return stamps, pos
    summed = np.zeros((unique.size, 3), dtype=np.float64)
    np.add.at(summed, inverse, pos)
    return unique, summed / counts[:, None]


def _window_count(offsets_s: NDArray[np.float64], window_s: float) -> int:
    """Samples within ``window_s`` of the end (offsets ascending from 0), at least 2 when K >= 2."""
    n = int(np.searchsorted(offsets_s, window_s, side="right"))
    return min(max(n, 2), offsets_s.size)


def _fit_velocity(t: NDArray[np.float64], pos: NDArray[np.float64]) -> NDArray[np.float64]:
    """Least-squares velocity (3,) m/s of ``pos`` (n, 3) against ``t`` (n,) s; zero when n < 2."""
    if t.size < 2:
        return np.zeros(3)
    dt = t - t.mean()
    return np.asarray((dt @ (pos - pos.mean(axis=0))) / (dt @ dt), dtype=np.float64)
