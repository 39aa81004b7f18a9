"""Tests of the Mid-360 / Avia pairing and the point filter."""

from __future__ import annotations

import numpy as np
import pytest

from cldet.core.frames import pair_frames, valid_points
from cldet.stamps import row_times
from cldet.types import Cloud

MS = 1_000_000


def _cloud(stamp_ns: int, n: int = 2, value: float = 1.0) -> Cloud:
    return Cloud(stamp_ns, np.full((n, 3), value, dtype=np.float32))


def test_pairs_each_mid360_with_the_avia_14ms_later() -> None:
    mid = [_cloud(1000 * MS + 100 * MS * k, value=k + 1) for k in range(5)]
    avia = [_cloud(c.stamp_ns + 14 * MS, n=k + 1, value=-(k + 1)) for k, c in enumerate(mid)]
    frames = list(pair_frames(iter(mid), iter(avia)))
    assert [f.stamp_ns for f in frames] == [c.stamp_ns for c in mid]
    for k, f in enumerate(frames):
        assert f.avia_stamp_ns == mid[k].stamp_ns + 14 * MS
        assert len(f.avia) == k + 1 and f.avia[0, 0] == -(k + 1)
        assert f.mid360[0, 0] == k + 1


def test_missing_and_extra_avia_frames() -> None:
    mid = [_cloud(100 * MS * k) for k in range(1, 6)]
    # no Avia for the 2nd frame, an Avia frame far from any Mid-360 frame, one too late
    avia = [
        _cloud(100 * MS + 14 * MS),
        _cloud(250 * MS),  # 50 ms from both neighbours: dropped at max_gap 40 ms
        _cloud(300 * MS + 10 * MS),
        _cloud(400 * MS - 5 * MS),
        _cloud(500 * MS + 60 * MS),  # beyond the gap
    ]
    frames = list(pair_frames(mid, avia, max_gap_ns=40 * MS))
    assert [f.avia_stamp_ns for f in frames] == [114 * MS, None, 310 * MS, 395 * MS, None]
    assert frames[1].avia.shape == (0, 3)


def test_an_avia_frame_is_used_once_and_nearest_wins() -> None:
    mid = [_cloud(0), _cloud(30 * MS)]
    avia = [_cloud(20 * MS), _cloud(28 * MS)]
    frames = list(pair_frames(mid, avia))
    assert [f.avia_stamp_ns for f in frames] == [20 * MS, 28 * MS]


def test_no_avia_at_all_and_no_mid360() -> None:
    frames = list(pair_frames([_cloud(0), _cloud(100 * MS)], []))
    assert [f.avia_stamp_ns for f in frames] == [None, None]
    assert list(pair_frames([], [_cloud(0)])) == []
    with pytest.raises(ValueError, match="max_gap_ns"):
        list(pair_frames([], [], max_gap_ns=-1))


def test_valid_points_drops_zero_nonfinite_and_out_of_range() -> None:
    p = np.array(
        [[0, 0, 0], [-0.0, -0.0, 0.0], [1, 0, 0], [np.nan, 1, 1], [0.1, 0, 0], [200, 0, 0]],
        dtype=np.float64,
    )
    out = valid_points(p, min_range_m=0.3, max_range_m=150.0)
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out, [[1, 0, 0]])
    assert valid_points(p[:3]).shape == (1, 3)


def test_row_times_date_a_scan_array_by_its_rows() -> None:
    """Row i of an N-row Livox array fired i / N of the 100 ms scan after the stamp."""
    times = row_times(np.array([0, 1, 10_032, 20_063]), 20_064)
    np.testing.assert_allclose(times, [0.0, 0.1 / 20_064, 0.05, 0.1 * 20_063 / 20_064], rtol=1e-6)
    assert times.dtype == np.float32
    assert row_times(np.zeros(0, dtype=np.int64), 0).shape == (0,)


def test_pairing_keeps_each_clouds_point_times() -> None:
    mid = Cloud(100 * MS, np.ones((2, 3), np.float32), np.array([0.01, 0.09], np.float32))
    avia = Cloud(114 * MS, np.ones((1, 3), np.float32), np.array([0.05], np.float32))
    (frame,) = pair_frames(iter([mid]), iter([avia]))
    assert frame.mid360_times is mid.times and frame.avia_times is avia.times
    (alone,) = pair_frames(iter([Cloud(100 * MS, np.ones((1, 3), np.float32))]), iter([]))
    assert alone.mid360_times is None and alone.avia_times is None
