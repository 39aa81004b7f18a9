"""Pairing of Mid-360 and Avia frames: a streaming merge by nearest stamp.

The Avia fires ~14 ms after the Mid-360, both at 10 Hz, and both clouds are already in the
Mid-360 frame, so pairing is only a matter of stamps (integer ns).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator

import numba
import numpy as np
from numpy.typing import NDArray

from cldet.types import Cloud, LidarFrame

__all__ = ["pair_frames", "valid_mask", "valid_points"]

_EMPTY = np.zeros((0, 3), dtype=np.float32)


def pair_frames(
    mid360: Iterable[Cloud], avia: Iterable[Cloud], max_gap_ns: int = 50_000_000
) -> Iterator[LidarFrame]:
    """Yield each Mid-360 frame with its nearest Avia frame within ``max_gap_ns``.

    Both inputs must be in stamp order. Streaming: only the Avia frames within the gap of the
    current Mid-360 stamp are buffered. Each Avia frame is paired at most once (with the nearest
    Mid-360 frame that comes first in order); an Avia frame with no Mid-360 frame within the gap
    is dropped. A Mid-360 frame without an Avia partner gets a ``(0, 3)`` Avia cloud and
    ``avia_stamp_ns = None``.

    Args:
        mid360: Mid-360 clouds in stamp order (ns).
        avia: Avia clouds in stamp order (ns), already in the Mid-360 frame.
        max_gap_ns: largest |Avia - Mid-360| stamp difference accepted, ns.

    Yields:
        One LidarFrame per Mid-360 cloud, at the Mid-360 stamp.
    """
    if max_gap_ns < 0:
        raise ValueError(f"max_gap_ns must be >= 0, got {max_gap_ns}")
    avia_it = iter(avia)
    pending: deque[Cloud] = deque()
    exhausted = False
    for m in mid360:
        t = m.stamp_ns
        # buffer every Avia frame up to t + gap
        while not exhausted and (not pending or pending[-1].stamp_ns <= t + max_gap_ns):
            nxt = next(avia_it, None)
            if nxt is None:
                exhausted = True
            else:
                pending.append(nxt)
        # drop frames too old for this (and hence any later) Mid-360 frame
        while pending and pending[0].stamp_ns < t - max_gap_ns:
            pending.popleft()
        best: Cloud | None = None
        for a in pending:
            if a.stamp_ns > t + max_gap_ns:
                break
            if best is None or abs(a.stamp_ns - t) < abs(best.stamp_ns - t):
                best = a
        if best is None:
            yield LidarFrame(
                stamp_ns=t, mid360=m.points, avia=_EMPTY, avia_stamp_ns=None, mid360_times=m.times
            )
        else:
            # consume it and every older one (they are nearer to this frame than to any later)
            while pending and pending[0] is not best:
                pending.popleft()
            pending.popleft()
            yield LidarFrame(
                stamp_ns=t,
                mid360=m.points,
                avia=best.points,
                avia_stamp_ns=best.stamp_ns,
                mid360_times=m.times,
                avia_times=best.times,
            )


@numba.njit(cache=True)
def _keep_mask(p: NDArray[np.float32], min2: float, max2: float) -> NDArray[np.bool_]:
    n = p.shape[0]
    keep = np.empty(n, dtype=np.bool_)
    for i in range(n):
        r2 = p[i, 0] * p[i, 0] + p[i, 1] * p[i, 1] + p[i, 2] * p[i, 2]
        keep[i] = np.isfinite(r2) and r2 > 0.0 and r2 >= min2 and r2 <= max2
    return keep


def valid_mask(
    points: NDArray[np.floating], min_range_m: float = 0.0, max_range_m: float = np.inf
) -> NDArray[np.bool_]:
    """(N,) which rows of ``points`` (N,3) ``valid_points`` keeps."""
    p = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
    return _keep_mask(p, float(min_range_m) ** 2, float(max_range_m) ** 2)


def valid_points(
    points: NDArray[np.floating], min_range_m: float = 0.0, max_range_m: float = np.inf
) -> NDArray[np.float32]:
    """The rows of ``points`` (N,3) that are finite, not exactly (0,0,0) and within the range band.

    Range is the distance from the Mid-360 origin, metres.
    """
    p = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
    if len(p) == 0:
        return p
    keep = _keep_mask(p, float(min_range_m) ** 2, float(max_range_m) ** 2)
    return p if keep.all() else p[keep]
