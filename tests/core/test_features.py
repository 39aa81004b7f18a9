"""Track features: the airframe's box estimates do not depend on how many points spanned it."""

from __future__ import annotations

import numpy as np
import pytest

from cldet.config import CldetConfig
from cldet.core.clustering import summarize_clusters
from cldet.core.features import FEATURE_NAMES, TrackDetections, track_detections, track_features
from cldet.core.tracking import ClusterTable, TrackRecord


def _track(
    size_m: tuple[float, float, float], points: int, seed: int, sensor: str = "avia"
) -> np.ndarray:
    """The features of a 60-detection hover whose clusters hold ``points`` points of one
    ``sensor`` ("avia" or "mid360") drawn evenly inside a box of ``size_m`` (x, y, z edges)."""
    rng = np.random.default_rng(seed)
    h = 60
    clouds = rng.uniform(0.0, 1.0, (h, points, 3)) * size_m
    edges = np.ptp(clouds, axis=1)
    z_ss = np.sum((clouds[:, :, 2] - clouds[:, :, 2].mean(axis=1, keepdims=True)) ** 2, axis=1)
    counts = np.full(h, points)
    none = np.zeros(h, dtype=np.int64)
    positions = np.tile([3.0, 4.0, 20.0], (h, 1))
    rec = TrackRecord(
        0,
        np.arange(h),
        np.zeros(h, dtype=np.int64),
        positions,
        np.full(h, points),
        np.full(h, 1.0),
        np.zeros(h),
    )
    det = TrackDetections(
        extent=edges.max(axis=1),
        size=edges,
        height=np.full(h, 18.0),
        n_mid360=counts if sensor == "mid360" else none,
        n_avia=none if sensor == "mid360" else counts,
        cross=np.full(h, 0.1),
        crowd=none,
        mid_z_ss=z_ss if sensor == "mid360" else np.zeros(h),
    )
    return track_features(rec, det, np.arange(h) * 0.1)


def _f(features: np.ndarray, name: str) -> float:
    return float(features[FEATURE_NAMES.index(name)])


def test_box_estimates_tell_a_flat_airframe_from_a_tall_one_at_any_point_count() -> None:
    flat, tall = (0.35, 0.29, 0.11), (0.30, 0.30, 0.19)  # a Mavic 3's and a Phantom 4's boxes
    for points in (2, 3, 8):
        f, t = _track(flat, points, 1), _track(tall, points, 2)
        assert 0.75 * 0.11 < _f(f, "size_z_est_m") < 1.3 * 0.11
        assert 0.75 * 0.19 < _f(t, "size_z_est_m") < 1.3 * 0.19
        assert _f(f, "aspect_med") < 0.8 * _f(t, "aspect_med")
    # the raw medians shrink with the point count; the scaled ones do not
    sparse, dense = _track(tall, 2, 3), _track(tall, 8, 4)
    assert _f(sparse, "size_z_med_m") < 0.6 * _f(dense, "size_z_med_m")
    assert abs(_f(sparse, "size_z_est_m") / _f(dense, "size_z_est_m") - 1.0) < 0.3


def test_box_estimates_are_unknown_without_a_detection_of_two_points() -> None:
    features = _track((0.3, 0.3, 0.2), 1, 5)
    for name in ("size_z_est_m", "size_xy_est_m", "aspect_med"):
        assert np.isnan(_f(features, name))


def test_the_mid360_height_spread_tells_flat_from_tall_at_any_point_count() -> None:
    # points even over a height h spread by h / sqrt(12) about their mean, pooled over detections
    # of 2, 3 or 8 points alike
    for points in (2, 3, 8):
        flat = _f(_track((0.35, 0.29, 0.11), points, 6, "mid360"), "mid_sd_z_m")
        tall = _f(_track((0.30, 0.30, 0.19), points, 7, "mid360"), "mid_sd_z_m")
        assert flat == pytest.approx(0.11 / np.sqrt(12), rel=0.2)
        assert tall == pytest.approx(0.19 / np.sqrt(12), rel=0.2)
    # the Avia's points do not count (its rosette smears a moving drone through the scan)
    assert np.isnan(_f(_track((0.30, 0.30, 0.19), 8, 8), "mid_sd_z_m"))


def test_the_height_spread_reads_the_clusters_mid360_points_and_skips_raw_gate_detections() -> None:
    """From frames' clusters (4 Mid-360 points over a flat airframe's 0.11 m, 4 Avia points
    smeared over 1 m by its motion) through the tables: the Mid-360's spread alone; a raw-gate
    detection, which has no cluster, is left out."""
    rng = np.random.default_rng(9)
    h = 40
    tables = []
    for _ in range(h):
        mid = rng.uniform(0.0, 1.0, (4, 3)) * (0.35, 0.29, 0.11) + (10.0, 0.0, 5.0)
        avia = rng.uniform(0.0, 1.0, (4, 3)) * (0.35, 0.29, 1.0) + (10.0, 0.0, 5.0)
        points = np.vstack([mid, avia])
        clusters = summarize_clusters(points, np.zeros(8, dtype=np.int32), n_mid360=4)
        tables.append(ClusterTable.from_clusters(clusters))
    clusters_of = np.zeros(h, dtype=np.int64)
    clusters_of[5] = -1  # the raw-point gate's
    rec = TrackRecord(
        0,
        np.arange(h),
        clusters_of,
        np.tile([10.0, 0.0, 5.0], (h, 1)),
        np.full(h, 8),
        np.ones(h),
        np.zeros(h),
    )
    det = track_detections(rec, tables, CldetConfig().tracking)
    assert np.isnan(det.mid_z_ss[5]) and np.isfinite(np.delete(det.mid_z_ss, 5)).all()
    spread = _f(track_features(rec, det, np.arange(h) * 0.1), "mid_sd_z_m")
    assert spread == pytest.approx(0.11 / np.sqrt(12), rel=0.25)  # the Avia's 1 m: ~0.29


def test_the_summary_gives_numpys_own_numbers_bit_for_bit() -> None:
    """The compiled summary against numpy's functions on random tracks of 1 to 300 detections
    (past 128 numpy's pairwise sums recurse) with unknown and infinite heights, raw-gate
    detections and unfiltered updates: equal (``==``), NaN where numpy gives NaN."""
    rng = np.random.default_rng(11)
    for h in (1, 2, 3, 7, 8, 9, 17, 64, 129, 300):
        for _ in range(4):
            clusters = np.where(rng.random(h) < 0.2, -1, 0)
            raw = clusters < 0
            pos = rng.normal(0.0, 30.0, (h, 3)) * 10.0 ** rng.uniform(-2, 1, (h, 1))
            times = np.cumsum(rng.uniform(0.05, 0.4, h))
            speed = rng.gamma(2.0, 4.0, h)
            nis = np.where(rng.random(h) < 0.1, np.nan, rng.gamma(1.5, 2.0, h))
            rec = TrackRecord(0, np.arange(h), clusters, pos, rng.integers(1, 40, h), nis, speed)
            size = np.where(raw[:, None], np.nan, rng.uniform(0.01, 2.0, (h, 3)))
            height = rng.normal(3.0, 4.0, h)
            height[rng.random(h) < 0.2] = np.nan
            height[rng.random(h) < 0.05] = np.inf
            n_mid = np.where(rng.random(h) < 0.3, 0, rng.integers(1, 30, h))
            n_avia = np.where(n_mid == 0, rng.integers(1, 30, h), rng.integers(0, 30, h))
            ss = np.where(raw, np.nan, rng.uniform(0.0, 0.05, h))
            det = TrackDetections(
                extent=np.max(np.where(raw[:, None], 0.0, size), axis=1),
                size=size,
                height=height,
                n_mid360=n_mid,
                n_avia=n_avia,
                cross=rng.uniform(1e-7, 3.0, h),
                crowd=np.zeros(h, dtype=np.int64),
                mid_z_ss=ss,
            )
            f = track_features(rec, det, times)
            finite_h = height[np.isfinite(height)]
            steps = np.linalg.norm(np.diff(pos, axis=0), axis=1)
            ok = ~raw & (n_mid >= 2)
            expect = {
                "height_med_m": np.median(finite_h) if len(finite_h) else np.nan,
                "height_p10_m": np.percentile(finite_h, 10) if len(finite_h) else np.nan,
                "extent_p90_m": np.nanpercentile(np.where(raw, np.nan, det.extent), 90)
                if (~raw).any()
                else np.nan,
                "size_xy_med_m": np.nanmedian(np.max(size[:, :2], axis=1))
                if (~raw).any()
                else np.nan,
                "log_cross_p90": np.percentile(np.log10(det.cross), 90),
                "speed_p90": np.percentile(speed[1:], 90) if h > 1 else np.nan,
                "nis_med": np.nanmedian(nis) if np.isfinite(nis).any() else np.nan,
                "spread_p90_m": np.percentile(
                    np.linalg.norm(pos - np.median(pos, axis=0), axis=1), 90
                ),
                "path_m": steps.sum() if h > 1 else 0.0,
                "mid_sd_z_m": np.sqrt(np.sum(ss[ok]) / np.sum(n_mid[ok] - 1))
                if ok.any()
                else np.nan,
            }
            for name, value in expect.items():
                got = _f(f, name)
                assert got == value or (np.isnan(got) and np.isnan(value)), (h, name)
