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

import numba
import numpy as np
from numpy.typing import NDArray

from cldet.config import TrackingConfig
from cldet.core.stats import median_of_sorted, percentile_of_sorted
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
    None); ``times_s`` are the detections' times (H,), seconds.

    The logarithms, sums and the constant-velocity fit are numpy's; the order statistics and
    fractions one compiled pass (``_summary``) with numpy's own arithmetic (the median and
    percentile of ``cldet.core.stats``): the same numbers (a median of zeros may keep a zero's
    sign where numpy drops it), at a quarter of the cost of a numpy call per statistic."""
    n = len(rec.frames) if upto is None else max(1, min(upto, len(rec.frames)))
    t = np.ascontiguousarray(times_s[:n], dtype=np.float64)
    pos = np.ascontiguousarray(rec.positions[:n], dtype=np.float64)
    rng = np.linalg.norm(pos, axis=1)
    n_mid, n_avia = det.n_mid360[:n], det.n_avia[:n]
    if n >= 2:
        _, velocity, _ = constant_velocity_fit(t, pos)
        net = float(np.linalg.norm(velocity)) * float(t[-1] - t[0])
        path = float(np.linalg.norm(np.diff(pos, axis=0), axis=1).sum())
    else:
        net = path = 0.0
    out = np.empty(len(FEATURE_NAMES), dtype=np.float64)
    out[0] = np.log1p(n)
    out[-1] = _pooled_sd(det.mid_z_ss[:n], n_mid, ~rec.raw[:n])
    _summary(
        t,
        pos,
        rng,
        np.ascontiguousarray(rec.raw[:n]),
        np.ascontiguousarray(det.height[:n], dtype=np.float64),
        np.ascontiguousarray(det.extent[:n], dtype=np.float64),
        np.ascontiguousarray(det.size[:n], dtype=np.float64),
        np.asarray(np.log10(np.maximum(det.cross[:n], 1e-6)), dtype=np.float64),
        np.asarray(np.log1p(rec.n_points[:n]), dtype=np.float64),
        np.asarray(np.log10(np.maximum(rng, 1e-3)), dtype=np.float64),
        np.ascontiguousarray(n_mid, dtype=np.int64),
        np.ascontiguousarray(n_avia, dtype=np.int64),
        np.asarray(np.log10(np.maximum(n_mid, 1) / np.maximum(n_avia, 1)), dtype=np.float64),
        np.ascontiguousarray(rec.speed[:n], dtype=np.float64),
        np.ascontiguousarray(rec.nis[:n], dtype=np.float64),
        net,
        path,
        out,
    )
    return out


def _pooled_sd(ss: F64, counts: NDArray[np.int64], cl: NDArray[np.bool_]) -> float:
    """sqrt(sum of squared deviations / degrees of freedom) over the detections of clusters
    (``cl``) with 2 points or more (``counts``): the spread within one detection, whatever
    the detections' point counts (NaN: no such detection, or one whose spread is unknown)."""
    ok = cl & (counts >= 2)
    dof = float(np.sum(counts[ok] - 1))
    return float(np.sqrt(np.sum(ss[ok]) / dof)) if dof > 0 else float("nan")


@numba.njit(cache=True)
def _finite_sorted(x: F64) -> F64:
    return np.sort(x[np.isfinite(x)])


@numba.njit(cache=True)
def _all_sorted(x: F64) -> F64:
    """Sorted values; empty where any is NaN (the median and percentile are then NaN)."""
    if np.isnan(x).any():
        return np.empty(0, dtype=np.float64)
    return np.sort(x)


@numba.njit(cache=True)
def _summary(
    t: F64,
    pos: F64,
    rng: F64,
    raw: NDArray[np.bool_],
    height: F64,
    extent: F64,
    size: F64,
    log_cross: F64,
    log_points: F64,
    log_range: F64,
    n_mid: NDArray[np.int64],
    n_avia: NDArray[np.int64],
    log_ratio: F64,
    speed: F64,
    nis_all: F64,
    net: float,
    path: float,
    out: F64,
) -> None:
    """``track_features`` from its second to its second-last entry (see ``FEATURE_NAMES``),
    into ``out``."""
    n = len(t)
    cl = ~raw
    duration = t[n - 1] - t[0]
    out[1] = duration
    out[2] = n / (duration / 0.1 + 1.0)
    h = _finite_sorted(height)
    out[3] = median_of_sorted(h)
    out[4] = percentile_of_sorted(h, 10.0)
    out[5] = np.sum(h < _LOW_M) / len(h) if len(h) else np.nan
    ext = _finite_sorted(np.where(cl, extent, np.nan))
    out[6] = median_of_sorted(ext)
    out[7] = percentile_of_sorted(ext, 90.0)
    sz = _finite_sorted(size[:, 2].copy())
    out[8] = median_of_sorted(sz)
    out[9] = percentile_of_sorted(sz, 90.0)
    xy = np.empty(n)
    for k in range(n):
        a, b = size[k, 0], size[k, 1]
        xy[k] = np.nan if np.isnan(a) or np.isnan(b) else max(a, b)
    sxy = _finite_sorted(xy)
    out[10] = median_of_sorted(sxy)
    out[11] = percentile_of_sorted(sxy, 90.0)
    out[12] = median_of_sorted(_all_sorted(pos[:, 2] / np.maximum(rng, 1e-3)))
    lc = _all_sorted(log_cross)
    out[13] = median_of_sorted(lc)
    out[14] = percentile_of_sorted(lc, 90.0)
    out[15] = median_of_sorted(_all_sorted(log_points))
    out[16] = median_of_sorted(_all_sorted(log_range))
    both = (n_mid > 0) & (n_avia > 0) & cl
    out[17] = np.sum(both) / n
    out[18] = np.sum((n_mid == 0) & (n_avia > 0) & cl) / n
    out[19] = median_of_sorted(_finite_sorted(np.where(both, log_ratio, np.nan)))
    out[20] = np.sum(raw) / n
    sp = _all_sorted(speed[1:].copy())
    out[21] = median_of_sorted(sp)
    out[22] = percentile_of_sorted(sp, 90.0)
    accel = np.nan
    if n >= 3:
        dt1 = np.maximum(t[1:] - t[:-1], 1e-3)
        v = np.empty((n - 1, 3))
        for k in range(n - 1):
            for d in range(3):
                v[k, d] = (pos[k + 1, d] - pos[k, d]) / dt1[k]
        acc = np.empty(n - 2)
        for k in range(n - 2):
            dtm = max(0.5 * (dt1[k + 1] + dt1[k]), 1e-3)
            dx = v[k + 1, 0] - v[k, 0]
            dy = v[k + 1, 1] - v[k, 1]
            dz = v[k + 1, 2] - v[k, 2]
            acc[k] = np.sqrt(dx * dx + dy * dy + dz * dz) / dtm
        accel = median_of_sorted(_all_sorted(acc))
    out[23] = accel
    nis = _finite_sorted(nis_all)
    out[24] = median_of_sorted(nis)
    out[25] = np.sum(nis > _NIS95) / len(nis) if len(nis) else np.nan
    centre = np.empty(3)
    for d in range(3):
        centre[d] = median_of_sorted(_all_sorted(pos[:, d].copy()))
    spread = np.empty(n)
    for k in range(n):
        dx = pos[k, 0] - centre[0]
        dy = pos[k, 1] - centre[1]
        dz = pos[k, 2] - centre[2]
        spread[k] = np.sqrt(dx * dx + dy * dy + dz * dz)
    out[26] = percentile_of_sorted(_all_sorted(spread), 90.0)
    out[27] = net
    out[28] = path
    # the box estimates: detections of clusters with 2 points or more, each edge scaled by
    # (n+1)/(n-1) for its point count, and the vertical / larger horizontal ratio
    pts = n_mid + n_avia
    ok = cl & (pts >= 2)
    m = int(np.sum(ok))
    z_est = xy_est = aspect = np.nan
    if m:
        zs = np.empty(m)
        xys = np.empty(m)
        ratio = np.empty(m)
        j = 0
        for k in range(n):
            if ok[k]:
                scale = (pts[k] + 1.0) / (pts[k] - 1.0)
                zs[j] = size[k, 2] * scale
                xys[j] = xy[k] * scale
                ratio[j] = size[k, 2] / max(xy[k], 1e-3) if not np.isnan(xy[k]) else np.nan
                j += 1
        z_est = median_of_sorted(_finite_sorted(zs))
        xy_est = median_of_sorted(_finite_sorted(xys))
        aspect = median_of_sorted(_finite_sorted(ratio))
    out[29] = z_est
    out[30] = xy_est
    out[31] = aspect
