"""Tests of cldet.explore: the notebooks' helpers, on small hand-made and simulated inputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cldet import explore
from cldet.config import CldetConfig
from cldet.core.background import FOREGROUND
from cldet.core.estimator import fuse_points
from cldet.core.methods import estimate_sequence
from cldet.simulate import SequenceTruth, simulate_sequence
from cldet.stamps import format_stamp
from cldet.types import Estimate, LidarFrame, Source
from converters.mmaud import find_sequences

RNG = np.random.default_rng(7)


def _frame(stamp_ns: int, mid: np.ndarray, avia: np.ndarray | None = None) -> LidarFrame:
    avia_pts = np.zeros((0, 3), np.float32) if avia is None else avia.astype(np.float32)
    return LidarFrame(
        stamp_ns=stamp_ns,
        mid360=mid.astype(np.float32),
        avia=avia_pts,
        avia_stamp_ns=None if avia is None else stamp_ns + 14_000_000,
    )


def _blobs(centres: list[tuple[float, float, float]], n: int, sigma: float) -> np.ndarray:
    return np.concatenate([np.asarray(c) + RNG.normal(0, sigma, (n, 3)) for c in centres])


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, SequenceTruth]:
    """One short simulated train sequence (with ground_truth/) under ROOT/train/seq0001."""
    root = tmp_path_factory.mktemp("sim")
    truth = simulate_sequence(
        root / "train" / "seq0001", seed=11, duration_s=2.0, scenario="close_pass", images=False
    )
    return root, truth


# --------------------------------------------------------------------------- data access


def test_sequence_frames_is_reiterable_and_matches_the_files(
    simulated: tuple[Path, SequenceTruth],
) -> None:
    root, truth = simulated
    (seq,) = find_sequences(root)
    frames = explore.sequence_frames(seq)
    stamps = [f.stamp_ns for f in frames()]
    assert stamps == [f.stamp_ns for f in frames()]  # a fresh stream each call
    assert stamps == truth.lidar_stamps_ns.tolist()
    assert any(f.avia_stamp_ns is not None for f in frames())


def test_load_truth_from_the_ground_truth_folder(simulated: tuple[Path, SequenceTruth]) -> None:
    root, truth = simulated
    (seq,) = find_sequences(root)
    found = explore.load_truth(seq, root)
    assert found is not None and found.kind == "ground truth"
    np.testing.assert_array_equal(found.stamps_ns, truth.gt_stamps_ns)
    np.testing.assert_allclose(found.positions, truth.gt_positions)


def test_load_truth_from_csv_reference_or_nothing(tmp_path: Path) -> None:
    seq_dir = tmp_path / "val" / "seq0002"
    truth = simulate_sequence(seq_dir, seed=3, duration_s=1.0, labels=False, images=False)
    (seq,) = find_sequences(tmp_path)
    assert explore.load_truth(seq) is None

    # a reference track, as the real sample ships one
    ref = tmp_path / "reference" / "seq0002"
    ref.mkdir(parents=True)
    for stamp, pos in zip(truth.gt_stamps_ns[:5], truth.gt_positions[:5], strict=True):
        np.save(ref / f"{format_stamp(int(stamp))}.npy", pos)
    found = explore.load_truth(seq, tmp_path)
    assert found is not None and found.kind == "reference estimate"
    assert len(found.stamps_ns) == 5

    # the split's truth CSV wins over a reference track; other sequences' rows are ignored
    rows = [
        f"seq2,{format_stamp(int(s))},{p[0]},{p[1]},{p[2]},1"
        for s, p in zip(truth.gt_stamps_ns, truth.gt_positions, strict=True)
    ]
    rows.append(f"seq0009,{format_stamp(int(truth.gt_stamps_ns[0]))},0,0,0,1")
    (tmp_path / "val_truth.csv").write_text("Sequence,Timestamp,x,y,z,class\n" + "\n".join(rows))
    found = explore.load_truth(seq, tmp_path)
    assert found is not None and found.kind == "ground truth"
    np.testing.assert_array_equal(found.stamps_ns, truth.gt_stamps_ns)
    np.testing.assert_allclose(found.positions, truth.gt_positions, atol=1e-6)


def test_truth_at_interpolates() -> None:
    truth = explore.Truth(
        "ground truth", np.array([0, 1_000_000_000]), np.array([[0.0, 0, 0], [2.0, 0, 0]])
    )
    np.testing.assert_allclose(explore.truth_at(truth, [500_000_000]), [[1.0, 0, 0]])


def test_load_truth_real_sample(real_sample: Path) -> None:
    with pytest.warns(UserWarning, match="not a split"):  # reference/ sits next to val/
        (seq,) = find_sequences(real_sample, splits=["val"])
    found = explore.load_truth(seq, real_sample)
    assert found is not None and found.kind == "reference estimate"
    assert len(found.stamps_ns) == 76
    stats = explore.frame_statistics(explore.sequence_frames(seq)())
    assert len(stats.stamps_ns) == 88
    assert 3000 < np.median(stats.mid360_points) < 6000
    assert 0.3 < stats.avia_empty_fraction < 0.6  # 39 of 88 Avia frames are all zero


# --------------------------------------------------------------------------- sensors


def test_frame_statistics_counts_valid_points() -> None:
    mid = np.array([[1.0, 0, 0], [0, 0, 0], [0, 2, 0], [np.nan, 0, 0]])
    frames = [_frame(0, mid, np.array([[0, 0, 5.0]])), _frame(100_000_000, mid)]
    stats = explore.frame_statistics(frames)
    np.testing.assert_array_equal(stats.mid360_points, [2, 2])
    np.testing.assert_array_equal(stats.avia_points, [1, 0])
    np.testing.assert_array_equal(stats.avia_paired, [True, False])
    assert stats.avia_empty_fraction == 0.5
    assert explore.frame_statistics([]).avia_empty_fraction == 0.0


def test_elevation_deg_and_coverage() -> None:
    pts = np.array([[1.0, 0, 0], [0, 1, 1], [0, 0, 3], [1, 0, -1]])
    np.testing.assert_allclose(explore.elevation_deg(pts), [0, 45, 90, -45])
    frames = [_frame(0, pts[:2], pts[2:3]), _frame(1, pts[3:])]
    mid, avia = explore.elevation_coverage(frames, [-90, -10, 10, 60, 90.01])
    np.testing.assert_allclose(mid, [0.5, 0.5, 0.5, 0])
    np.testing.assert_allclose(avia, [0, 0, 0, 0.5])
    none = explore.elevation_coverage([], [0, 1])
    np.testing.assert_array_equal(none[0], [0])


def test_truth_histograms_cover_every_position() -> None:
    pos = RNG.normal([1, -10, 30], [5, 5, 10], (500, 3))
    h = explore.truth_histograms(pos, axis_bin_m=2.0, xy_cell_m=4.0)
    for a in range(3):
        assert h.axis_counts[a].sum() == 500
        assert h.axis_edges[a][0] <= pos[:, a].min() and h.axis_edges[a][-1] > pos[:, a].max()
        np.testing.assert_allclose(np.diff(h.axis_edges[a]), 2.0)
    assert h.xy_counts.sum() == 500
    assert h.xy_counts.shape == (len(h.x_edges) - 1, len(h.y_edges) - 1)
    np.testing.assert_allclose(h.mean, pos.mean(axis=0))
    with pytest.raises(ValueError, match="no position"):
        explore.truth_histograms(np.zeros((0, 3)))
    with pytest.raises(ValueError, match="finite"):
        explore.truth_histograms([[np.nan, 0, 0]])
    with pytest.raises(ValueError, match="bin sizes"):
        explore.truth_histograms(pos, axis_bin_m=0)


def test_background_split_matches_the_model(simulated: tuple[Path, SequenceTruth]) -> None:
    root, truth = simulated
    (seq,) = find_sequences(root)
    frames = explore.sequence_frames(seq)
    cfg = CldetConfig()
    model = explore.learn_background(frames(), cfg)
    assert model.n_frames == len(truth.lidar_stamps_ns)
    total_fg = 0
    for frame in frames():
        points, fg, n_mid = explore.split_environment(frame, model, cfg)
        fused, n_fused = fuse_points(frame, cfg)
        np.testing.assert_array_equal(points, fused)
        assert n_mid == n_fused
        np.testing.assert_array_equal(fg, model.classify(points) == FOREGROUND)
        total_fg += int(fg.sum())
    all_points = sum(len(fuse_points(f, cfg)[0]) for f in frames())
    assert 0 < total_fg < 0.05 * all_points  # most points are environment


# --------------------------------------------------------------------------- K-Means


def test_kmeans_elbow_finds_three_blobs() -> None:
    pts = _blobs([(0, 0, 0), (10, 0, 0), (0, 10, 5)], 40, 0.3)
    ks = list(range(2, 9))
    inertia = explore.kmeans_elbow(pts, ks)
    assert inertia.shape == (len(ks),)
    assert np.all(np.diff(inertia) <= 1e-9)
    assert explore.elbow_k(ks, inertia) == 3
    with pytest.raises(ValueError, match="cannot form"):
        explore.kmeans_elbow(pts[:5], ks)


def test_elbow_k_edge_cases() -> None:
    assert explore.elbow_k([2, 3, 4], [5.0, 5.0, 5.0]) in (2, 3, 4)
    with pytest.raises(ValueError, match=">= 3"):
        explore.elbow_k([2, 3], [2.0, 1.0])


def test_kmeans_stability_on_clear_blobs() -> None:
    pts = _blobs([(0, 0, 0), (20, 0, 0), (0, 20, 0)], 30, 0.2)
    stab = explore.kmeans_stability(pts, 3, range(6), init="k-means++")
    assert stab.centres.shape == (6, 3, 3)
    assert stab.inertias.shape == (6,)
    assert stab.centre_shift_m.min() == pytest.approx(0.0, abs=1e-9)
    assert stab.inertia_spread >= 0
    rand = explore.kmeans_stability(pts, 3, range(6), init="random")
    assert rand.init == "random"
    with pytest.raises(ValueError, match="cannot form"):
        explore.kmeans_stability(pts[:2], 3, [0])
    with pytest.raises(ValueError, match="seed"):
        explore.kmeans_stability(pts, 3, [])


# --------------------------------------------------------------------------- DBSCAN sweep


def test_dbscan_sweep_largest_vs_nearest() -> None:
    drone = np.array([[10.0, 0, 5], [10.2, 0, 5], [10.1, 0.1, 5]])
    person = _blobs([(0, 8, -0.5)], 12, 0.1)
    frames = [np.concatenate([drone, person]), np.zeros((0, 3)), drone]
    truth = np.tile([10.1, 0.0, 5.0], (3, 1))
    sweep = explore.dbscan_sweep(frames, truth, [0.5, 1.0], [1, 5])
    assert sweep.nearest_error_m.shape == (2, 2, 3)
    # frame 0: the drone is the nearest cluster, the person the largest
    assert sweep.nearest_error_m[0, 0, 0] < 0.1
    assert sweep.largest_error_m[0, 0, 0] > 5
    # min_samples 5: the 3-point drone is noise, only the person remains
    assert sweep.nearest_error_m[0, 1, 0] > 5
    assert sweep.n_clusters[0, 1, 2] == 0 and np.isnan(sweep.largest_error_m[0, 1, 2])
    # frame 1 has no point: a miss everywhere
    assert np.all(sweep.n_clusters[:, :, 1] == 0)
    np.testing.assert_allclose(sweep.miss_rate(), [[1 / 3, 2 / 3], [1 / 3, 2 / 3]])
    np.testing.assert_allclose(sweep.hit_rate("nearest"), [[2 / 3, 0], [2 / 3, 0]])
    np.testing.assert_allclose(sweep.hit_rate("largest"), [[1 / 3, 0], [1 / 3, 0]])
    assert sweep.median_error("nearest")[0, 0] < 0.1
    eps, ms, hit, med = sweep.best("nearest")
    assert (eps, ms) == (0.5, 1) and hit == pytest.approx(2 / 3) and med < 0.1
    with pytest.raises(ValueError, match="unknown pick"):
        sweep.median_error("smallest")
    with pytest.raises(ValueError, match="one truth row per frame"):
        explore.dbscan_sweep(frames, truth[:2], [1.0], [1])


def test_dbscan_sweep_all_missing_gives_nan_median() -> None:
    sweep = explore.dbscan_sweep([np.zeros((0, 3))], [[0.0, 0, 0]], [1.0], [1])
    assert np.isnan(sweep.median_error()[0, 0])
    assert sweep.best()[:2] == (1.0, 1)


# --------------------------------------------------------------------------- errors


def test_estimate_errors_and_sources() -> None:
    truth = explore.Truth(
        "ground truth", np.array([0, 400_000_000]), np.array([[0.0, 0, 0], [4.0, 0, 0]])
    )
    sources = [Source.DETECTED, Source.DETECTED, Source.SMOOTHED, Source.PREDICTED]
    estimates = [
        Estimate(k * 100_000_000, np.array([float(k), 0, d]), s, 1, 0.1)
        for k, (s, d) in enumerate(zip(sources, [0.0, 0.0, 3.0, 4.0], strict=True))
    ]
    series = explore.estimate_errors("track", estimates, truth)
    np.testing.assert_allclose(series.error_m, [0, 0, 3, 4])
    np.testing.assert_allclose(series.t_s, [0, 0.1, 0.2, 0.3])
    assert series.rms_m == pytest.approx(np.sqrt(25 / 4))
    assert explore.error_by_source(series) == {
        "detected": (2, 0.0),
        "predicted": (1, 4.0),
        "smoothed": (1, 3.0),
    }
    assert explore.source_runs(series.source) == [(0, 2, 1), (2, 3, 3), (3, 4, 2)]
    assert explore.source_runs([]) == []
    empty = explore.estimate_errors("x", [], truth)
    assert len(empty.error_m) == 0 and np.isnan(empty.rms_m)


def test_estimate_errors_on_a_simulated_run(simulated: tuple[Path, SequenceTruth]) -> None:
    root, _ = simulated
    (seq,) = find_sequences(root)
    truth = explore.load_truth(seq, root)
    assert truth is not None
    _, result = estimate_sequence(explore.sequence_frames(seq), CldetConfig())
    series = explore.estimate_errors("track", result.estimates, truth)
    assert len(series.error_m) == len(result.estimates)
    assert np.all(np.isfinite(series.error_m))
    assert sum(n for n, _ in explore.error_by_source(series).values()) == len(series.error_m)
