"""Track features: the airframe's box estimates do not depend on how many points spanned it."""

from __future__ import annotations

import numpy as np

from cldet.core.features import FEATURE_NAMES, TrackDetections, track_features
from cldet.core.tracking import TrackRecord


def _track(size_m: tuple[float, float, float], points: int, seed: int) -> np.ndarray:
    """The features of a 60-detection hover whose clusters hold ``points`` points drawn
    evenly inside a box of ``size_m`` (x, y, z edges)."""
    rng = np.random.default_rng(seed)
    h = 60
    edges = np.array(
        [np.ptp(rng.uniform(0.0, 1.0, (points, 3)) * size_m, axis=0) for _ in range(h)]
    )
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
        n_mid360=np.zeros(h, dtype=np.int64),
        n_avia=np.full(h, points),
        cross=np.full(h, 0.1),
        crowd=np.zeros(h, dtype=np.int64),
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
