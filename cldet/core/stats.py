"""Order statistics of short arrays without numpy's per-call overhead.

``np.median`` and ``np.percentile`` cost 15-50 us a call whatever the array's length; a track's
summary (``cldet.core.features``) takes two dozen of them, for hundreds of candidate tracks a
sequence, on arrays of a few to a few hundred values. One ``np.sort`` and a little arithmetic
give the same numbers, bit for bit: the median of an even count is the mean of the middle two,
and a percentile is numpy's default ("linear") interpolation, including the form of its lerp
(``b - (b - a) * (1 - t)`` where ``t >= 0.5``). Inputs are float64 arrays (integers or
float32 would add in their own type before the halving); a median of zeros may keep a zero's
sign where numpy drops it, which no comparison sees. The two on sorted values are compiled, so
that the track summary's compiled pass (``cldet.core.features``) calls them too.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "box_minimum",
    "column_medians",
    "median",
    "median_of_sorted",
    "percentile",
    "percentile_of_sorted",
]


@numba.njit(cache=True)
def median_of_sorted(s: NDArray[np.floating]) -> float:
    """The median of sorted values (NaN: none); compiled, so that compiled code can call it."""
    n = len(s)
    if n == 0:
        return np.nan
    h = n // 2
    if n % 2:
        return s[h]
    return (s[h - 1] + s[h]) / 2.0


@numba.njit(cache=True)
def percentile_of_sorted(s: NDArray[np.floating], q: float) -> float:
    """The ``q``-th percentile of sorted values (NaN: none), numpy's "linear" method."""
    n = len(s)
    if n == 0:
        return np.nan
    virtual = (n - 1) * (q / 100)
    # numpy's neighbours: past the last value both are the last, with the fraction measured
    # from index -1 (which matters only to an infinite last value: inf - inf)
    if virtual >= n - 1:
        lo, a, b = -1, s[n - 1], s[n - 1]
    else:
        lo = int(np.floor(virtual))
        a, b = s[lo], s[lo + 1]
    t = virtual - lo
    diff = b - a
    if t >= 0.5:
        return b - diff * (1 - t)
    return a + diff * t


def median(x: NDArray[np.floating]) -> float:
    """``float(np.median(x))`` of a 1-D array (NaN where any value is NaN; x not empty)."""
    s = np.sort(x)
    if np.isnan(s[-1]):  # NaN sorts last
        return float("nan")
    return float(median_of_sorted(s))


def column_medians(a: NDArray[np.floating]) -> NDArray[np.float64]:
    """``np.median(a, axis=0)`` of a 2-D array (a column with a NaN gives NaN; a not empty)."""
    s = np.sort(a, axis=0)
    n = len(s)
    h = n // 2
    out = s[h] if n % 2 else (s[h - 1] + s[h]) / 2.0
    return np.where(np.isnan(s[-1]), np.nan, out).astype(np.float64)


def percentile(x: NDArray[np.floating], q: float) -> float:
    """``float(np.percentile(x, q))`` of a 1-D array (NaN where any value is NaN; not empty)."""
    s = np.sort(x)
    if np.isnan(s[-1]):
        return float("nan")
    return float(percentile_of_sorted(s, q))


def box_minimum(a: NDArray[np.floating], size: int, wrap_columns: bool) -> NDArray[np.floating]:
    """``scipy.ndimage.minimum_filter(a, size, mode=("nearest", "wrap" or "nearest"))`` of a 2D
    array without NaN: the least value within ``size // 2`` rows and columns of each element,
    rows clamped at the edges, columns wrapped around (``wrap_columns``: a full circle of
    azimuths) or clamped; the same values (a minimum is exact) at a tenth of the cost on the
    small images of the background and the ground map. Separable: along the columns, then
    the same pass along the rows (of the transpose)."""
    half = int(size) // 2
    along_columns = _row_minimum(np.ascontiguousarray(a), half, bool(wrap_columns))
    return _row_minimum(np.ascontiguousarray(along_columns.T), half, False).T.copy()


@numba.njit(cache=True)
def _row_minimum(a: NDArray[np.floating], half: int, wrap: bool) -> NDArray[np.floating]:
    """Within each row of ``a``, the least value within ``half`` columns of each element, the
    columns wrapped around (``wrap``) or clamped at the ends."""
    n_r, n_c = a.shape
    out = np.empty_like(a)
    for i in range(n_r):
        for j in range(n_c):
            m = a[i, j]
            for d in range(-half, half + 1):
                k = j + d
                if k < 0 or k >= n_c:
                    if wrap:
                        k %= n_c
                    else:
                        k = min(max(k, 0), n_c - 1)
                if a[i, k] < m:
                    m = a[i, k]
            out[i, j] = m
    return out
