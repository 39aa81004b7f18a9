"""Tests of cldet.core.trajectory: interpolation inside, the track's own motion outside."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cldet.core.trajectory import evaluate_trajectory

EPOCH_NS = 1_713_163_000_123_456_000  # a test-split epoch with microseconds
V = np.array([1.5, -0.75, 0.25])  # m/s
P0 = np.array([3.0, -9.0, 30.0])  # m


def line(stamps_ns: np.ndarray) -> np.ndarray:
    """A straight-line flight at constant velocity V through P0 at EPOCH_NS."""
    t = (stamps_ns - EPOCH_NS).astype(np.float64) / 1e9
    return P0 + t[:, None] * V


def test_straight_line_is_exact_inside_and_outside() -> None:
    stamps = EPOCH_NS + np.arange(0, 5_000_000_000, 100_000_000, dtype=np.int64)  # 10 Hz, 5 s
    query = EPOCH_NS + np.array(
        [
            -3_000_000_000,
            -1,
            0,
            50_000_000,
            2_345_678_000,
            4_900_000_000,
            4_900_000_001,
            12_000_000_000,
        ],
        dtype=np.int64,
    )
    got = evaluate_trajectory(stamps, line(stamps), query)
    np.testing.assert_allclose(got, line(query), atol=1e-9)


def test_interpolation_between_two_samples_is_linear() -> None:
    stamps = np.array([EPOCH_NS, EPOCH_NS + 2_000_000_000])
    positions = np.array([[0.0, 0.0, 0.0], [2.0, 4.0, -6.0]])
    got = evaluate_trajectory(stamps, positions, np.array([EPOCH_NS + 500_000_000]))
    np.testing.assert_allclose(got, [[0.5, 1.0, -1.5]])


def test_extrapolation_uses_only_the_window_at_each_end() -> None:
    # Fast motion at the start, slow at the end: each end keeps its own velocity.
    t_s = np.arange(0.0, 10.01, 0.1)
    x = np.where(t_s < 5.0, 4.0 * t_s, 20.0 + 0.5 * (t_s - 5.0))
    positions = np.stack([x, np.zeros_like(x), np.full_like(x, 10.0)], axis=1)
    stamps = EPOCH_NS + np.round(t_s * 1e9).astype(np.int64)
    query = np.array([EPOCH_NS - 2_000_000_000, stamps[-1] + 2_000_000_000])
    got = evaluate_trajectory(stamps, positions, query)
    np.testing.assert_allclose(got[0], [-8.0, 0.0, 10.0], atol=1e-9)  # 4 m/s backwards
    np.testing.assert_allclose(got[1], [x[-1] + 1.0, 0.0, 10.0], atol=1e-9)  # 0.5 m/s


def test_least_squares_velocity_averages_noise() -> None:
    rng = np.random.default_rng(0)
    stamps = EPOCH_NS + np.arange(0, 3_000_000_000, 50_000_000, dtype=np.int64)
    noisy = line(stamps) + rng.normal(0.0, 0.005, (stamps.size, 3))
    query = np.array([stamps[-1] + 1_000_000_000])
    got = evaluate_trajectory(stamps, noisy, query)
    # Anchored at the last (noisy) sample, moved by the fitted velocity: within a few cm.
    np.testing.assert_allclose(got[0], noisy[-1] + V, atol=0.05)


def test_single_sample_is_held() -> None:
    got = evaluate_trajectory(
        np.array([EPOCH_NS]),
        np.array([[1.0, 2.0, 3.0]]),
        EPOCH_NS + np.array([-(10**9), 0, 10**10]),
    )
    np.testing.assert_array_equal(got, np.tile([1.0, 2.0, 3.0], (3, 1)))


def test_window_with_one_sample_still_uses_its_neighbour() -> None:
    stamps = np.array([EPOCH_NS, EPOCH_NS + 5_000_000_000])  # 5 s apart, window 1 s
    positions = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]])
    got = evaluate_trajectory(stamps, positions, np.array([EPOCH_NS + 6_000_000_000]))
    np.testing.assert_allclose(got, [[6.0, 0.0, 0.0]])


def test_max_extrapolation_holds_beyond_the_limit() -> None:
    stamps = EPOCH_NS + np.arange(0, 2_000_000_000, 100_000_000, dtype=np.int64)
    query = np.array([stamps[-1] + 500_000_000, stamps[-1] + 9_000_000_000, EPOCH_NS - 10**10])
    got = evaluate_trajectory(stamps, line(stamps), query, max_extrapolation_ns=1_000_000_000)
    np.testing.assert_allclose(got[0], line(query[:1])[0], atol=1e-9)
    np.testing.assert_allclose(got[1], line(np.array([stamps[-1] + 10**9]))[0], atol=1e-9)
    np.testing.assert_allclose(got[2], line(np.array([EPOCH_NS - 10**9]))[0], atol=1e-9)


def test_unsorted_and_duplicate_stamps() -> None:
    stamps = np.array([EPOCH_NS + 10**9, EPOCH_NS, EPOCH_NS + 10**9])
    positions = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [3.0, 0.0, 0.0]])  # dup -> mean 2
    got = evaluate_trajectory(stamps, positions, np.array([EPOCH_NS + 500_000_000]))
    np.testing.assert_allclose(got, [[1.0, 0.0, 0.0]])


def test_empty_query_gives_empty_result() -> None:
    got = evaluate_trajectory(np.array([EPOCH_NS]), np.zeros((1, 3)), np.array([], dtype=np.int64))
    assert got.shape == (0, 3)


@pytest.mark.parametrize(
    ("stamps", "positions", "query", "match"),
    [
        (np.array([], dtype=np.int64), np.zeros((0, 3)), np.array([0]), "non-empty"),
        (np.array([0, 1]), np.zeros((3, 3)), np.array([0]), r"shape \(2, 3\)"),
        (np.array([0, 1]), np.array([[0, 0, 0], [np.nan, 0, 0]]), np.array([0]), "finite"),
        (np.array([0.0, 1.0]), np.zeros((2, 3)), np.array([0]), "integer nanoseconds"),
    ],
)
def test_bad_input_raises(
    stamps: np.ndarray, positions: np.ndarray, query: np.ndarray, match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        evaluate_trajectory(stamps, positions, query)


@settings(max_examples=60, deadline=None)
@given(
    offsets=st.lists(st.integers(0, 30_000_000_000), min_size=1, max_size=30, unique=True),
    queries=st.lists(st.integers(-60_000_000_000, 90_000_000_000), min_size=0, max_size=30),
    seed=st.integers(0, 2**31 - 1),
)
def test_property_finite_shape_and_samples_reproduced(
    offsets: list[int], queries: list[int], seed: int
) -> None:
    rng = np.random.default_rng(seed)
    stamps = EPOCH_NS + np.array(offsets, dtype=np.int64)
    positions = rng.uniform(-100.0, 100.0, (len(offsets), 3))
    query = EPOCH_NS + np.array(queries, dtype=np.int64)
    got = evaluate_trajectory(stamps, positions, query)
    assert got.shape == (len(queries), 3)
    assert np.all(np.isfinite(got))
    # At its own stamps the trajectory returns its own samples.
    np.testing.assert_allclose(evaluate_trajectory(stamps, positions, stamps), positions, atol=1e-9)
    # Inside the span the result stays within the samples' bounding box.
    inside = (query >= stamps.min()) & (query <= stamps.max())
    assert np.all(got[inside] >= positions.min(axis=0) - 1e-9)
    assert np.all(got[inside] <= positions.max(axis=0) + 1e-9)


def test_trajectory_errors_are_distances_to_the_reference_at_each_stamp() -> None:
    from cldet.core.trajectory import rms, trajectory_errors

    ref_ns = EPOCH_NS + np.arange(0, 5) * 100_000_000
    query = EPOCH_NS + np.array([50_000_000, 250_000_000, 700_000_000])  # the last one outside
    offset = np.array([0.3, 0.0, 0.4])  # 0.5 m
    errors = trajectory_errors(query, line(query) + offset, ref_ns, line(ref_ns))
    np.testing.assert_allclose(errors, 0.5, atol=1e-9)
    assert trajectory_errors([], np.zeros((0, 3)), ref_ns, line(ref_ns)).shape == (0,)
    assert rms([3.0, 4.0]) == pytest.approx(np.sqrt(12.5))
    assert np.isnan(rms([]))
