"""Plain data passed between layers: frozen dataclasses, times in integer ns, lengths in metres."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.floating]


@dataclass(frozen=True)
class Cloud:
    """One point cloud (a LiDAR or radar frame) at one instant."""

    stamp_ns: int
    points: NDArray[np.float32]  # (N, 3) x, y, z metres in the sensor's frame; valid rows only
    # (N,) each point's firing time after ``stamp_ns``, seconds (the scan lasts ~100 ms); None:
    # not recorded (the estimator then dates every point at ``frames.scan_offset_s``)
    times: NDArray[np.float32] | None = None


@dataclass(frozen=True)
class LidarFrame:
    """One Mid-360 scan with the Avia scan paired to it (both already in the Mid-360 frame)."""

    stamp_ns: int  # the Mid-360 stamp; estimates are made at this instant
    mid360: NDArray[np.float32]  # (N, 3) valid points, metres
    avia: NDArray[np.float32]  # (M, 3) valid points, metres; (0, 3) when no Avia frame is paired
    avia_stamp_ns: int | None = None  # stamp of the paired Avia frame, None when there is none
    mid360_times: NDArray[np.float32] | None = None  # (N,) point times after stamp_ns, s (Cloud)
    avia_times: NDArray[np.float32] | None = None  # (M,) after avia_stamp_ns, s; None: unknown


@dataclass(frozen=True)
class PositionSample:
    """A 3D position at one instant (ground truth, a reference estimate)."""

    stamp_ns: int
    position: NDArray[np.float64]  # (3,) x, y, z metres, Mid-360 frame


@dataclass(frozen=True)
class ClassSample:
    """The drone type label at one instant (0..3, constant within a sequence)."""

    stamp_ns: int
    class_id: int


@dataclass(frozen=True)
class ImageFrame:
    """One camera image as the PNG bytes found on disk (never decoded)."""

    stamp_ns: int
    png: bytes


class Source(IntEnum):
    """Where an estimate comes from."""

    DETECTED = 1  # a cluster was associated with the track in this frame
    PREDICTED = 2  # no detection: the track's motion model predicted it
    SMOOTHED = 3  # filled or refined by the forward-backward smoother
    FALLBACK = 4  # no track at all: a fallback rule (cl-det's history / training mean)


@dataclass(frozen=True)
class Cluster:
    """One cluster of foreground points in one frame."""

    cluster_id: int  # index within the frame, 0..K-1
    centroid: NDArray[np.float64]  # (3,) metres
    lower: NDArray[np.float64]  # (3,) axis-aligned box min, metres
    upper: NDArray[np.float64]  # (3,) axis-aligned box max, metres
    n_points: int
    n_mid360: int = 0  # of which from the Mid-360
    n_avia: int = 0  # of which from the Avia
    # the Mid-360 points' squared deviations from their mean height (sensor z), summed, m^2: with
    # n_mid360 their vertical spread (a drone type's height), free of the Avia's motion smear;
    # NaN: not measured
    mid360_z_ss: float = float("nan")


@dataclass(frozen=True)
class Estimate:
    """The drone's estimated position at one instant."""

    stamp_ns: int
    position: NDArray[np.float64]  # (3,) metres, Mid-360 frame
    source: Source
    n_points: int  # points in the associated cluster (0 when not detected)
    sigma_m: float  # 1-sigma position uncertainty, metres


@dataclass(frozen=True)
class ClassEstimate:
    """The drone type of a sequence as estimated from the evidence up to one instant."""

    stamp_ns: int
    class_id: int  # the most probable class
    class_ids: tuple[int, ...]  # the classes the model knows
    probabilities: tuple[float, ...]  # one per class id, summing to 1
