"""End-to-end tests of the estimator on simulated sequences (held-out seeds) and the real sample.

Seeds 0-4 were used to develop the method (200-202 were looked at once); these tests use
seeds 300-302. Errors are 3D
distances to the ground truth (body centre + prism) interpolated at the Mid-360 stamps, with the
default (zero) bias correction, so they include the LiDAR's near-face bias (~0.2-0.3 m).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from cldet.config import CldetConfig, load_config
from cldet.core.bias import fit_bias_sequences
from cldet.core.estimator import (
    FrameDetections,
    SequenceEstimate,
    TrackEstimator,
    _Evidence,
    fuse_points,
    fuse_timed,
)
from cldet.core.frames import pair_frames, valid_points
from cldet.core.methods import estimate_sequence, make_estimator
from cldet.core.tracking import ClusterTable, TrackRecord
from cldet.errors import FrameOrderError
from cldet.types import Cluster, Estimate, LidarFrame, PositionSample, Source

simulate = pytest.importorskip("cldet.simulate")
mmaud = pytest.importorskip("converters.mmaud")

DURATION_S = 6.0
HELD_OUT = (300, 301, 302)


@dataclass(frozen=True)
class Simulated:
    frames: list[LidarFrame]
    truth: list[PositionSample]
    visible: np.ndarray  # (N,) drone points in the Mid-360 frame + paired Avia frame


_CACHE: dict[tuple[str, int], Simulated] = {}


def _simulated(root: Path, scenario: str, seed: int) -> Simulated:
    key = (scenario, seed)
    if key not in _CACHE:
        seq_dir = root / f"{scenario}_{seed}" / "train" / "seq0001"
        info = simulate.simulate_sequence(
            seq_dir, seed=seed, duration_s=DURATION_S, scenario=scenario, images=False
        )
        (seq,) = mmaud.find_sequences(seq_dir.parents[1])
        frames = list(
            pair_frames(mmaud.iter_clouds(seq, "lidar_360"), mmaud.iter_clouds(seq, "livox_avia"))
        )
        truth = list(mmaud.iter_ground_truth(seq))
        avia_pts = dict(
            zip(info.avia_stamps_ns.tolist(), info.avia_drone_points.tolist(), strict=True)
        )
        mid_pts = dict(
            zip(info.lidar_stamps_ns.tolist(), info.mid360_drone_points.tolist(), strict=True)
        )
        visible = np.array(
            [mid_pts.get(f.stamp_ns, 0) + avia_pts.get(f.avia_stamp_ns or -1, 0) for f in frames]
        )
        _CACHE[key] = Simulated(frames, truth, visible)
    return _CACHE[key]


@pytest.fixture(scope="module")
def sim_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("sim")


def _errors(result: SequenceEstimate, truth: list[PositionSample]) -> np.ndarray:
    gs = np.array([g.stamp_ns for g in truth])
    gp = np.array([g.position for g in truth])
    st = np.array([e.stamp_ns for e in result.estimates])
    pos = np.array([e.position for e in result.estimates])
    at = np.stack([np.interp(st, gs, gp[:, d]) for d in range(3)], axis=1)
    return np.linalg.norm(pos - at, axis=1)


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e**2)))


_RUNS: dict[tuple[int, str, str], tuple[list[FrameDetections], SequenceEstimate]] = {}


def _run(
    sim: Simulated, method: str = "track", **over: object
) -> tuple[list[FrameDetections], SequenceEstimate]:
    """One estimator run, remembered: several tests score the same sequence with the same config
    (the estimator is deterministic, its results frozen; the determinism test runs it afresh)."""
    key = (id(sim), method, repr(sorted(over.items())))
    if key not in _RUNS:
        config = load_config(overrides={"method": method, **over})
        _RUNS[key] = estimate_sequence(lambda: sim.frames, config)
    return _RUNS[key]


@pytest.mark.slow
@pytest.mark.parametrize(
    "scenario",
    [
        "mixed",
        "close_pass",
        "hover",
        "avia_only",
        "person",
        "bird",
    ],
)
def test_track_is_accurate_and_far_better_than_cldet(sim_root: Path, scenario: str) -> None:
    track_rms, cldet_rms = [], []
    for seed in HELD_OUT:
        sim = _simulated(sim_root, scenario, seed)
        _, tr = _run(sim)
        _, cl = _run(sim, "cl-det")
        track_rms.append(_rms(_errors(tr, sim.truth)))
        cldet_rms.append(_rms(_errors(cl, sim.truth)))
    # the median sequence: within the LiDAR's near-face bias (no bias correction) of the truth
    assert np.median(track_rms) < 0.5, (track_rms, cldet_rms)
    # far better on average (at 2-4 m cl-det's largest cluster is often the drone too)
    assert np.mean(track_rms) * 3 < np.mean(cldet_rms), (track_rms, cldet_rms)
    for t, c in zip(track_rms, cldet_rms, strict=True):
        assert t < max(c, 1.0), (track_rms, cldet_rms)


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["person", "bird"])
def test_distractors_do_not_pull_the_track_off_the_drone(sim_root: Path, scenario: str) -> None:
    for seed in HELD_OUT:
        sim = _simulated(sim_root, scenario, seed)
        _, result = _run(sim)
        err = _errors(result, sim.truth)
        seen = sim.visible > 0
        if seen.sum() < 10:
            continue  # the drone is (nearly) invisible: nothing to hold on to
        assert np.mean(err[seen] < 1.0) > 0.9, (seed, np.round(err, 2))


@pytest.mark.slow
def test_hovering_drone_is_not_erased(sim_root: Path) -> None:
    for seed in HELD_OUT:
        sim = _simulated(sim_root, "hover", seed)
        _, result = _run(sim)
        err = _errors(result, sim.truth)
        detected = np.array([e.source == Source.DETECTED for e in result.estimates])
        seen = sim.visible > 0
        assert np.mean(detected[seen]) > 0.8, seed
        assert np.mean(err[seen] < 0.5) > 0.9, (seed, np.round(err, 2))
        # ... whereas without the floating-blob rule and the raw-point gate it is lost
        _, blind = _run(sim, background={"floating_max_size_m": 0.0}, tracking={"raw_gate_m": 0.0})
        blind_detected = np.array([e.source == Source.DETECTED for e in blind.estimates])
        assert np.mean(blind_detected[seen]) < np.mean(detected[seen])


@pytest.mark.slow
def test_avia_only_phases_are_tracked(sim_root: Path) -> None:
    for seed in HELD_OUT:
        sim = _simulated(sim_root, "avia_only", seed)
        assert all(f.mid360 is not None for f in sim.frames)
        _, result = _run(sim)
        err = _errors(result, sim.truth)
        detected = np.array([e.source == Source.DETECTED for e in result.estimates])
        seen = sim.visible > 0
        assert np.mean(detected[seen]) > 0.7, seed
        assert _rms(err) < 0.5, (seed, np.round(err, 2))


@pytest.mark.slow
def test_bias_fitted_on_training_seeds_helps_on_held_out(sim_root: Path) -> None:
    pairs = []
    for scenario in ("mixed", "close_pass", "hover"):
        for seed in (0, 1):  # "training" sequences
            sim = _simulated(sim_root, scenario, seed)
            pairs.append((_run(sim)[1].estimates, sim.truth))
    bias = fit_bias_sequences(pairs)
    # the near face is nearer the sensor, the prism above the body: both push outwards / up
    assert 0.0 < bias.z_m < 0.6 and -0.3 < bias.along_ray_m < 0.5, bias
    before, after = [], []
    for scenario in ("mixed", "close_pass"):
        for seed in HELD_OUT:
            sim = _simulated(sim_root, scenario, seed)
            before.append(_rms(_errors(_run(sim)[1], sim.truth)))
            after.append(_rms(_errors(_run(sim, bias=bias.model_dump())[1], sim.truth)))
    assert np.median(after) < np.median(before), (before, after)
    assert np.median(after) < 0.3, (before, after)


@pytest.mark.slow
def test_frame_detections_and_sequence_estimate_contract(sim_root: Path) -> None:
    sim = _simulated(sim_root, "person", HELD_OUT[0])
    cfg = load_config()
    dets, result = estimate_sequence(lambda: sim.frames, cfg)
    assert len(dets) == len(result.estimates) == len(sim.frames)
    stamps = [e.stamp_ns for e in result.estimates]
    assert stamps == [f.stamp_ns for f in sim.frames]
    for frame, det in zip(sim.frames, dets, strict=True):
        assert det.stamp_ns == frame.stamp_ns
        assert det.labels.shape == (len(det.foreground),)
        assert det.foreground.dtype == np.float32 and det.foreground.shape[1:] == (3,)
        fused, _ = fuse_points(frame, cfg)
        if len(det.foreground):  # foreground is a subset of the frame's points
            d = np.min(np.linalg.norm(det.foreground[:, None] - fused[None], axis=2), axis=1)
            assert d.max() == 0.0
        assert [c.cluster_id for c in det.clusters] == list(range(len(det.clusters)))
        assert sum(c.n_points for c in det.clusters) == int((det.labels >= 0).sum())
    by_stamp = {d.stamp_ns: d for d in dets}
    for stamp, cid in result.chosen.items():
        assert 0 <= cid < len(by_stamp[stamp].clusters)
    for e in result.estimates:
        assert e.position.shape == (3,) and np.all(np.isfinite(e.position))
        assert np.isfinite(e.sigma_m) and e.sigma_m >= 0
        assert e.source in (Source.DETECTED, Source.PREDICTED, Source.SMOOTHED)
        assert (e.n_points > 0) == (e.source == Source.DETECTED)
    assert [ev.stamp_ns for ev in result.events] == sorted(ev.stamp_ns for ev in result.events)
    assert result.events[0].kind in ("acquired", "predicted")
    # deterministic
    _, again = estimate_sequence(lambda: sim.frames, cfg)
    assert [e.position.tolist() for e in again.estimates] == [
        e.position.tolist() for e in result.estimates
    ]


def test_empty_sequence_and_no_candidate() -> None:
    cfg = load_config()
    est = TrackEstimator(cfg)
    assert est.refine().estimates == ()
    # frames with nothing in them: no track at all, the configured fallback, flagged as such
    empty = [
        LidarFrame(k * 100_000_000, np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32))
        for k in range(5)
    ]
    _, result = estimate_sequence(lambda: empty, cfg)
    assert [e.source for e in result.estimates] == [Source.FALLBACK] * 5
    np.testing.assert_allclose(result.estimates[0].position, cfg.tracking.fallback_position)


@pytest.mark.parametrize("method", ["track", "cl-det"])
@pytest.mark.parametrize("second", [100, 200])
def test_frames_out_of_order_or_with_equal_stamps_are_a_clear_error(
    method: str, second: int
) -> None:
    est = make_estimator(load_config(overrides={"method": method}))
    f0 = LidarFrame(200, np.ones((1, 3), np.float32), np.zeros((0, 3), np.float32))
    f1 = LidarFrame(second, np.ones((1, 3), np.float32), np.zeros((0, 3), np.float32))
    est.register_frame(f0)
    with pytest.raises(FrameOrderError, match=f"frame stamped {second} ns .* 200 ns"):
        est.register_frame(f1)


def test_nan_rows_empty_frames_and_a_single_frame_are_handled() -> None:
    cfg = load_config()
    nan = np.array([[np.nan, 1.0, 2.0], [3.0, np.inf, 1.0], [4.0, 1.0, 1.0]], np.float32)
    frames = [
        LidarFrame(0, nan, np.zeros((0, 3), np.float32)),
        LidarFrame(100_000_000, np.zeros((0, 3), np.float32), nan),
    ]
    for seq in (frames, frames[:1]):
        dets, result = estimate_sequence(seq, cfg)
        assert len(dets) == len(result.estimates) == len(result.causal) == len(seq)
        assert all(np.all(np.isfinite(e.position)) for e in result.estimates + result.causal)


@pytest.mark.filterwarnings("ignore:ignoring folders")  # the sample holds reference/ too
def test_real_sample_close_to_the_first_place_estimate(real_sample: Path) -> None:
    (seq,) = mmaud.find_sequences(real_sample, splits=["val"])
    frames = list(
        pair_frames(mmaud.iter_clouds(seq, "lidar_360"), mmaud.iter_clouds(seq, "livox_avia"))
    )
    reference = list(mmaud.iter_positions(real_sample / "reference" / "seq0001"))
    cfg = load_config()
    _, result = estimate_sequence(lambda: frames, cfg)
    warm_up = 3  # 0.2 s of background, then a track needs its second detection
    judged = int(np.ceil(cfg.tracking.causal_judge_s * 10))  # 10 Hz scans before a causal choice
    for estimates, limit, late in ((result.estimates, 0.12, 0), (result.causal, 0.2, judged)):
        stamps = np.array([e.stamp_ns for e in estimates])
        pos = np.array([e.position for e in estimates])
        nearest = [int(np.argmin(np.abs(stamps - r.stamp_ns))) for r in reference]
        # the causal estimate has none during the background's warm-up (its first frames),
        # until a track has gathered tracking.causal_confirm evidence and lived causal_judge_s
        d = [
            np.linalg.norm(pos[i] - r.position)
            for i, r in zip(nearest, reference, strict=True)
            if estimates[i].source != Source.FALLBACK
        ]
        assert len(d) >= len(reference) - 4 - late
        assert _rms(np.asarray(d)) < limit
    assert all(e.source == Source.DETECTED for e in result.estimates[warm_up:])
    confirmed = warm_up + judged + 1  # and causally, judged, then confirmed
    assert all(e.source == Source.DETECTED for e in result.causal[confirmed:])


def test_cldet_without_environment_clusters_every_valid_point(sim_root: Path) -> None:
    sim = _simulated(sim_root, "mixed", HELD_OUT[0])
    frames = sim.frames[:20]
    learned, _ = estimate_sequence(lambda: frames, load_config(overrides={"method": "cl-det"}))
    none, result = estimate_sequence(
        lambda: frames,
        load_config(overrides={"method": "cl-det", "baseline": {"environment": "none"}}),
    )
    for f, det_none, det_learned in zip(frames, none, learned, strict=True):
        n_valid = len(valid_points(f.mid360))
        assert len(det_none.foreground) == n_valid
        assert len(det_learned.foreground) < 0.2 * n_valid
        # the estimate is the mean of the largest cluster over all points
        assert det_none.clusters[0].n_points == max(c.n_points for c in det_none.clusters)
    assert len(result.estimates) == len(frames)


POST = ((5.8, -4.2, -1.5), (6.2, -3.8, 1.0))  # a post in the scene of ``_scene_frames``


def _scene_frames(
    path: list[np.ndarray], seed: int, n_rays: int = 6000, fringe_from: int | None = None
) -> list[LidarFrame]:
    """Mid-360-like scans of the small test scene (ground, wall, a post) with a 0.3 m drone;
    from scan ``fringe_from`` on, three more returns 0.9-1.0 m around it in each scan (spray,
    a flickering edge beside it: its cluster is then wider than a drone)."""
    from tests.core.scene import scan

    rng = np.random.default_rng(seed)
    empty = np.zeros((0, 3), np.float32)
    frames = []
    for k, p in enumerate(path):
        pts = scan(rng, [((*p,), 0.3)], n_rays=n_rays, boxes=[POST])
        if fringe_from is not None and k >= fringe_from:
            u = rng.normal(size=(3, 3))
            u *= rng.uniform(0.9, 1.0, (3, 1)) / np.linalg.norm(u, axis=1, keepdims=True)
            pts = np.concatenate([pts, (p + u).astype(np.float32)])
        frames.append(LidarFrame(k * 100_000_000, pts, empty))
    return frames


def _hover_path(spot: np.ndarray) -> list[np.ndarray]:
    """A flight of 5 m in 1.5 s to ``spot``, then a hover there: 6 s in all."""
    start = spot + np.array([-4.0, -3.0, 0.5])
    return [start + (spot - start) * min(k / 15, 1.0) for k in range(60)]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_drone_that_flies_in_and_hovers_is_protected_from_the_background(seed: int) -> None:
    # it flies 5 m in 1.5 s, then hovers 0.2 m beside the post for 4.5 s: longer than the
    # background needs to learn a static surface, not floating in free space, and inside the
    # post's dilation margin: protection keeps its points out of the background and reclaims
    # the margin around it
    spot = np.array([6.0, -3.3, 0.8])
    frames = _scene_frames(_hover_path(spot), seed)

    def hovering_detected(protect: bool) -> float:
        cfg = load_config(overrides={"background": {"protect_tracks": protect}})
        _, result = estimate_sequence(frames, cfg)
        late = result.causal[-20:]
        near = [np.linalg.norm(e.position - spot) < 0.5 for e in late]
        detected = [e.source == Source.DETECTED for e in late]
        return float(np.mean(np.array(near) & np.array(detected)))

    assert hovering_detected(True) > 0.9
    assert hovering_detected(False) < 0.5


def test_a_protected_drone_stays_protected_when_its_cluster_grows_wider_than_a_drone() -> None:
    # the hover of the test above, with a few returns 0.9-1.0 m around the drone in every scan
    # of it: its cluster is wider than a drone, no confirmed mover by the tracker's test in many
    # of those scans; held protection keeps its points out of the background all the same, and
    # without it the hover is learned (the recurring-range rule: three bins). Not every seed is
    # kept: the drone's returns that fall within the post's margin (CORE) are still learned and
    # can pull the static range forward (seeds 5 and 6 of 1-8 are lost either way)
    spot = np.array([6.0, -3.3, 0.8])
    shares: dict[bool, list[float]] = {True: [], False: []}
    for seed in range(1, 5):
        frames = _scene_frames(_hover_path(spot), seed, n_rays=12000, fringe_from=15)
        on = sum(int(np.sum(np.linalg.norm(f.mid360 - spot, axis=1) < 0.35)) for f in frames[-20:])
        for hold in shares:
            cfg = load_config(overrides={"background": {"protect_hold": hold}})
            dets, _ = estimate_sequence(frames, cfg)
            fg = sum(
                int(np.sum(np.linalg.norm(d.foreground - spot, axis=1) < 0.35)) for d in dets[-20:]
            )
            shares[hold].append(fg / on)
    assert np.mean(shares[True]) > 0.7, shares
    assert np.mean(shares[False]) < 0.1, shares


def test_a_sparse_far_structure_whose_returns_scatter_is_learned_not_protected() -> None:
    # a hedge 25 m away, 10 m wide and 2 m tall, lit in four random places a scan: each of its
    # direction cells is hit in few bins, its clusters' centroids scatter by metres, so the
    # tracker confirms "movers" there; their running mean never moves by a drone's size, so
    # nothing there is protected and the hedge is learned within a second or so, where
    # protecting every confirmed mover keeps it foreground for seconds
    rng = np.random.default_rng(0)
    empty = np.zeros((0, 3), np.float32)
    from tests.core.scene import scan

    def hedge(n: int) -> np.ndarray:
        return np.column_stack(
            [np.full(n, -25.0), rng.uniform(-5.0, 5.0, n), rng.uniform(-0.5, 1.5, n)]
        ).astype(np.float32)

    frames = [
        LidarFrame(k * 100_000_000, np.concatenate([scan(rng, n_rays=3000), hedge(4)]), empty)
        for k in range(80)
    ]

    def hedge_foreground(min_moved_m: float, dense_points: int) -> int:
        bg = {"protect_min_moved_m": min_moved_m, "protect_dense_points": dense_points}
        dets, _ = estimate_sequence(frames, load_config(overrides={"background": bg}))
        return sum(int(np.sum(d.foreground[:, 0] < -24.0)) for d in dets[10:70])

    # one point is "dense" too: every confirmed mover protected, the old rule
    learned, protected = hedge_foreground(1.2, 3), hedge_foreground(0.0, 1)
    assert learned < 0.3 * protected, (learned, protected)


def test_a_cluster_cut_by_the_bottom_of_the_field_of_view_may_reach_the_ground() -> None:
    # the upper body of a person 0.7 m from the sensor: its lowest point lies on the Mid-360's
    # bottom edge (-7.3 deg), 1.4 m above the ground; a drone as high, 9 m away, is not cut
    est = TrackEstimator(load_config())
    rng = np.random.default_rng(0)
    ground = np.column_stack([rng.uniform(-20, 20, (2000, 2)), np.full(2000, -1.5)])
    assert est.background.ground.fit(ground)
    z_cut = np.tan(np.radians(-7.3)) * 0.7 + 0.05
    person = Cluster(
        0, np.array([0.7, 0.0, 0.4]), np.array([0.5, -0.2, z_cut]), np.array([0.9, 0.2, 0.8]), 20
    )
    drone = Cluster(
        1, np.array([9.0, 0.0, 0.0]), np.array([8.8, -0.2, -0.1]), np.array([9.2, 0.2, 0.1]), 6
    )
    heights = est._heights((person, drone))
    np.testing.assert_allclose(heights, [0.0, 1.4], atol=0.05)
    off = TrackEstimator(load_config(overrides={"tracking": {"fov_cut_m": 0.0}}))
    off.background.ground.fit(ground)
    assert off._heights((person, drone))[0] == pytest.approx(z_cut + 1.5, abs=0.05)


def test_from_a_mast_a_cluster_cut_high_above_the_ground_is_no_ground_mover() -> None:
    # a sensor 5 m up: the field's bottom edge passes 3.8 m above the ground 9 m out, higher
    # than anything that moves on the ground reaches; a drone cut there keeps its height
    est = TrackEstimator(load_config())
    rng = np.random.default_rng(1)
    r = np.sqrt(rng.uniform(40.0**2, 80.0**2, 3000))
    az = rng.uniform(-np.pi, np.pi, 3000)
    ground = np.stack([r * np.cos(az), r * np.sin(az), np.full(3000, -5.0)], axis=1)
    assert est.background.ground.fit(ground)
    z_cut = np.tan(np.radians(-7.3)) * 9.0 + 0.05
    drone = Cluster(
        0,
        np.array([9.0, 0.0, z_cut + 0.1]),
        np.array([8.8, -0.2, z_cut]),
        np.array([9.2, 0.2, z_cut + 0.2]),
        4,
    )
    # 30 m out the edge passes 1.2 m up: a person's head and shoulders there may reach down
    z_far = np.tan(np.radians(-7.3)) * 30.0 + 0.05
    person = Cluster(
        1,
        np.array([30.0, 0.0, z_far + 0.3]),
        np.array([29.8, -0.2, z_far]),
        np.array([30.2, 0.2, z_far + 0.6]),
        8,
    )
    heights = est._heights((drone, person))
    np.testing.assert_allclose(heights, [z_cut + 5.0, 0.0], atol=0.05)
    tall = TrackEstimator(load_config(overrides={"tracking": {"ground_mover_max_m": 10.0}}))
    tall.background.ground.fit(ground)
    assert tall._heights((drone, person))[0] == 0.0


def test_a_frame_flooded_with_speckle_gives_at_most_max_clusters() -> None:
    rng = np.random.default_rng(0)
    empty = np.zeros((0, 3), np.float32)
    frames = [
        LidarFrame(k * 100_000_000, rng.uniform(-40, 40, (2000, 3)).astype(np.float32), empty)
        for k in range(4)
    ]
    cfg = load_config(overrides={"clustering": {"max_clusters": 50}})
    dets, result = estimate_sequence(frames, cfg)
    assert max(len(d.clusters) for d in dets) == 50  # speckle is foreground after warm-up
    assert all(int(d.labels.max(initial=-1)) < 50 for d in dets)
    assert len(result.estimates) == 4


def _with_objects(
    seed: int,
    n: int,
    objects: object,
    wall: bool = False,
    n_rays: int = 20000,
    boxes: Sequence[tuple[Sequence[float], Sequence[float]]] = (),
) -> list[LidarFrame]:
    """Scans of the test scene with, per frame k, the spheres ``objects(k)``; no wall unless
    ``wall``, and the extra ``boxes`` (``tests.core.scene.scan``)."""
    from tests.core.scene import scan

    rng = np.random.default_rng(seed)
    empty = np.zeros((0, 3), np.float32)
    return [
        LidarFrame(
            k * 100_000_000,
            scan(rng, objects(k), n_rays=n_rays, wall=wall, boxes=boxes),  # type: ignore[operator]
            empty,
        )
        for k in range(n)
    ]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_rigidly_fixed_floating_object_loses_to_a_sparse_drone(seed: int) -> None:
    # a 0.4 m sign floating 4 m away, 40 deg up, stays foreground (nothing holds it up),
    # returns dozens of points a scan and its mean position never moves by a centimetre; the
    # drone, 35 m out and moving at 4 m/s, returns a point in about one scan of three
    def drone(k: int) -> np.ndarray:
        return np.array([35.0, -16.0 + 0.4 * k, 6.0])

    frames = _with_objects(seed, 80, lambda k: [((3.0, 1.0, 2.5), 0.2), (tuple(drone(k)), 0.2)])
    truth = np.array([drone(k) for k in range(80)])

    def rms(fixed_spread_m: float) -> float:
        # the hand-set factors alone: the learned prior also sinks the sign here
        cfg = load_config(
            overrides={"tracking": {"fixed_spread_m": fixed_spread_m, "prior_scorer": False}}
        )
        _, result = estimate_sequence(frames, cfg)
        return _rms(np.array([e.position for e in result.estimates]) - truth)

    assert rms(0.025) < 1.0
    assert rms(0.0) > 5.0  # the rule is needed here


@pytest.mark.parametrize("seed", [1, 2])
def test_a_rigidly_fixed_object_loses_to_a_drone_hovering_low_all_along(seed: int) -> None:
    # the same sign, and a drone hovering 1.1 m above the ground 6.7 m away the whole time,
    # wandering by 10 cm: low (height weight 0.1) and static (0.6), it holds 0.06 per
    # detection; the sign must weigh less than that per detection, whatever its count
    def drone(k: int) -> np.ndarray:
        return np.array([6.0, 3.0, -0.4]) + 0.1 * np.array([np.sin(0.2 * k), np.cos(0.3 * k), 0])

    frames = _with_objects(seed, 80, lambda k: [((3.0, 1.0, 2.5), 0.2), (tuple(drone(k)), 0.2)])
    truth = np.array([drone(k) for k in range(80)])

    def rms(fixed_factor: float) -> float:
        # the hand-set factors alone: the learned prior also sinks the sign here
        cfg = load_config(
            overrides={"tracking": {"fixed_factor": fixed_factor, "prior_scorer": False}}
        )
        _, result = estimate_sequence(frames, cfg)
        return _rms(np.array([e.position for e in result.estimates[5:]]) - truth[5:])

    assert rms(0.01) < 0.5
    assert rms(0.1) > 2.0  # the sign's 80 detections outweigh the low hover


@pytest.mark.parametrize("seed", [1, 2])
def test_the_causal_estimate_does_not_follow_a_still_object_before_it_is_judged(seed: int) -> None:
    # the floating sign (dozens of points, seen by more beams) and a drone drifting at 0.5 m/s,
    # both there from the first frame: for their first second they gather the same evidence,
    # and the sign, with more points, wins the tie; judged first, it never gets reported
    def drone(k: int) -> np.ndarray:
        return np.array([8.0, -2.0 + 0.05 * k, 3.0])

    frames = _with_objects(seed, 40, lambda k: [((3.0, 1.0, 2.5), 0.2), (tuple(drone(k)), 0.2)])

    def wrong(judge_s: float) -> int:
        cfg = load_config(overrides={"tracking": {"causal_judge_s": judge_s}})
        _, result = estimate_sequence(frames, cfg)
        reported = [
            (e, drone(k)) for k, e in enumerate(result.causal) if e.source != Source.FALLBACK
        ]
        assert len(reported) > 20
        return sum(float(np.linalg.norm(e.position - d)) > 1.0 for e, d in reported)

    assert wrong(1.0) == 0
    assert wrong(0.0) >= 5  # chosen at once: the sign is followed until judged


@pytest.mark.parametrize("seed", [1, 2])
def test_the_causal_estimate_judges_a_still_object_by_what_it_does_now(seed: int) -> None:
    # the floating sign's track begins on something rising beside it (2 m in four scans),
    # then stays rigid for good; alone, it is followed; the drone, drifting at 0.5 m/s,
    # arrives at scan 20. The box around all the sign's running means stays 2 m tall, so
    # judged by the box the sign never looks static and, followed and with more points, keeps
    # beating the drone; judged by what it does after its first second, it is rigid structure
    sign = np.array([3.0, 1.0, 2.5])

    def drone(k: int) -> np.ndarray:
        return np.array([8.0, -2.0 + 0.05 * k, 3.0])

    def objects(k: int) -> list[tuple[tuple[float, ...], float]]:
        rising = sign - [0.0, 0.0, 0.5 * max(4 - k, 0)]
        return [(tuple(rising), 0.2)] + ([(tuple(drone(k)), 0.2)] if k >= 20 else [])

    frames = _with_objects(seed, 60, objects)

    def wrong_late(robust: bool) -> int:
        tracking = {"causal_robust_still": robust, "prior_scorer": False}
        _, result = estimate_sequence(frames, load_config(overrides={"tracking": tracking}))
        late = list(enumerate(result.causal))[40:]
        assert all(e.source != Source.FALLBACK for _, e in late)
        return sum(float(np.linalg.norm(e.position - drone(k))) > 1.0 for k, e in late)

    assert wrong_late(True) == 0
    assert wrong_late(False) >= 10  # judged by the box, the sign is still followed


def test_the_causal_estimate_waits_for_confirmation() -> None:
    # something large crosses the view for three scans right after the warm-up, then the drone
    # is alone: unconfirmed, the causal estimate reports the passer; confirmed, it waits (the
    # judging second, causal_judge_s, would hold the passer back as well: off here,
    spot = np.array([8.0, 3.0, 2.0])

    def objects(k: int) -> list[tuple[tuple[float, ...], float]]:
        out = [(tuple(spot + [0.0, 0.05 * k, 0.0]), 0.25)]
        if 2 <= k <= 4:
            out.append(((5.0, -6.0 + 0.5 * k, 4.0), 0.6))
        return out

    frames = _with_objects(0, 30, objects)

    def worst(confirm: float) -> float:
        # nor the learned prior, which doubts the passer too
        tracking = {"causal_confirm": confirm, "causal_judge_s": 0.0, "prior_scorer": False}
        _, result = estimate_sequence(frames, load_config(overrides={"tracking": tracking}))
        errors = [
            np.linalg.norm(e.position - (spot + [0.0, 0.05 * k, 0.0]))
            for k, e in enumerate(result.causal)
            if e.source != Source.FALLBACK
        ]
        return float(max(errors))

    assert worst(3.0) < 1.0
    assert worst(0.0) > 5.0  # the rule is needed here


def _lost_drone_causal(
    seed: int,
    back: int,
    clutter: tuple[float, float, float],
    keep_lost: bool,
    tracking: dict[str, object] | None = None,
    *,
    seen: Callable[[int], bool] | None = None,
    n: int = 70,
    clutter_from: int = 40,
    clutter_mps: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> tuple[list[Estimate], np.ndarray]:
    """The causal estimates of a drone crossing 8 m out (dozens of points a scan) at 1 m/s in
    scans 0-29, gone (behind something) until scan ``back``, then on along its line (or seen
    in the scans ``seen`` picks, of ``n``), with a small still object at ``clutter`` from scan
    ``clutter_from`` on (``tracking.causal_keep_lost`` = ``keep_lost``, and ``tracking``
    overrides; the hand-set factors alone: the learned prior doubts the still object too).
    Also the drone's path (n,3)."""
    path = np.array([[8.0, -3.0 + 0.1 * k, 2.0] for k in range(n)])
    shown = seen if seen is not None else (lambda k: k < 30 or k >= back)

    def objects(k: int) -> list[tuple[tuple[float, ...], float]]:
        out: list[tuple[tuple[float, ...], float]] = []
        if shown(k):
            out.append((tuple(path[k]), 0.25))
        if k >= clutter_from:
            moved = 0.1 * (k - clutter_from) * np.asarray(clutter_mps)
            out.append((tuple(np.asarray(clutter) + moved), 0.15))
        return out

    overrides = {"causal_keep_lost": keep_lost, "prior_scorer": False, **(tracking or {})}
    frames = _with_objects(seed, n, objects)
    _, result = estimate_sequence(frames, load_config(overrides={"tracking": overrides}))
    # followed once it has been in view for 1.5 s (of its first three seconds, where seen)
    assert all(result.causal[k].source == Source.DETECTED for k in range(15, 30) if shown(k))
    return list(result.causal), path


@pytest.mark.parametrize("seed", [1, 2])
def test_a_lost_drone_stays_the_causal_choice_over_weak_clutter_that_turns_up_later(
    seed: int,
) -> None:
    # the drone never comes back; the still object turns up 1 s after it was last seen, 25 m
    # from there, beyond any link from it. Its evidence passes causal_confirm but not the lost
    # chain's: the refinement keeps the drone's chain, and so does the causal choice
    clutter = (-14.0, 10.0, 3.0)

    def on_clutter(keep_lost: bool, gap_s: float = 8.0) -> int:
        tracking = {"link_max_gap_s": gap_s}
        causal, _ = _lost_drone_causal(seed, 70, clutter, keep_lost, tracking)
        return sum(float(np.linalg.norm(e.position - clutter)) < 1.0 for e in causal)

    assert on_clutter(True) == 0
    assert on_clutter(False) >= 10  # the rule is needed here
    # nothing can continue a chain lost link_max_gap_s ago: it no longer competes
    assert on_clutter(True, gap_s=1.5) >= 10


@pytest.mark.parametrize("seed", [1, 2])
def test_a_drone_back_within_reach_continues_its_lost_chain(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the same, but the drone is back after 1.5 s (scan 45) where its line leads (until then
    # the estimate coasts along it): its new track could continue the lost chain, so it is
    # followed once judged (causal_judge_s, 10 scans), although its own evidence stays below
    # the chain's for a second more
    def first_on_drone() -> int | None:
        causal, path = _lost_drone_causal(seed, 45, (-14.0, 10.0, 3.0), True)
        on = [
            k
            for k in range(45, 70)
            if causal[k].source == Source.DETECTED
            and float(np.linalg.norm(causal[k].position - path[k])) < 0.5
        ]
        assert on == list(range(on[0], 70)) if on else True  # once followed, kept
        return on[0] if on else None

    first = first_on_drone()
    assert first is not None and first <= 45 + 10 + 2
    # a new track that may not continue the chain has to outweigh it: a second later or more
    monkeypatch.setattr("cldet.core.estimator.TrackEstimator._continues", lambda *_: False)
    later = first_on_drone()
    assert later is None or later >= first + 8


@pytest.mark.parametrize("seed", [1, 2])
def test_a_chain_lost_twice_keeps_the_evidence_of_both_its_tracks(seed: int) -> None:
    # the drone is seen for 3 s, hidden for 1.5 s, seen again for 1.5 s (its new track
    # continues the chain), then hidden for good; 0.5 s later a small object turns up 25 m
    # away, beyond any link, moving at 1 m/s as steadily as a drone. In the 6.5 s left it
    # outweighs the second track alone, not the two: the lost chain's evidence adds up
    start, velocity = np.array([-14.0, 10.0, 3.0]), (0.0, 1.0, 0.0)

    def on_other(seen: Callable[[int], bool]) -> int:
        causal, _ = _lost_drone_causal(
            seed, 0, tuple(start), True, seen=seen, n=130, clutter_from=65, clutter_mps=velocity
        )
        other = [start + 0.1 * (k - 65) * np.asarray(velocity) for k in range(130)]
        return sum(
            float(np.linalg.norm(e.position - o)) < 1.0 for e, o in zip(causal, other, strict=True)
        )

    assert on_other(lambda k: k < 30 or 45 <= k < 60) == 0
    # without the first three seconds the lost chain is the second track alone
    assert on_other(lambda k: 45 <= k < 60) >= 10


@pytest.mark.parametrize("seed", [1, 2])
def test_two_continuations_of_a_lost_chain_are_weighed_by_their_own_evidence(seed: int) -> None:
    # the drone is lost at scan 30; 0.6 s later a small object turns up 2.8 m from where it was
    # last seen, drifting at 0.3 m/s (within a link's reach: it could continue the chain), and
    # is followed; the drone is back at scan 45 on its line, a continuation too. What both
    # carry on from the lost chain cancels, so the drone's own evidence wins it back (counting
    # the chain for both, the 1.3 switch ratio applied to it too, it never would)
    start, velocity = np.array([6.0, -2.0, 0.5]), np.array([0.0, -0.3, 0.0])
    causal, path = _lost_drone_causal(
        seed, 45, tuple(start), True, n=110, clutter_from=36, clutter_mps=tuple(velocity)
    )
    other = [start + 0.1 * (k - 36) * velocity for k in range(110)]
    on_other = [k for k in range(36, 110) if np.linalg.norm(causal[k].position - other[k]) < 0.7]
    on_drone = [
        k
        for k in range(45, 110)
        if causal[k].source == Source.DETECTED
        and float(np.linalg.norm(causal[k].position - path[k])) < 0.5
    ]
    assert len(on_other) >= 10  # followed first
    assert on_drone and on_drone[0] <= 75
    assert on_drone == list(range(on_drone[0], 110))  # once back, kept


def _crossing(seed: int, n: int, first: int, last: int) -> tuple[list[LidarFrame], np.ndarray]:
    """``n`` scans (10 Hz) of a drone crossing at 15 m/s, 15 m out at its closest, returning
    points in scans ``first``-``last`` only: (frames, its true position per scan (n,3))."""
    truth = np.array([[15.0, -60.0 + 1.5 * k, 4.0] for k in range(n)])
    return _with_objects(
        seed, n, lambda k: [(tuple(truth[k]), 0.25)] if first <= k <= last else []
    ), truth


def _instant_scans(smoothing: dict[str, object]) -> CldetConfig:
    """The configuration with ``smoothing`` overrides, for the test scene's scans: they are
    instantaneous (no scan offset)."""
    return load_config(overrides={"frames": {"scan_offset_s": 0.0}, "smoothing": smoothing})


def test_a_fast_drone_hit_anywhere_in_the_scan_is_refined_at_its_points_time() -> None:
    """A drone crossing at 20 m/s, 10 m out at its closest, that each scan hits at a random
    instant of its 100 ms (the clouds record every point's firing time): dated at the scan's
    middle (``frames.point_times`` 'off') each detection is off by up to 1 m along its path;
    'fit' dates it at its points' time in the refinement's smoother, which then puts the track
    where the drone was at each stamp. The tracker's filter stays at the frame's time."""
    from tests.core.scene import scan

    rng = np.random.default_rng(0)
    n, empty = 50, np.zeros((0, 3), np.float32)

    def at(t: float) -> np.ndarray:
        return np.array([10.0, -50.0 + 20.0 * t, 3.0])

    frames = []
    for k in range(n):
        hit = rng.uniform(0.0, 0.1)  # when in scan k the drone was hit
        pts = scan(rng, [((*at(0.1 * k + hit),), 0.15)], n_rays=60000, wall=False)
        times = rng.uniform(0.0, 0.1, len(pts)).astype(np.float32)
        times[np.linalg.norm(pts - at(0.1 * k + hit), axis=1) < 0.25] = hit
        frames.append(LidarFrame(k * 100_000_000, pts, empty, mid360_times=times))
    truth = np.array([at(0.1 * k) for k in range(n)])

    def detected_rms(point_times: str) -> float:
        cfg = load_config(overrides={"frames": {"point_times": point_times}})
        _, result = estimate_sequence(frames, cfg)
        det = [k for k, e in enumerate(result.estimates) if e.source == Source.DETECTED]
        assert len(det) >= 25
        return _rms(np.array([result.estimates[k].position for k in det]) - truth[det])

    fit, off = detected_rms("fit"), detected_rms("off")
    assert fit < 0.15 and fit < 0.5 * off  # about 0.11 against 0.34 m


def test_a_lost_fast_pass_is_coasted_causally_at_its_points_time() -> None:
    """A drone crossing at 20 m/s, 10 m out at its closest, hit each scan at an instant that
    drifts from late in the scan to early over the 3 s it is seen (its direction moves through
    the scan pattern), then out of reach for 3 s. Dated at the scan's middle, the detections
    lie 0.8 m ahead at the start and 0.8 m behind at the end: the straight run's line through
    them is 0.5 m/s slow. The causal estimate coasts along that line from the past alone, as the
    refinement extrapolates, and with ``frames.point_times`` 'fit' both fit it at the points'
    own times."""
    from tests.core.scene import scan

    rng = np.random.default_rng(3)
    n, seen, empty = 60, 30, np.zeros((0, 3), np.float32)

    def at(t: float) -> np.ndarray:
        return np.array([10.0, -50.0 + 20.0 * t, 3.0])

    frames = []
    for k in range(n):
        hit = 0.09 - 0.08 * k / (seen - 1)  # when in scan k the drone was hit
        objects = [((*at(0.1 * k + hit),), 0.15)] if k < seen else []
        pts = scan(rng, objects, n_rays=60000, wall=False)
        times = rng.uniform(0.0, 0.1, len(pts)).astype(np.float32)
        if k < seen:
            times[np.linalg.norm(pts - at(0.1 * k + hit), axis=1) < 0.25] = hit
        frames.append(LidarFrame(k * 100_000_000, pts, empty, mid360_times=times))

    def end_errors(point_times: str) -> tuple[float, float]:
        """The refined and the causal estimate's error at the last scan, 3 s after the last hit."""
        cfg = load_config(overrides={"frames": {"point_times": point_times}})
        _, result = estimate_sequence(frames, cfg)
        assert sum(e.source == Source.DETECTED for e in result.estimates) >= 20
        refined, causal = result.estimates[-1], result.causal[-1]
        assert refined.source == causal.source == Source.PREDICTED
        truth = at(0.1 * (n - 1))
        return (
            float(np.linalg.norm(refined.position - truth)),
            float(np.linalg.norm(causal.position - truth)),
        )

    fit, off = end_errors("fit"), end_errors("off")
    assert max(fit) < 0.5 * min(off)  # about 0.25 against 2.6 m


def test_a_straight_pass_seen_only_midway_is_extrapolated_along_its_line() -> None:
    # a drone crossing at 15 m/s, 15-27 m out, returns points only in scans 25-55 of 80 (out
    # of range or hidden before and after); it flew straight while seen, so inertia carries it
    # on along that line for about as long, where a decaying velocity stops it short. The
    # causal estimate, once the track is lost, carries it on the same way from its past alone
    frames, truth = _crossing(0, 80, 25, 55)

    def rms(straight_rms_m: float) -> tuple[float, float]:
        # the braking bound (smoothing.max_decel_mps2) off: alone it recovers part of this
        cfg = _instant_scans({"straight_rms_m": straight_rms_m, "max_decel_mps2": 0.0})
        _, result = estimate_sequence(frames, cfg)
        assert sum(e.source == Source.DETECTED for e in result.estimates) >= 25
        causal = np.array([e.position for e in result.causal[56:]])
        assert all(e.source == Source.PREDICTED for e in result.causal[56:])
        return (
            _rms(np.array([e.position for e in result.estimates]) - truth),
            _rms(causal - truth[56:]),
        )

    refined, causal = rms(0.4)
    assert refined < 1.0 and causal < 0.6
    refined, causal = rms(0.0)  # the rule is needed here (about 5 m and 1.3 m without it)
    assert refined > 3.0 and causal > 1.0


def test_a_transit_seen_briefly_is_carried_on_for_longer_than_it_was_seen() -> None:
    # the crossing above (15 m/s, 15 m out at its closest), seen in scans 38-55 only (1.7 s),
    # then flying on out of reach for 2.4 s: a drone in transit keeps going; held only as long
    # as it was seen, its velocity decays 1.5 s on and the end falls metres short
    frames, truth = _crossing(4, 80, 38, 55)

    def end_error(factor: float) -> float:
        cfg = _instant_scans({"straight_hold_factor": factor})
        _, result = estimate_sequence(frames, cfg)
        pos = np.array([e.position for e in result.estimates])
        return float(np.max(np.linalg.norm(pos[-10:] - truth[-10:], axis=1)))

    assert end_error(2.0) < 0.7
    assert end_error(1.0) > 1.5


def test_a_fast_transit_carried_on_slows_no_faster_than_a_drone_brakes() -> None:
    # the crossing above (15 m/s) seen in scans 38-45 only (0.8 s), then 3.4 s out of reach:
    # held for twice as long as it was seen, the velocity then decays; at 1.5 s it would brake
    # at 10 m/s^2, beyond a multirotor's tilt; bounded to 6 m/s^2 it decays over 2.5 s
    frames, truth = _crossing(4, 80, 38, 45)

    def end_errors(max_decel: float) -> tuple[float, float]:
        """The refined and the causal estimate's error at the last scan."""
        _, result = estimate_sequence(frames, _instant_scans({"max_decel_mps2": max_decel}))
        refined, causal = result.estimates[-1], result.causal[-1]
        assert refined.source == causal.source == Source.PREDICTED
        return (
            float(np.linalg.norm(refined.position - truth[-1])),
            float(np.linalg.norm(causal.position - truth[-1])),
        )

    # 10.0 m both: still short, it might have braked; the causal coast carries it on alike
    assert max(end_errors(6.0)) < 11.0
    assert min(end_errors(0.0)) > 13.0  # 13.9 m


@pytest.mark.parametrize(("last_scan", "limit_m"), [(43, 0.7), (40, 1.5)])
def test_a_transit_seen_for_half_a_second_keeps_its_velocity_for_a_while(
    last_scan: int, limit_m: float
) -> None:
    # the crossing above (15 m/s) seen from scan 38 to ``last_scan`` only (6 scans, 0.5 s, or
    # 3, the fewest that make a straight run), out of reach before and after: however short,
    # a straight run at transit speed is inertia's evidence; carried on for twice as long as it
    # was seen before decaying, the refined track stays near the drone in the second before the
    # first detection and the second after the last, where a velocity decaying from the track's
    # ends (as when only runs longer than the decay's 1.5 s were held) falls metres behind
    frames, truth = _crossing(4, 60, 38, last_scan)

    def worst_beyond(straight_rms_m: float) -> float:
        # the braking bound (smoothing.max_decel_mps2) off: alone it recovers part of this
        cfg = _instant_scans({"straight_rms_m": straight_rms_m, "max_decel_mps2": 0.0})
        _, result = estimate_sequence(frames, cfg)
        detected = [e.source == Source.DETECTED for e in result.estimates]
        assert sum(detected) == last_scan - 37
        pos = np.array([e.position for e in result.estimates])
        beyond = np.r_[28:38, last_scan + 1 : last_scan + 11]  # a second before, a second after
        return float(np.max(np.linalg.norm(pos[beyond] - truth[beyond], axis=1)))

    assert worst_beyond(0.4) < limit_m  # 0.35 m with 6 detections, 1.1 m with 3
    assert worst_beyond(0.0) > 3.0  # 4.4 and 3.8 m: the straight run's rule off


def _one_track(
    n: int, seen: np.ndarray, positions: np.ndarray, speed: float
) -> tuple[list[ClusterTable], TrackRecord]:
    """``n`` frames' cluster tables with one cluster (ten points, 0.3 m) at ``positions`` in the
    frames ``seen`` and none elsewhere, and the one track over them (filtered ``speed``)."""
    one = np.ones(1, dtype=np.int64)
    at = dict(zip(seen.tolist(), positions, strict=True))
    tables = [
        ClusterTable(at[k][None, :], np.full(1, 0.3), 10 * one, 10 * one, 0 * one)
        if k in at
        else ClusterTable.from_clusters(())
        for k in range(n)
    ]
    h = len(seen)
    rec = TrackRecord(
        0, seen, np.zeros(h, np.int64), positions, np.full(h, 10), np.ones(h), np.full(h, speed)
    )
    return tables, rec


def _walk_then_unseen(
    view_ranges: dict[int, float],
    check_s: float = 1.0,
    onset: dict[int, int] | None = None,
    rest: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """The refined track of one drone seen (ten points a scan) in scans 10-29 of 60 walking
    along y at 2 m/s, 10 m out, then never again; the final static scene is empty but for
    ``view_ranges`` (direction cell -> static range), whose surfaces appeared at ``onset``
    (cell -> ns; the others were always there); ``smoothing.unseen_check_s`` = ``check_s``,
    ``smoothing.came_to_rest`` = ``rest``.
    (estimates (60,3), its last detection)"""
    from cldet.core.background import NO_ONSET, StaticView, direction_cells
    from cldet.core.estimator import Candidates, refine_candidates

    cfg = _instant_scans({"unseen_check_s": check_s, "came_to_rest": rest})
    n, seen = 60, np.arange(10, 30)
    pos = np.array([[10.0, -3.0 + 0.2 * (k - 10), 2.0] for k in seen])
    tables, rec = _one_track(n, seen, pos, 2.0)
    bc = cfg.background
    around = np.full(90 * 180, np.inf, dtype=np.float32)
    for cell, r in view_ranges.items():
        around[cell] = r
    onset_ns = np.full(len(around), NO_ONSET, dtype=np.int64)
    for cell, ns in (onset or {}).items():
        onset_ns[cell] = ns
    view = StaticView(around, bc.cell_deg, bc.margin_m, bc.margin_fraction, -7.3, around, onset_ns)
    times = 0.1 * np.arange(n)
    cand = Candidates([rec], tables, times, np.arange(n) * 100_000_000, view)
    est = refine_candidates(cand, cfg)
    assert direction_cells(pos[-1:], bc.cell_deg)[2:] == (90, 180)
    return np.array([e.position for e in est.estimates]), pos[-1]


def test_motion_is_not_carried_on_into_open_view_where_the_drone_would_have_been_seen() -> None:
    # a drone seen well for 2 s, then never again: carried on at 2 m/s it would have crossed
    # open sky in front of the sensors, where ten points a scan cannot go unseen. Where the
    # final static scene holds something at its last place (it stopped and was learned there),
    # it is held there; where nothing is there either, nothing tells which, and the motion is
    # carried on as before (it may have sped out of view)
    from cldet.core.background import direction_cells

    _, last = _walk_then_unseen({})
    cells, rng, _, _ = direction_cells(last[None, :].astype(np.float32), 2.0)
    stopped = {int(cells[0]): float(rng[0])}
    held, _ = _walk_then_unseen(stopped)
    carried, _ = _walk_then_unseen({})
    assert np.linalg.norm(held[-1] - last) < 0.3
    assert np.linalg.norm(carried[-1] - last) > 2.0
    assert np.linalg.norm(_walk_then_unseen(stopped, check_s=0.0)[0][-1] - last) > 2.0


def test_a_track_whose_end_came_to_rest_there_is_held_even_where_it_could_have_gone_on() -> None:
    # the drone walks along foliage at its own range: carried on, its path would lie behind
    # leaves the whole way, so it could have gone on unseen. Where the static surface at its
    # last place appeared after the track began (the spot was seen through before), it came to
    # rest there and was learned: held. Where that surface was always there, carried on
    from cldet.core.background import direction_cells

    _, last = _walk_then_unseen({})
    along = last + np.outer(np.linspace(0.0, 4.0, 41), [0.0, 1.0, 0.0])
    cells, rng, _, _ = direction_cells(along.astype(np.float32), 2.0)
    foliage = {int(c): float(r) - 0.2 for c, r in zip(cells, rng, strict=True)}
    end_cell = int(cells[0])
    foliage[end_cell] = float(rng[0])
    carried, _ = _walk_then_unseen(foliage)
    before, after = 5 * 100_000_000, 25 * 100_000_000  # the track is seen in scans 10-29
    stayed, _ = _walk_then_unseen(foliage, onset={end_cell: after})
    always, _ = _walk_then_unseen(foliage, onset={end_cell: before})
    assert np.linalg.norm(carried[-1] - last) > 2.0
    assert np.linalg.norm(stayed[-1] - last) < 0.3
    assert np.linalg.norm(always[-1] - last) > 2.0
    off, _ = _walk_then_unseen(foliage, onset={end_cell: after}, rest=False)
    assert np.linalg.norm(off[-1] - last) > 2.0


def test_a_path_carried_back_into_the_ground_stops_where_it_meets_it() -> None:
    # a drone rests 0.5 m above level ground 10 m in front of a sensor 2 m up (unseen: learned
    # with the scene), then climbs away at 2 m/s up and 2 m/s along y from scan 30 of 60, seen
    # from then on. Carried back, its climb runs metres into the ground; a drone flies above
    # the ground: the path stops where it meets it, near where the drone rested
    from cldet.core.estimator import Candidates, refine_candidates
    from cldet.core.ground import GroundModel

    n, seen = 60, np.arange(30, 60)
    t_s = 0.1 * np.arange(n)
    rest = np.array([10.0, 0.0, -1.5])
    truth = rest + np.outer(np.maximum(t_s - 3.0, 0.0), [0.0, 2.0, 2.0])
    tables, rec = _one_track(n, seen, truth[seen], 2.8)
    ground = GroundModel(plane=GroundModel.from_pose(2.0, 0.0, 0.0))
    stamps = np.arange(n) * 100_000_000

    def before(stop_m: float) -> np.ndarray:
        # the stop alone: kept above the ground it had (terrain_clearance_m), the path carried
        # back would also stay clear of it
        cfg = _instant_scans({"ground_stop_m": stop_m, "terrain_clearance_m": 0.0})
        est = refine_candidates(Candidates([rec], tables, t_s, stamps, None, ground), cfg)
        return np.array([e.position for e in est.estimates])[:30]

    carried = before(0.0)
    assert ground.depth_below(carried).max() > 2.0  # 2.05 m under the ground at the start
    stopped = before(1.0)
    assert ground.depth_below(stopped).max() <= 0.0
    assert _rms(stopped - truth[:30]) < 0.5 * _rms(carried - truth[:30])  # 0.30 against 1.51 m


def test_a_path_carried_on_over_rising_ground_climbs_with_it() -> None:
    # a sensor 2 m above ground that rises at 20 % along +y; a drone flies level along +y at
    # 5 m/s, seen for 3 s, and is 2.1 m above the ground at its last detection. Carried on
    # level, its path runs into the slope; a drone cannot fly through the ground, and flying
    # on it climbs with it: kept at the clearance it had (capped at terrain_clearance_m)
    from cldet.core.estimator import Candidates, refine_candidates
    from cldet.core.ground import GroundModel

    slope = 0.2
    up = np.array([0.0, -slope, 1.0]) / np.hypot(1.0, slope)
    ground = GroundModel(plane=(up, 2.0))
    n, seen = 60, np.arange(30)
    t_s = 0.1 * np.arange(n)
    level = np.stack([np.full(n, 10.0), -10.0 + 5.0 * t_s, np.full(n, 1.0)], axis=1)
    clearance = 2.0
    truth = level + np.maximum(ground.depth_below(level) + clearance, 0.0)[:, None] * up
    assert np.allclose(truth[seen], level[seen])  # level while seen, 2.1-4.9 m up
    tables, rec = _one_track(n, seen, truth[seen], 5.0)
    stamps = np.arange(n) * 100_000_000

    def after(clearance_m: float) -> np.ndarray:
        cfg = _instant_scans({"terrain_clearance_m": clearance_m})
        est = refine_candidates(Candidates([rec], tables, t_s, stamps, None, ground), cfg)
        return np.array([e.position for e in est.estimates])[30:]

    level_on = after(0.0)
    assert ground.depth_below(level_on).max() > 0.5  # through the slope by the end
    climbed = after(clearance)
    assert -ground.depth_below(climbed).min() > 1.9
    assert _rms(climbed - truth[30:]) < 0.1 * _rms(level_on - truth[30:])


def test_the_background_warm_up_is_no_evidence_that_a_drone_was_not_there() -> None:
    # a drone first detected in scan 3 in a straight transit at 3.5 m/s: carried back, its path
    # lies in open view, and the scene at its first detection could hide a drone that hovered
    # there (came_out: the warm-up learned it). If scans 0-2 could have shown it, not seeing it
    # there contradicts the transit: held. Nothing is foreground during the warm-up (0.2 s: scans
    # 0-1); the one scan left could have missed it: carried back
    from cldet.core.background import StaticView
    from cldet.core.estimator import _stop_unseen

    cfg = load_config()
    n, bc = 50, cfg.background
    t_s = 0.1 * np.arange(n)
    have = np.arange(n) >= 3
    view = StaticView(
        np.full(90 * 180, np.inf, np.float32), bc.cell_deg, bc.margin_m, bc.margin_fraction, -7.3
    )
    velocity = np.array([0.0, -3.5, 0.0])
    ends = {
        0: (np.array([10.0, 5.0, 2.0]), velocity, 3.0),
        -1: (np.array([10.0, -11.0, 2.0]), velocity, 3.0),
    }

    def start_velocity(blind_scans: int) -> np.ndarray:
        blind = np.arange(n) < blind_scans
        return _stop_unseen(ends, t_s, have, blind, view, True, False, cfg.smoothing)[0][1]

    assert not np.any(start_velocity(0))
    warm_up = int(round(bc.bin_s / 0.1))
    assert warm_up == 2
    np.testing.assert_array_equal(start_velocity(warm_up), velocity)


def _protection(
    centres: dict[int, np.ndarray], n_points: int, dense_points: int
) -> tuple[float, bool]:
    """A ball of ``n_points`` returns (8 cm spread) at each frame's centre, nothing in the other
    frames (of 0.1 s) up to the last centre's: the one track's spread and whether it is
    protected, with ``background.protect_dense_points`` = ``dense_points``."""
    rng = np.random.default_rng(0)
    empty = np.zeros((0, 3), np.float32)
    cfg = load_config(overrides={"background": {"protect_dense_points": dense_points}})
    est = TrackEstimator(cfg)
    for k in range(max(centres) + 1):
        c = centres.get(k)
        pts = empty if c is None else c + rng.normal(0.0, 0.08, (n_points, 3))
        est.register_frame(LidarFrame(k * 100_000_000, pts.astype(np.float32), empty))
    (tid,) = est._tracker.active_ids().tolist()
    assert est._tracker.is_confirmed_mover(tid)
    return est._tracker.spread(tid), est._protects(tid)


@pytest.mark.parametrize("n_points", [20, 1])
def test_a_young_track_that_jumps_is_protected_only_when_its_clusters_are_dense(
    n_points: int,
) -> None:
    # three detections, a gap (the object was hidden), then one 1.4 m away across their line:
    # its detections spread wider than a drone before a running mean exists, and follow no
    # line. Twenty points in a compact ball
    # are one object that moved: protected. One point each may be a larger thing lit in
    # different places: not protected (the sparse-structure test above)
    a = np.array([7.0, 0.0, 1.0])
    centres = {3: a, 4: a + [0.0, 0.1, 0.0], 5: a + [0.0, 0.2, 0.0], 9: a + [1.4, 0.0, 0.0]}
    spread, protected = _protection(centres, n_points, 3)
    assert spread > load_config().tracking.max_size_m
    assert protected == (n_points >= 3)
    assert not _protection(centres, n_points, 0)[1]


def test_a_flight_displaces_the_running_mean_where_scatter_only_widens_its_box() -> None:
    # a far pole lit in different places each scan, seen for 30 s (0.6 m scatter per axis),
    # against a drone that flew 3 m in 1 s and hovers: the box around the running means of the
    # scatter grows past the protection threshold as the samples pile up (extreme values); the
    # displacement from the first running mean to the latest does not
    rng = np.random.default_rng(0)
    pole, flight = _Evidence(), _Evidence()
    for k in range(300):
        t = 0.1 * k
        pole.add(t, 1.0, rng.normal([28.0, 0.0, 5.0], 0.6), False)
        at = np.array([10.0, 3.0 * min(t, 1.0), 4.0]) + rng.normal(0.0, 0.05, 3)
        flight.add(t, 1.0, at, False)
    threshold = load_config().background.protect_min_moved_m
    assert pole.mean_moved > threshold > pole.displaced
    assert flight.displaced > threshold


@pytest.mark.parametrize("n_points", [20, 1])
def test_a_still_track_is_protected_as_a_hover_only_when_its_clusters_are_dense(
    n_points: int,
) -> None:
    # a track whose detections stay within a drone's size: a compact cluster of twenty points
    # is one small body hovering (protected); single returns there are as likely a larger
    # thing lit in different places each scan (a far pole, a swaying canopy edge: learned)
    rng = np.random.default_rng(1)
    centres = {k: np.array([7.0, 0.0, 1.0]) + rng.uniform(-0.3, 0.3, 3) for k in range(3, 12)}
    spread, protected = _protection(centres, n_points, 3)
    assert spread <= load_config().tracking.max_size_m
    assert protected == (n_points >= 3)
    assert _protection(centres, n_points, 0)[1]


def _rain(rng: np.random.Generator, n: int) -> np.ndarray:
    """Lone rain returns: 87 % within 0.3-6 m, the rest 15-150 m, in the Mid-360's field."""
    az = rng.uniform(-np.pi, np.pi, n)
    el = np.radians(rng.uniform(-7.0, 52.0, n))
    r = np.where(rng.random(n) < 0.87, rng.uniform(0.3, 6.0, n), rng.uniform(15.0, 150.0, n))
    return r[:, None] * np.column_stack(
        [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]
    )


@pytest.mark.slow
def test_tracks_strung_through_rain_weigh_less_than_a_sparse_high_drone() -> None:
    # a drone hovering 65 m up, one return in 20 % of scans, in rain (100 lone returns a scan,
    # most within 6 m): near the sensor some track always finds a drop to continue on. A
    # detection with k other clusters within tracking.crowd_radius_m weighs 1 / (1 + k): with
    # it the drone wins all 8 rainy sequences, without it the rain wins 2 of them
    from tests.core.scene import scan

    empty = np.zeros((0, 3), np.float32)
    drone = np.array([20.0, 5.0, 65.0])

    def failures(crowd_radius_m: float) -> int:
        # the hand-set factors alone: the learned prior also sinks the rain tracks here
        cfg = load_config(
            overrides={"tracking": {"crowd_radius_m": crowd_radius_m, "prior_scorer": False}}
        )
        fails = 0
        for seed in range(8):
            rng = np.random.default_rng(seed)
            frames = []
            for k in range(60):
                seen = rng.random() < 0.2
                blip = drone + rng.normal(0.0, 0.15, (int(seen), 3))
                pts = np.concatenate([scan(rng, n_rays=3000), _rain(rng, rng.poisson(100)), blip])
                frames.append(LidarFrame(k * 100_000_000, pts.astype(np.float32), empty))
            _, result = estimate_sequence(frames, cfg)
            pos = np.array([e.position for e in result.estimates[10:]])
            fails += int(_rms(np.linalg.norm(pos - drone, axis=1)) > 1.0)
        return fails

    assert failures(3.0) == 0
    assert failures(0.0) >= 2


@pytest.mark.slow
def test_a_drone_that_flies_into_rain_near_the_sensor_is_carved_out_of_the_rain() -> None:
    # a drone flies from 10 m to 2.5 m from the sensor in 3 s and hovers there 3 s, in rain
    # (300 lone returns a scan, most within 6 m: near the sensor the 1 m linkage chains them
    # into one wide cluster, and the drone joins it). The track it had before, which has flown,
    # carves its returns out of that cluster (tracking.carve_gate_m); without, its detection
    # is the wide cluster's centroid and the drone is lost
    from tests.core.scene import scan

    empty = np.zeros((0, 3), np.float32)
    spot = np.array([2.5, 1.5, 0.8])
    start = spot + np.array([7.0, -3.0, 0.5])
    path = np.array([start + (spot - start) * min(k / 30, 1.0) for k in range(60)])

    def failures(carve_gate_m: float) -> int:
        cfg = load_config(overrides={"tracking": {"carve_gate_m": carve_gate_m}})
        fails = 0
        for seed in range(4):
            rng = np.random.default_rng(seed)
            frames = [
                LidarFrame(
                    k * 100_000_000,
                    np.concatenate(
                        [scan(rng, [((*p,), 0.3)], n_rays=6000), _rain(rng, rng.poisson(300))]
                    ).astype(np.float32),
                    empty,
                )
                for k, p in enumerate(path)
            ]
            _, result = estimate_sequence(frames, cfg)
            pos = np.array([e.position for e in result.estimates[5:]])
            fails += int(_rms(np.linalg.norm(pos - path[5:], axis=1)) > 1.0)
        return fails

    assert failures(0.6) <= 1
    assert failures(0.0) >= 3


@pytest.mark.slow
@pytest.mark.parametrize("seed", [10097, 10105, 10189])
def test_the_learned_prior_picks_the_drone_where_the_hand_set_factors_do_not(seed: int) -> None:
    # three randomised development worlds outside the prior's training seeds (10200-10599) on
    # which the hand-set factors alone choose clutter: a high hover seen in the Avia against a
    # swaying canopy overhead (10097), a fast pass against a far static return (10105), a hover
    # beside a potted shrub on a roof against the shrub's flicker (10189). The prior re-weighs
    # the same tracks by what it learned from 400 other worlds
    from cldet.simulate import simulate_world_frames

    frames, truth = simulate_world_frames(seed, 8.0)

    def rms(prior: bool) -> float:
        cfg = load_config(overrides={"tracking": {"prior_scorer": prior}})
        _, result = estimate_sequence(frames, cfg)
        stamps = np.array([e.stamp_ns for e in result.estimates])
        pos = np.array([e.position for e in result.estimates])
        t = (truth.gt_stamps_ns - stamps[0]).astype(np.float64)
        at = np.column_stack([np.interp(t, stamps - stamps[0], pos[:, k]) for k in range(3)])
        return _rms(np.linalg.norm(at - truth.gt_positions, axis=1))

    assert rms(True) < 1.0
    assert rms(False) > 5.0


@pytest.mark.parametrize("seed", [1, 2])
def test_a_missed_frame_of_a_straight_pass_follows_the_runs_line(seed: int) -> None:
    # a drone passing at 10 m/s, 10 m out, seen for 3 s; a scan's returns are taken anywhere
    # along the metre it flies during the scan, and those of its last two scans came late (0.5
    # m ahead); then it is hidden for half a second (behind a tree; its track not yet lost).
    # The tracker's filter takes that smear as speed, where the line fitted to the whole
    # straight run hardly moves
    def drone(k: int) -> np.ndarray:
        return np.array([10.0, -15.0 + 1.0 * k, 4.0])

    def objects(k: int) -> list[tuple[tuple[float, ...], float]]:
        if 30 <= k < 35:
            return []
        late = 0.5 if k in (28, 29) else 0.0
        return [(tuple(drone(k) + [0.0, late, 0.0]), 0.35)]

    frames = _with_objects(seed, 40, objects)

    def worst_missed(straight: bool) -> float:
        cfg = _instant_scans({"causal_straight_coast": straight})
        _, result = estimate_sequence(frames, cfg)
        missed = [(k, e) for k, e in enumerate(result.causal) if 30 <= k < 35]
        assert all(e.source == Source.PREDICTED for _, e in missed)
        return max(float(np.linalg.norm(e.position - drone(k))) for k, e in missed)

    assert worst_missed(True) < 0.5
    assert worst_missed(False) > 2 * worst_missed(True)  # the rule is needed here


def test_a_known_mount_is_the_estimators_ground_from_the_start() -> None:
    # sensor.ground_from_pose: the ground plane is the configured mount's, never fitted
    known = TrackEstimator(
        load_config(overrides={"sensor": {"ground_from_pose": True, "height_m": 2.4}})
    )
    ground = known.background.ground
    assert ground.fitted and ground.offset == 2.4
    np.testing.assert_allclose(ground.normal, [0.0, 0.0, 1.0])
    assert not TrackEstimator(load_config()).background.ground.fitted  # fitted to the data


def test_each_point_is_dated_at_its_firing_time_where_recorded() -> None:
    """``fuse_timed``: the Mid-360's recorded times as they are, the Avia's counted from its own
    stamp (14 ms later), the rows the range filter drops dropped with their times; a cloud
    without times, or ``frames.point_times`` 'off', dates every point at ``scan_offset_s``."""
    cfg = CldetConfig()  # point_times 'fit', the default
    off = load_config(overrides={"frames": {"point_times": "off"}})
    mid = np.array([[5.0, 0, 0], [0.1, 0, 0], [0, 6.0, 0]], dtype=np.float32)  # 0.1 m: too near
    avia = np.array([[0, 0, 30.0]], dtype=np.float32)
    frame = LidarFrame(
        stamp_ns=1_000_000_000,
        mid360=mid,
        avia=avia,
        avia_stamp_ns=1_014_000_000,
        mid360_times=np.array([0.01, 0.02, 0.09], dtype=np.float32),
        avia_times=np.array([0.05], dtype=np.float32),
    )
    pts, n_mid, times = fuse_timed(frame, cfg)
    assert n_mid == 2 and len(pts) == 3
    np.testing.assert_allclose(times, [0.01, 0.09, 0.064], rtol=1e-5)
    for untimed, c in (
        (LidarFrame(1_000_000_000, mid, avia, 1_014_000_000), cfg),
        (frame, off),
    ):
        _, _, times = fuse_timed(untimed, c)
        np.testing.assert_allclose(times, cfg.frames.scan_offset_s)
