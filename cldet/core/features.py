"""What a candidate track looked like: per-detection arrays and one feature vector per track.

The hand-set selection (``cldet.core.selection``) and the learned models (``cldet.core.model``)
read the same measurements, gathered here once per track from the frames' cluster tables:
box size, height above the local ground, which LiDAR returned the points, and the
cross-section (points / density * range^2, the area that returned them). The feature vector
(:data:`FEATURE_NAMES`) summarises a track with physical quantities only: nothing in it names a
site, an elevation band or a sensor mount, so what is learned from one rig's logs can transfer
to another's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from cldet.config import TrackingConfig
from cldet.core.stats import column_medians, median, nanmedian, nanpercentile, percentile
from cldet.core.tracking import ClusterTable, TrackRecord, constant_velocity_fit, cross_section

__all__ = [
    "FEATURE_NAMES",
    "TYPE_FEATURES",
    "TrackDetections",
    "track_detections",
    "track_features",
]

F64 = NDArray[np.float64]

FEATURE_NAMES: Final[tuple[str, ...]] = (
    "log_hits",  # log(1 + detections)
    "duration_s",  # first to last detection
    "hit_rate",  # detections per 100 ms frame over the track's span
    "height_med_m",  # lowest point above the local ground (NaN: unknown)
    "height_p10_m",
    "low_fraction",  # detections whose lowest point is under 2 m above the ground
    "extent_med_m",  # largest box edge
    "extent_p90_m",
    "size_z_med_m",  # vertical box edge
    "size_z_p90_m",
    "size_xy_med_m",  # larger horizontal box edge
    "size_xy_p90_m",
    "elevation_sin_med",  # sine of the line of sight's elevation (which faces the LiDAR sees)
    "log_cross_med",  # log10 of the cross-section, m^2
    "log_cross_p90",
    "log_points_med",  # log(1 + points per detection)
    "log_range_med",  # log10 of the range, m
    "both_fraction",  # detections seen by both LiDARs in one cluster
    "avia_only_fraction",
    "log_mid_avia_med",  # log10(Mid-360 points / Avia points) where both saw it in one cluster
    "raw_fraction",  # detections from the raw-point gate
    "speed_med",  # filtered speed, m/s
    "speed_p90",
    "accel_med",  # |second difference| / dt^2 of consecutive detections, m/s^2
    "nis_med",  # normalised innovation squared of the updates
    "nis_out_fraction",  # updates above the 95 % point of chi^2 (3 dof)
    "spread_p90_m",  # 90th percentile distance to the median position
    "net_motion_m",  # constant-velocity fit's displacement over the span
    "path_m",  # summed step lengths (with net_motion: does it go anywhere)
    # the airframe's box from detections of 2 points or more, each edge scaled by (n+1)/(n-1):
    # n points spread evenly over a segment span (n-1)/(n+1) of it on average, so the scaled
    # edge estimates the segment's length whatever the range and the point count
    "size_z_est_m",  # median vertical edge so scaled
    "size_xy_est_m",  # median larger horizontal edge so scaled
    "aspect_med",  # median vertical / larger horizontal edge (the scaling cancels): flat or tall
    # the Mid-360 points' standard deviation in z about each detection's own mean, pooled over
    # the detections with 2 Mid-360 points or more (its square unbiased at any count): the
    # airframe's height seen from the side. The Mid-360 sweeps a small target once a frame; the
    # Avia's rosette comes back to it through the 100 ms scan, so its points also spread with
    # the drone's motion
    "mid_sd_z_m",
)

TYPE_FEATURES: Final[tuple[str, ...]] = (
    "log_cross_med",
    "log_cross_p90",
    "elevation_sin_med",
    "size_z_est_m",
    "size_xy_est_m",
    "aspect_med",
    "log_range_med",
    "log_mid_avia_med",
    "mid_sd_z_m",
)
"""The features the drone-type classifier reads: what the airframe's size changes (the area
that returned the points, seen from which side; the box the points span, corrected for how
many points spanned it, and its shape: a Mavic 3 is flat, 0.11 m tall for 0.35 m long, a
Phantom 4 of the same footprint is 0.19 m tall), and what its surface's reflectivity changes
(the two LiDARs' detection ranges differ, about 40 m against 190 m on a dark target, so the
Mid-360's share of the returns falls with range sooner on a dark airframe than on a white
one); not how it moves, which says more about the flight than about the airframe."""
TYPE_COLUMNS: Final = tuple(FEATURE_NAMES.index(n) for n in TYPE_FEATURES)

_NIS95 = 7.81
_LOW_M = 2.0


@dataclass(frozen=True)
class TrackDetections:
    """Per-detection measurements of one track, gathered from its frames' cluster tables."""

    extent: F64  # (H,) largest box edge, m (0 for raw-gate detections)
    size: F64  # (H,3) box edges, m (NaN for raw-gate detections)
    height: F64  # (H,) lowest point above the local ground, m (NaN unknown)
    n_mid360: NDArray[np.int64]  # (H,) raw-gate points are counted as the sparser Mid-360's
    n_avia: NDArray[np.int64]  # (H,)
    cross: F64  # (H,) cross-section, m^2
    crowd: NDArray[np.int64]  # (H,) other clusters near the detection's (0 for raw-gate ones)
    mid_z_ss: F64  # (H,) Mid-360 points' summed squared z deviations, m^2 (NaN: unknown)

    @property
    def both(self) -> NDArray[np.bool_]:
        """(H,) seen by both LiDARs in one cluster."""
        return (self.n_mid360 > 0) & (self.n_avia > 0)


def track_detections(
    rec: TrackRecord, tables: list[ClusterTable], cfg: TrackingConfig
) -> TrackDetections:
    """Gather one track's per-detection measurements."""
    h = len(rec.frames)
    extent = np.zeros(h)
    size = np.full((h, 3), np.nan)
    height = np.full(h, np.nan)
    n_mid = rec.n_points.copy()
    n_avia = np.zeros(h, dtype=np.int64)
    crowd = np.zeros(h, dtype=np.int64)
    mid_z_ss = np.full(h, np.nan)
    for k in np.flatnonzero(~rec.raw):
        table, c = tables[rec.frames[k]], rec.clusters[k]
        extent[k] = table.extent[c]
        size[k] = table.sizes()[c]
        height[k] = table.heights()[c]
        n_mid[k], n_avia[k] = table.n_mid360[c], table.n_avia[c]
        crowd[k] = table.crowds()[c]
        mid_z_ss[k] = table.mid360_z_spreads()[c]
    cross = cross_section(n_mid, n_avia, rec.positions, cfg)
    return TrackDetections(extent, size, height, n_mid, n_avia, cross, crowd, mid_z_ss)


def track_features(
    rec: TrackRecord, det: TrackDetections, times_s: F64, upto: int | None = None
) -> F64:
    """(len(FEATURE_NAMES),) the track's summary over its first ``upto`` detections (all when
    None); ``times_s`` are the detections' times (H,), seconds."""
    n = len(rec.frames) if upto is None else max(1, min(upto, len(rec.frames)))
    t = times_s[:n]
    pos = rec.positions[:n]
    raw = rec.raw[:n]
    cl = ~raw
    duration = float(t[-1] - t[0])
    height = det.height[:n]
    with np.errstate(invalid="ignore"):
        low = (
            float(np.mean(height[np.isfinite(height)] < _LOW_M))
            if np.isfinite(height).any()
            else float("nan")
        )
    size = det.size[:n]
    cross = det.cross[:n]
    log_cross = np.log10(np.maximum(cross, 1e-6))
    rng = np.linalg.norm(pos, axis=1)
    n_mid, n_avia = det.n_mid360[:n], det.n_avia[:n]
    both = (n_mid > 0) & (n_avia > 0) & cl
    speeds = rec.speed[:n][1:]
    nis = rec.nis[:n]
    nis = nis[np.isfinite(nis)]
    if n >= 3:
        dt1 = np.maximum(np.diff(t), 1e-3)
        v = np.diff(pos, axis=0) / dt1[:, None]
        dtm = np.maximum(0.5 * (dt1[1:] + dt1[:-1]), 1e-3)
        accel = median(np.linalg.norm(np.diff(v, axis=0), axis=1) / dtm)
    else:
        accel = float("nan")
    centre = column_medians(pos)
    if n >= 2:
        _, velocity, _ = constant_velocity_fit(t, pos)
        net = float(np.linalg.norm(velocity)) * duration
        path = float(np.linalg.norm(np.diff(pos, axis=0), axis=1).sum())
    else:
        net = path = 0.0
    z_est, xy_est, aspect = _box_estimates(det, n, cl)
    return np.array(
        [
            np.log1p(n),
            duration,
            n / (duration / 0.1 + 1.0),
            nanmedian(height),
            nanpercentile(height, 10),
            low,
            nanmedian(np.where(cl, det.extent[:n], np.nan)),
            nanpercentile(np.where(cl, det.extent[:n], np.nan), 90),
            nanmedian(size[:, 2]),
            nanpercentile(size[:, 2], 90),
            nanmedian(np.max(size[:, :2], axis=1)),
            nanpercentile(np.max(size[:, :2], axis=1), 90),
            median(pos[:, 2] / np.maximum(rng, 1e-3)),
            median(log_cross),
            percentile(log_cross, 90),
            median(np.log1p(rec.n_points[:n])),
            median(np.log10(np.maximum(rng, 1e-3))),
            float(np.mean(both)),
            float(np.mean((n_mid == 0) & (n_avia > 0) & cl)),
            nanmedian(
                np.where(both, np.log10(np.maximum(n_mid, 1) / np.maximum(n_avia, 1)), np.nan)
            ),
            float(np.mean(raw)),
            median(speeds) if len(speeds) else float("nan"),
            percentile(speeds, 90) if len(speeds) else float("nan"),
            accel,
            median(nis) if len(nis) else float("nan"),
            float(np.mean(nis > _NIS95)) if len(nis) else float("nan"),
            percentile(np.linalg.norm(pos - centre, axis=1), 90),
            net,
            path,
            z_est,
            xy_est,
            aspect,
            _pooled_sd(det.mid_z_ss[:n], n_mid, cl),
        ],
        dtype=np.float64,
    )


def _pooled_sd(ss: F64, counts: NDArray[np.int64], cl: NDArray[np.bool_]) -> float:
    """sqrt(sum of squared deviations / degrees of freedom) over the detections of clusters
    (``cl``) with 2 points or more (``counts``): the spread within one detection, whatever
    the detections' point counts (NaN: no such detection, or one whose spread is unknown)."""
    ok = cl & (counts >= 2)
    dof = float(np.sum(counts[ok] - 1))
    return float(np.sqrt(np.sum(ss[ok]) / dof)) if dof > 0 else float("nan")


def _box_estimates(
    det: TrackDetections, n: int, cl: NDArray[np.bool_]
) -> tuple[float, float, float]:
    """Median vertical and larger horizontal box edges of the first ``n`` detections (those of
    clusters, ``cl``, with 2 points or more), each scaled by (n+1)/(n-1) for its point count,
    and the median ratio of the two (NaN: no such detection)."""
    pts = det.n_mid360[:n] + det.n_avia[:n]
    ok = cl & (pts >= 2)
    if not ok.any():
        return float("nan"), float("nan"), float("nan")
    scale = (pts[ok] + 1.0) / (pts[ok] - 1.0)
    z = det.size[:n][ok, 2]
    xy = np.max(det.size[:n][ok, :2], axis=1)
    return (
        nanmedian(z * scale),
        nanmedian(xy * scale),
        nanmedian(z / np.maximum(xy, 1e-3)),
    )
