"""Tests of the exact grid DBSCAN: properties, and equality with scikit-learn."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from sklearn.cluster import DBSCAN

from cldet.core.clustering import cluster_points, summarize_clusters


def _partition(labels: np.ndarray) -> set[frozenset[int]]:
    """The clusters as sets of point indices (noise excluded): independent of cluster naming."""
    return {frozenset(np.flatnonzero(labels == c).tolist()) for c in set(labels.tolist()) if c >= 0}


coords = st.floats(-6.0, 6.0, allow_nan=False, width=32)
point_sets = arrays(np.float64, st.tuples(st.integers(0, 60), st.just(3)), elements=coords)


@settings(max_examples=60, deadline=None)
@given(
    points=point_sets,
    eps=st.floats(0.2, 3.0),
    min_samples=st.integers(1, 4),
    seed=st.integers(0, 2**31),
)
def test_labels_length_and_order_invariance(
    points: np.ndarray, eps: float, min_samples: int, seed: int
) -> None:
    labels = cluster_points(points, eps, min_samples)
    assert labels.shape == (len(points),) and labels.dtype == np.int32
    if len(points):
        k = labels.max() + 1
        assert set(labels.tolist()) <= set(range(-1, k))
        sizes = np.bincount(labels[labels >= 0], minlength=k)
        assert np.all(np.diff(sizes) <= 0)  # cluster 0 is the largest
    perm = np.random.default_rng(seed).permutation(len(points))
    permuted = cluster_points(points[perm], eps, min_samples)
    back = np.empty_like(permuted)
    back[perm] = permuted
    if min_samples == 1:
        np.testing.assert_array_equal(back, labels)  # even the numbering is order independent
    else:  # border points tied between clusters may move; core points and noise may not
        assert set(np.flatnonzero(back < 0)) == set(np.flatnonzero(labels < 0))


@settings(max_examples=60, deadline=None)
@given(points=point_sets, eps=st.floats(0.2, 3.0))
def test_equals_sklearn_min_samples_1(points: np.ndarray, eps: float) -> None:
    if len(points) == 0:
        return
    ours = cluster_points(points, eps, 1)
    ref = DBSCAN(eps=eps, min_samples=1).fit_predict(points)
    assert _partition(ours) == _partition(ref)


@pytest.mark.parametrize("min_samples", [2, 3, 5])
@pytest.mark.parametrize("seed", range(5))
def test_equals_sklearn_core_points_and_noise(min_samples: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    points = np.concatenate(
        [rng.normal(c, 0.4, (40, 3)) for c in rng.uniform(-8, 8, (4, 3))]
        + [rng.uniform(-10, 10, (60, 3))]
    )
    eps = 0.9
    ours = cluster_points(points, eps, min_samples)
    model = DBSCAN(eps=eps, min_samples=min_samples).fit(points)
    ref = model.labels_
    core = np.zeros(len(points), dtype=bool)
    core[model.core_sample_indices_] = True
    assert set(np.flatnonzero(ours < 0)) == set(np.flatnonzero(ref < 0))
    assert _partition(np.where(core, ours, -1)) == _partition(np.where(core, ref, -1))
    # a border point joins a cluster it is within eps of a core point of
    for i in np.flatnonzero(~core & (ours >= 0)):
        d = np.linalg.norm(points[core & (ours == ours[i])] - points[i], axis=1)
        assert d.min() <= eps


def test_large_random_sets_equal_sklearn() -> None:
    rng = np.random.default_rng(7)
    for n, extent, eps in [(2000, 30.0, 0.7), (600, 3.0, 1.0), (500, 10.0, 1.0)]:
        points = rng.uniform(0, extent, (n, 3))
        ours = cluster_points(points, eps)
        ref = DBSCAN(eps=eps, min_samples=1).fit_predict(points)
        assert _partition(ours) == _partition(ref)


@pytest.mark.parametrize("min_samples", [1, 3])
def test_equals_scipy_pairs_and_components(min_samples: int) -> None:
    """The library reference of benchmarks/bench_libraries.py: cKDTree pairs, graph components.

    The numba grid is kept because it is faster (bench_libraries.py); it must give the same
    partition as the library on a foreground-like cloud (blobs, clutter, speckle).
    """
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_libraries.py"
    spec = importlib.util.spec_from_file_location("bench_libraries", path)
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    points = bench.foreground_cloud(3000, 11)
    ours = cluster_points(points, 1.0, min_samples)
    assert _partition(ours) == _partition(bench.scipy_dbscan(points, 1.0, min_samples))


def test_exact_at_eps_boundary_and_far_coordinates() -> None:
    points = np.array([[0, 0, 0], [1.0, 0, 0], [2.5, 0, 0], [1e5, 1e5, 50], [1e5 + 0.5, 1e5, 50]])
    labels = cluster_points(points, 1.0)
    assert labels[0] == labels[1] != labels[2]  # distance exactly eps joins
    assert labels[3] == labels[4]
    assert len(set(labels.tolist())) == 3


def test_the_mid360_height_spread_follows_each_points_label_in_any_order() -> None:
    # labels out of order; cluster 0 holds one Mid-360 point (spread 0) and one Avia point,
    # cluster 1 two Mid-360 points 0.4 m apart in z (about 100 m up) and an Avia point far off
    points = np.array(
        [[5, 0, 100.0], [0, 0, 1.0], [5, 0, 100.4], [9, 9, 3.0], [0, 0, 2.0], [5, 0, 90.0]]
    )
    labels = np.array([1, 0, 1, 2, 0, 1], dtype=np.int32)
    clusters = summarize_clusters(points, labels, n_mid360=4)
    assert [c.n_mid360 for c in clusters] == [1, 2, 1]
    assert clusters[0].mid360_z_ss == 0.0 and clusters[2].mid360_z_ss == 0.0
    assert clusters[1].mid360_z_ss == pytest.approx(2 * 0.2**2, rel=1e-9)


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="eps_m"):
        cluster_points(np.zeros((2, 3)), 0.0)
    with pytest.raises(ValueError, match="min_samples"):
        cluster_points(np.zeros((2, 3)), 1.0, 0)


def test_summarize_clusters() -> None:
    points = np.array([[0, 0, 0], [0, 0, 1], [0, 1, 0], [10, 10, 10], [50, 0, 0]], dtype=np.float32)
    labels = cluster_points(points, 1.5)
    clusters = summarize_clusters(points, labels, n_mid360=2)
    assert [c.cluster_id for c in clusters] == [0, 1, 2]
    big = clusters[0]
    assert big.n_points == 3 and big.n_mid360 == 2 and big.n_avia == 1
    np.testing.assert_allclose(big.centroid, [0, 1 / 3, 1 / 3])
    np.testing.assert_allclose(big.lower, [0, 0, 0])
    np.testing.assert_allclose(big.upper, [0, 1, 1])
    # the vertical spread counts the Mid-360's points only (z 0 and 1 about 0.5), not the Avia's
    assert big.mid360_z_ss == pytest.approx(0.5)
    assert [c.mid360_z_ss for c in clusters[1:]] == [0.0, 0.0]
    assert sum(c.n_points for c in clusters) == 5
    assert summarize_clusters(np.zeros((0, 3)), np.zeros(0, dtype=np.int32)) == ()
