"""Tests of the centroid bias correction and its least-squares fit."""

from __future__ import annotations

import numpy as np
import pytest

from cldet.config import BiasConfig
from cldet.core.bias import apply_bias, fit_bias
from cldet.errors import CldetError
from cldet.types import Estimate, PositionSample, Source

MS = 1_000_000


def test_apply_bias_along_the_ray_and_up() -> None:
    p = np.array([[3.0, 0.0, 4.0], [0.0, 0.0, 0.0]])
    out = apply_bias(p, BiasConfig(along_ray_m=0.5, z_m=0.15))
    np.testing.assert_allclose(out[0], [3.3, 0.0, 4.4 + 0.15])
    np.testing.assert_allclose(out[1], [0.0, 0.0, 0.15])  # no ray at the origin
    np.testing.assert_array_equal(apply_bias(p, BiasConfig()), p)


def test_fit_bias_recovers_known_offsets() -> None:
    rng = np.random.default_rng(1)
    truth_stamps = np.arange(0, 10_000, 50) * MS  # 20 Hz
    truth_pos = np.stack(
        [10 * np.cos(truth_stamps / 3e9), 10 * np.sin(truth_stamps / 3e9), 5 + truth_stamps / 2e9],
        1,
    )
    truth = [PositionSample(int(s), p) for s, p in zip(truth_stamps, truth_pos, strict=True)]
    est_stamps = np.arange(7, 9_900, 100) * MS  # 10 Hz, not aligned with the truth
    true_pos = np.stack([np.interp(est_stamps, truth_stamps, truth_pos[:, d]) for d in range(3)], 1)
    # detections see the near face (0.2 m short along the ray) and miss the prism (0.15 m)
    u = true_pos / np.linalg.norm(true_pos, axis=1, keepdims=True)
    seen = true_pos - 0.2 * u - np.array([0, 0, 0.15]) + rng.normal(0, 0.02, true_pos.shape)
    dets = [
        Estimate(int(s), p, Source.DETECTED, 5, 0.1) for s, p in zip(est_stamps, seen, strict=True)
    ]
    dets.append(Estimate(int(est_stamps[3]), np.array([99.0, 99, 99]), Source.PREDICTED, 0, 9.0))
    # a few detections of something else, metres away
    dets += [
        Estimate(int(s) + 1, p + 5.0, Source.DETECTED, 2, 0.1)
        for s, p in zip(est_stamps[:9], seen[:9], strict=True)
    ]
    bias = fit_bias(dets, truth)
    assert bias.along_ray_m == pytest.approx(0.2, abs=0.02)
    assert bias.z_m == pytest.approx(0.15, abs=0.02)
    corrected = apply_bias(seen, bias)
    assert np.sqrt(np.mean(np.sum((corrected - true_pos) ** 2, 1))) < 0.06


def test_fit_bias_needs_overlapping_detections() -> None:
    truth = [PositionSample(0, np.zeros(3)), PositionSample(50 * MS, np.ones(3))]
    far = [Estimate(10**12, np.ones(3), Source.DETECTED, 3, 0.1)]
    with pytest.raises(CldetError, match="only 0 detected"):
        fit_bias(far, truth)
    with pytest.raises(CldetError, match="no ground truth"):
        fit_bias(far, [])
    wrong = [Estimate(k * 10 * MS, np.full(3, 7.0), Source.DETECTED, 3, 0.1) for k in range(5)]
    with pytest.raises(CldetError, match="within 1.0 m"):
        fit_bias(wrong, truth)


def test_detection_pairs_interpolate_inside_the_truth_and_skip_wide_gaps() -> None:
    from cldet.core.bias import detection_pairs

    truth = [
        PositionSample(0, np.array([0.0, 0.0, 10.0])),
        PositionSample(100 * MS, np.array([1.0, 0.0, 10.0])),
        PositionSample(500 * MS, np.array([5.0, 0.0, 10.0])),
    ]
    dets = [
        Estimate(50 * MS, np.array([0.5, 0.1, 10.0]), Source.DETECTED, 3, 0.1),  # interpolated
        Estimate(300 * MS, np.array([3.0, 0.0, 10.0]), Source.DETECTED, 3, 0.1),  # 400 ms gap
        Estimate(500 * MS, np.array([5.0, 0.0, 10.2]), Source.DETECTED, 3, 0.1),  # at a sample
        Estimate(600 * MS, np.array([6.0, 0.0, 10.0]), Source.DETECTED, 3, 0.1),  # outside
        Estimate(60 * MS, np.array([9.0, 9.0, 9.0]), Source.PREDICTED, 0, 1.0),  # not detected
    ]
    positions, true = detection_pairs(dets, truth, max_truth_gap_ns=200 * MS)
    np.testing.assert_allclose(positions, [[0.5, 0.1, 10.0], [5.0, 0.0, 10.2]])
    np.testing.assert_allclose(true, [[0.5, 0.0, 10.0], [5.0, 0.0, 10.0]])
    positions, true = detection_pairs(dets, truth)  # no gap limit: the 300 ms one too
    assert len(positions) == len(true) == 3
    np.testing.assert_allclose(true[1], [3.0, 0.0, 10.0])
    empty, none = detection_pairs(dets, [])
    assert empty.shape == none.shape == (0, 3)
