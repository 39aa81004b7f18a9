"""What the sensors see: valid points per frame, elevation coverage, where the drone flies, and
which points are environment (the estimator's own background model)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cldet.config import CldetConfig
from cldet.core.background import FOREGROUND, BackgroundModel
from cldet.core.estimator import fuse_points
from cldet.core.frames import valid_points
from cldet.types import LidarFrame


@dataclass(frozen=True)
class FrameStats:
    """Valid points per paired frame of a sequence."""

    stamps_ns: NDArray[np.int64]  # (N,) Mid-360 stamps
    mid360_points: NDArray[np.int64]  # (N,) valid Mid-360 points
    avia_points: NDArray[np.int64]  # (N,) valid points of the paired Avia frame (0: none paired)
    avia_paired: NDArray[np.bool_]  # (N,) an Avia frame was paired

    @property
    def avia_empty_fraction(self) -> float:
        """Fraction of frames whose Avia cloud is empty (unpaired or all-zero)."""
        return float(np.mean(self.avia_points == 0)) if len(self.avia_points) else 0.0


def frame_statistics(frames: Iterable[LidarFrame]) -> FrameStats:
    """Count the valid points of each frame's two LiDARs (finite and not (0,0,0)).

    Args:
        frames: paired frames in stamp order.

    Returns:
        A :class:`FrameStats`.
    """
    stamps: list[int] = []
    mid: list[int] = []
    avia: list[int] = []
    paired: list[bool] = []
    for frame in frames:
        stamps.append(frame.stamp_ns)
        mid.append(len(valid_points(frame.mid360)))
        avia.append(len(valid_points(frame.avia)))
        paired.append(frame.avia_stamp_ns is not None)
    return FrameStats(
        stamps_ns=np.asarray(stamps, dtype=np.int64),
        mid360_points=np.asarray(mid, dtype=np.int64),
        avia_points=np.asarray(avia, dtype=np.int64),
        avia_paired=np.asarray(paired, dtype=np.bool_),
    )


def elevation_deg(points: ArrayLike) -> NDArray[np.float64]:
    """Elevation of each point (N,3) seen from the Mid-360 origin, degrees (-90..90, z up)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return np.degrees(np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1])))


def elevation_coverage(
    frames: Iterable[LidarFrame], edges_deg: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mean valid points per frame in each elevation band, per sensor.

    Args:
        frames: paired frames.
        edges_deg: (B+1,) ascending elevation band edges, degrees.

    Returns:
        (Mid-360 points per frame per band (B,), Avia points per frame per band (B,)); zeros
        when there is no frame.
    """
    edges = np.asarray(edges_deg, dtype=np.float64)
    mid = np.zeros(len(edges) - 1)
    avia = np.zeros(len(edges) - 1)
    n = 0
    for frame in frames:
        mid += np.histogram(elevation_deg(valid_points(frame.mid360)), bins=edges)[0]
        avia += np.histogram(elevation_deg(valid_points(frame.avia)), bins=edges)[0]
        n += 1
    return (mid / n, avia / n) if n else (mid, avia)


@dataclass(frozen=True)
class TruthHistograms:
    """Per-axis histograms and the x-y heatmap of drone positions."""

    axis_edges: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]  # x, y, z
    axis_counts: tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]
    xy_counts: NDArray[np.int64]  # (len(x_edges)-1, len(y_edges)-1), x along axis 0
    x_edges: NDArray[np.float64]  # metres
    y_edges: NDArray[np.float64]  # metres
    mean: NDArray[np.float64]  # (3,) metres
    std: NDArray[np.float64]  # (3,) metres


def truth_histograms(
    positions: ArrayLike, axis_bin_m: float = 1.0, xy_cell_m: float = 1.0
) -> TruthHistograms:
    """Histograms of drone positions (N,3): each axis in bins of ``axis_bin_m``, x-y in cells.

    Bin edges are multiples of the bin size covering every position.

    Raises:
        ValueError: no position, a non-finite position or a non-positive bin size.
    """
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        raise ValueError("no position to histogram")
    if not np.all(np.isfinite(p)):
        raise ValueError("positions must be finite")
    if axis_bin_m <= 0 or xy_cell_m <= 0:
        raise ValueError(f"bin sizes must be > 0, got {axis_bin_m} and {xy_cell_m}")
    edges = tuple(_edges(p[:, a], axis_bin_m) for a in range(3))
    counts = tuple(np.histogram(p[:, a], bins=edges[a])[0].astype(np.int64) for a in range(3))
    x_edges, y_edges = _edges(p[:, 0], xy_cell_m), _edges(p[:, 1], xy_cell_m)
    xy = np.histogram2d(p[:, 0], p[:, 1], bins=(x_edges, y_edges))[0].astype(np.int64)
    return TruthHistograms(
        axis_edges=(edges[0], edges[1], edges[2]),
        axis_counts=(counts[0], counts[1], counts[2]),
        xy_counts=xy,
        x_edges=x_edges,
        y_edges=y_edges,
        mean=p.mean(axis=0),
        std=p.std(axis=0),
    )


def _edges(values: NDArray[np.float64], step: float) -> NDArray[np.float64]:
    lo = np.floor(values.min() / step)
    hi = np.floor(values.max() / step) + 1
    return np.arange(lo, hi + 0.5) * step


def learn_background(
    frames: Iterable[LidarFrame], config: CldetConfig | None = None
) -> BackgroundModel:
    """Learn the static background (online, as the estimator does) from a sequence's frames.

    Both LiDARs' valid points within the configured range band are counted, as the estimator
    does (:func:`cldet.core.estimator.fuse_points`). The model then holds the static range of
    the last window of ``background.window_bins`` bins.

    Args:
        frames: every frame of the sequence, in stamp order.
        config: the estimator configuration (defaults when None).

    Returns:
        The model; :func:`split_environment` classifies a frame's points with it.
    """
    cfg = config or CldetConfig()
    model = BackgroundModel(cfg.background)
    last_ns = None
    for frame in frames:
        points, _ = fuse_points(frame, cfg)
        model.update(frame.stamp_ns, points)
        last_ns = frame.stamp_ns
    if last_ns is not None:  # finish the last bin so that it counts
        model.advance(last_ns + int(round(cfg.background.bin_s * 1e9)))
    return model


def split_environment(
    frame: LidarFrame, model: BackgroundModel, config: CldetConfig | None = None
) -> tuple[NDArray[np.float32], NDArray[np.bool_], int]:
    """A frame's fused points and which of them are foreground (not environment).

    Args:
        frame: one paired frame.
        model: the sequence's background (:func:`learn_background`).
        config: the estimator configuration (defaults when None).

    Returns:
        (points (N,3) metres, Mid-360 first; foreground mask (N,); number of Mid-360 points).
    """
    cfg = config or CldetConfig()
    points, n_mid = fuse_points(frame, cfg)
    return points, model.classify(points) == FOREGROUND, n_mid
