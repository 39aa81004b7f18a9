"""Tests of the candidate tracker and the whole-sequence selection on synthetic clusters."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from cldet.config import TrackingConfig
from cldet.core.selection import ScoredTrack, extend_chain, score_tracks, select_chain
from cldet.core.tracking import (
    CandidateTracker,
    ClusterTable,
    TrackRecord,
    constant_velocity_fit,
    crowding,
    windowed_velocity,
)

GROUND = -1.5


def _table(items: list[tuple[np.ndarray, float, int]]) -> ClusterTable:
    """Clusters from (centroid, extent, n_points)."""
    if not items:
        return ClusterTable.from_clusters(())
    return ClusterTable(
        centroid=np.array([c for c, _, _ in items], dtype=np.float64),
        extent=np.array([e for _, e, _ in items]),
        n_points=np.array([n for _, _, n in items], dtype=np.int64),
        n_mid360=np.array([n for _, _, n in items], dtype=np.int64),
        n_avia=np.zeros(len(items), dtype=np.int64),
        height=np.array([c[2] - GROUND for c, _, _ in items], dtype=np.float64),
    )


def _run(tables: list[ClusterTable], cfg: TrackingConfig, dt: float = 0.1):  # type: ignore[no-untyped-def]
    tracker = CandidateTracker(cfg)
    for k, table in enumerate(tables):
        tracker.step(k, k * dt, table)
    times = np.arange(len(tables)) * dt
    scored = score_tracks(tracker.records(), tables, times, cfg)
    return scored, select_chain(scored, cfg)


def _drone(t: float) -> np.ndarray:
    return np.array([10 + 2 * np.cos(0.4 * t), 5 * np.sin(0.4 * t), 4 + 0.3 * t])


def test_drone_wins_over_person_bird_and_speckle() -> None:
    rng = np.random.default_rng(0)
    cfg = TrackingConfig()
    tables = []
    n = 120
    for k in range(n):
        t = k * 0.1
        items: list[tuple[np.ndarray, float, int]] = []
        if rng.random() < 0.5:  # a far drone: seen in half of the frames, 1-3 points
            items.append((_drone(t) + rng.normal(0, 0.05, 3), 0.2, int(rng.integers(1, 4))))
        # a person walking at 1.4 m/s, seen every frame, large and low
        items.append(
            (np.array([-6 + 1.4 * t, 3.0, GROUND + 1.0]) + rng.normal(0, 0.05, 3), 1.7, 30)
        )
        if 30 <= k < 60:  # a bird crossing fast and erratically
            jink = rng.normal(0, 0.4, 3)
            items.append((np.array([-20 + 14 * (t - 3), -8, 9 + np.sin(9 * t)]) + jink, 0.3, 2))
        for _ in range(3):  # speckle
            items.append((rng.uniform([-30, -30, -1], [30, 30, 10]), 0.0, 1))
        tables.append(_table(items))
    scored, chain = _run(tables, cfg)
    assert chain
    chosen = np.concatenate(
        [
            tr.positions[i0:i1] - np.array([_drone(tt) for tt in tr.times_s[i0:i1]])
            for tr, i0, i1 in chain
        ]
    )
    assert np.all(np.linalg.norm(chosen, axis=1) < 0.5)
    n_det = sum(i1 - i0 for _, i0, i1 in chain)
    assert n_det > 0.4 * n


def test_chain_bridges_a_long_unseen_stretch() -> None:
    cfg = TrackingConfig()
    tables = []
    for k in range(100):
        t = k * 0.1
        seen = not (3.0 <= t < 6.0)  # 3 s unseen: longer than max_miss_s, the track ends
        items = [(_drone(t), 0.3, 5)] if seen else []
        items.append((np.array([3.0, -3.0, 2.0 + 0.01 * k]), 0.2, 3))  # a static pole top
        tables.append(_table(items))
    scored, chain = _run(tables, cfg)
    assert len(chain) == 2
    first, second = chain[0][0], chain[1][0]
    assert first.times_s[0] < 3.0 and second.times_s[0] >= 6.0
    for tr, i0, i1 in chain:
        truth = np.array([_drone(tt) for tt in tr.times_s[i0:i1]])
        assert np.allclose(tr.positions[i0:i1], truth)


def test_raw_points_keep_a_confirmed_mover_alive() -> None:
    cfg = TrackingConfig(raw_gate_m=0.6)  # the raw gate is off by default
    tracker = CandidateTracker(cfg)
    rng = np.random.default_rng(2)
    stop = np.array([6.0, 2.0, 3.0])
    for k in range(40):
        t = k * 0.1
        pos = stop + np.array([min(t - 1.0, 0.0) * 1.0, 0, 0])  # flies 1 m/s then hovers at stop
        if t < 1.0:
            table = _table([(pos, 0.3, 6)])
            raw = np.zeros((0, 3))
        else:  # learned as background: no cluster, only raw points
            table = _table([])
            raw = pos + rng.normal(0, 0.1, (6, 3))
        tracker.step(k, t, table, raw)
    (rec,) = [r for r in tracker.records() if len(r.frames) > 5]
    assert rec.raw.sum() >= 25
    assert np.linalg.norm(rec.positions[-1] - stop) < 0.2


def test_raw_points_of_a_wall_do_not() -> None:
    cfg = TrackingConfig(raw_gate_m=0.6)  # the raw gate is off by default
    tracker = CandidateTracker(cfg)
    yy, zz = np.meshgrid(np.linspace(-3, 3, 40), np.linspace(0, 4, 30))
    wall = np.stack([np.full(yy.size, 8.0), yy.ravel(), zz.ravel()], axis=1)
    for k in range(30):
        t = k * 0.1
        pos = np.array([8.0 - 1.0 + t, 0.0, 2.0]) if t < 1.0 else None
        table = _table([(pos, 0.3, 5)]) if pos is not None else _table([])
        tracker.step(k, t, table, wall)
    assert all(r.raw.sum() == 0 for r in tracker.records())


def test_a_flickering_clump_that_goes_nowhere_loses_to_a_sparse_far_mover() -> None:
    # a far drone seen in 40 % of frames with one point, flying steadily at 1.5 m/s, against a
    # swaying clump 25 m away seen more often whose sparse centroid jumps ~0.4 m frame to frame
    rng = np.random.default_rng(7)
    cfg = TrackingConfig()
    tables = []
    for k in range(55):
        t = k * 0.1
        items: list[tuple[np.ndarray, float, int]] = []
        if rng.random() < 0.4:
            drone = np.array([27.0 - 1.1 * t, 15.0 - 0.9 * t, 11.5 - 0.4 * t])
            items.append((drone + rng.normal(0, 0.05, 3), 0.0, 1))
        if rng.random() < 0.7:
            clump = np.array([-25.4, 3.5, 3.8]) + rng.normal(0, [0.1, 0.1, 0.45])
            items.append((clump, 0.3, 2))
        tables.append(_table(items))
    scored, chain = _run(tables, cfg)
    assert chain and all(tr.positions[0, 0] > 0 for tr, _, _ in chain)
    clump = max((s for s in scored if s.positions[0, 0] < 0), key=lambda s: s.score)
    drone = max((s for s in scored if s.positions[0, 0] > 0), key=lambda s: s.score)
    assert clump.score < 0.5 * drone.score


def test_lone_returns_near_the_sensor_lose_to_a_hovering_drone_by_cross_section() -> None:
    # rain: one return a frame a few metres out, each near the last (a track hops from drop to
    # drop), against a Mavic-sized drone hovering 12 m out (6 points a frame, static: it wanders
    # by 10 cm, its position controller and the wind; still to 3 cm it would be rigid structure)
    rng = np.random.default_rng(5)
    tables = []
    drop = np.array([2.5, 1.0, 1.0])
    for k in range(60):
        drop = drop + rng.normal(0, 0.15, 3)
        wander = 0.1 * np.array([np.sin(0.13 * k), np.cos(0.09 * k), 0.3 * np.sin(0.21 * k)])
        drone = np.array([12.0, -3.0, 4.0]) + wander + rng.normal(0, 0.03, 3)
        tables.append(_table([(drop.copy(), 0.0, 1), (drone, 0.3, 6)]))
    on = TrackingConfig()
    off = TrackingConfig(min_cross_section_m2=1e-9)
    for cfg, drone_wins in ((on, True), (off, False)):
        _, chain = _run(tables, cfg)
        assert chain
        assert all(tr.positions[0, 0] > 10 for tr, _, _ in chain) == drone_wins


def test_records_keep_ended_tracks_and_drop_lone_detections() -> None:
    """An object followed for a while and then gone is still a candidate at the end; a lone
    return is no track (nothing scores one) and leaves nothing behind."""
    cfg = TrackingConfig()
    rng = np.random.default_rng(3)
    tracker = CandidateTracker(cfg)
    n = 200
    for k in range(n):
        items: list[tuple[np.ndarray, float, int]] = []
        if k < 30:  # seen for 3 s, then gone for good (long past max_miss_s)
            items.append((np.array([8.0 + 0.5 * k * 0.1, 2.0, 3.0]), 0.3, 10))
        # speckle: one return somewhere new every frame
        items.append((rng.uniform([-30, -30, 0], [30, 30, 10]), 0.0, 1))
        tracker.step(k, k * 0.1, _table(items))
    records = tracker.records()
    assert all(len(r.frames) >= 2 for r in records)
    ended = [r for r in records if r.frames[0] == 0]
    assert len(ended) == 1 and len(ended[0].frames) == 30
    ids = [r.track_id for r in records]
    assert ids == sorted(ids) and tracker.next_id > max(ids)


def test_crowding_counts_neighbours_about_as_substantial_within_the_radius() -> None:
    # a ten-point drone cluster among single rain returns: the returns crowd each other, not
    # it, nor it them; a six-point cluster beside it crowds it and is crowded by it (within a
    # factor of two either way)
    centroid = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.0, 1, 0], [0.0, -1, 0], [10.0, 0, 0]])
    n_points = np.array([10, 1, 1, 6, 1])
    np.testing.assert_array_equal(crowding(centroid, n_points, 3.0), [1, 1, 1, 1, 0])
    np.testing.assert_array_equal(crowding(centroid, n_points, 0.0), [0, 0, 0, 0, 0])
    assert len(crowding(np.zeros((0, 3)), np.zeros(0, dtype=np.int64), 3.0)) == 0


def _scored(
    track_id: int,
    times: np.ndarray,
    positions: np.ndarray,
    points: np.ndarray,
    cfg: TrackingConfig | None = None,
) -> ScoredTrack:
    """A scored track whose detections each weigh 1 (its motion as ``score_tracks`` takes it
    under ``cfg``, default the defaults)."""
    h = len(times)
    rec = TrackRecord(
        track_id,
        np.arange(h),
        np.zeros(h, dtype=np.int64),
        positions,
        points.astype(np.int64),
        np.ones(h),
        np.zeros(h),
    )
    velocity = windowed_velocity(times, positions, (cfg or TrackingConfig()).link_velocity_s)
    return ScoredTrack(rec, times, positions, velocity, np.ones(h), float(h))


def _lost_then_found(tail_points: int) -> tuple[ScoredTrack, ScoredTrack]:
    """Track 1 follows the drone (20 returns a detection) for 4 s, then coasts 2 s on
    detections of ``tail_points`` returns that lead away at 8.5 m/s; track 2 is the drone again,
    8 m from where it was last seen, farther than any speed from track 1's end."""
    t_a = np.arange(60) * 0.1
    drone = np.column_stack([10 + 2.0 * t_a[:40], np.zeros(40), np.full(40, 5.0)])
    stray = drone[-1] + np.outer(np.arange(1, 21) * 0.1, [-6.0, 6.0, 0.0])
    a = _scored(1, t_a, np.vstack([drone, stray]), np.r_[np.full(40, 20), np.full(20, tail_points)])
    t_b = 6.0 + np.arange(30) * 0.1
    b_pos = drone[-1] + np.array([8.0, 0.0, 0.0]) + np.outer(t_b - 6.0, [2.0, 0.0, 0.0])
    return a, _scored(2, t_b, b_pos, np.full(30, 20))


def test_a_link_drops_a_tail_of_single_returns_that_strayed_but_not_a_steady_track() -> None:
    cfg = TrackingConfig()
    a, b = _lost_then_found(tail_points=1)
    assert np.linalg.norm(b.positions[0] - a.positions[-1]) > cfg.link_speed * 0.1 + 1.0
    chain = [(tr.record.track_id, i0, i1) for tr, i0, i1 in select_chain([a, b], cfg)]
    assert len(chain) == 2 and chain[1] == (2, 0, 30)
    _, i0, i1 = chain[0]
    assert 40 <= i1 < 60  # the drone's part kept, the tail's end (out of reach) dropped
    # the same track with a steady tail (as many returns as before) is not cut
    a, b = _lost_then_found(tail_points=20)
    assert [tr.record.track_id for tr, _, _ in select_chain([a, b], cfg)] == [1]
    # the switch off: links leave at the next track's start only
    a, b = _lost_then_found(tail_points=1)
    off = TrackingConfig(link_tail_ratio=0.0)
    assert [tr.record.track_id for tr, _, _ in select_chain([a, b], off)] == [1]


def test_a_link_carries_the_earlier_tracks_motion_across_the_gap() -> None:
    # a pass at 18 m/s tracked for 1 s, unseen for 0.8 s, then tracked again 14.4 m on: beyond
    # link_speed's reach from where it was last seen, within it from where its motion carried
    # it (a drone cruising at 15-23 m/s is no slower across a gap than while it is seen)
    cfg = TrackingConfig()

    def path(t: np.ndarray, speed: float = 18.0) -> np.ndarray:
        return np.column_stack([-20.0 + speed * t, np.full(len(t), 15.0), np.full(len(t), 5.0)])

    t_a, t_b = np.arange(10) * 0.1, 1.7 + np.arange(10) * 0.1
    a, b = _scored(1, t_a, path(t_a), np.full(10, 2)), _scored(2, t_b, path(t_b), np.full(10, 2))
    assert np.linalg.norm(b.positions[0] - a.positions[-1]) > cfg.link_speed * 0.8 + 1.0
    assert [tr.record.track_id for tr, _, _ in select_chain([a, b], cfg)] == [1, 2]
    # the switch off: reached from where it was only
    off = TrackingConfig(link_velocity_s=0.0)
    assert len(select_chain([_scored(1, t_a, path(t_a), np.full(10, 2), off), b], off)) == 1
    # the same jump from a track that ended there moving the other way at speed: no link (its
    # speed added to the reach in every direction would allow it)
    away = a.positions[-1] + np.outer(t_a - t_a[-1], [-18.0, 0.0, 0.0])
    back = _scored(1, t_a, away, np.full(10, 2))
    assert len(select_chain([back, b], cfg)) == 1


def _weak(tr: ScoredTrack, weight: float) -> ScoredTrack:
    """The track with each detection weighing ``weight`` (judged static, say)."""
    contribution = np.full(len(tr.times_s), weight)
    return replace(tr, contribution=contribution, score=float(contribution.sum()))


def test_the_chain_is_carried_on_by_weak_tracks_that_touch_it_and_by_nothing_else() -> None:
    cfg = TrackingConfig()
    t = np.arange(20) * 0.1
    still = np.tile([5.0, 0.0, 3.0], (20, 1))
    # the drone hovers for 2 s (judged static: its detections weigh little), then flies off
    hover = _weak(_scored(1, t, still, np.full(20, 20)), 0.05)
    t_fly = 2.1 + np.arange(40) * 0.1
    fly = _scored(2, t_fly, still[0] + np.outer(t_fly - 2.0, [2.0, 0.0, 0.0]), np.full(40, 20))
    # something else meanwhile, 10 m away: more evidence than the hover, out of reach
    other = _weak(_scored(3, t, still + [10.0, 0.0, 0.0], np.full(20, 20)), 0.5)
    # after the flight: a weak track where it ended, 0.3 s later; one that starts too late
    end = fly.positions[-1]
    t_on = fly.times_s[-1] + 0.3 + np.arange(10) * 0.1
    on = _weak(_scored(4, t_on, np.tile(end, (10, 1)), np.full(10, 20)), 0.1)
    # right after that, three near-weightless returns (what clutter makes by chance)
    speck = _weak(
        _scored(6, t_on[-1] + 0.1 + np.arange(3) * 0.1, np.tile(end, (3, 1)), np.ones(3)), 0.03
    )
    late = _weak(_scored(5, t_on + 2.0, np.tile(end, (10, 1)), np.full(10, 20)), 0.05)
    tracks = [hover, fly, other, on, late, speck]
    chain = select_chain(tracks, cfg)
    assert [tr.record.track_id for tr, _, _ in chain] == [2]  # too weak to be worth a link
    extended = [(tr.record.track_id, i0, i1) for tr, i0, i1 in extend_chain(chain, tracks, cfg)]
    assert extended == [(1, 0, 20), (2, 0, 40), (4, 0, 10)]
    # switched off, the chain stays as chosen
    off = TrackingConfig(extend_gap_s=0.0)
    assert [tr.record.track_id for tr, _, _ in extend_chain(chain, tracks, off)] == [2]
    # without the evidence floor the specks carry it on too
    bare = TrackingConfig(extend_min_evidence=0.0)
    assert [tr.record.track_id for tr, _, _ in extend_chain(chain, tracks, bare)] == [1, 2, 4, 6]


def _chained_blob(rng: np.random.Generator, around: np.ndarray) -> np.ndarray:
    """A drone's 30 returns within 0.15 m of ``around``, strung by lone returns 0.8 m apart
    (rain near the sensor) to 4 m away: the 1 m linkage makes one cluster of them."""
    blob = around + rng.normal(0.0, 0.05, (30, 3))
    chain = around + np.outer(np.arange(1, 6) * 0.8, [1.0, 0.0, 0.0]) + rng.normal(0, 0.02, (5, 3))
    return np.concatenate([blob, chain])


def _carve(points: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 1 m linkage's labels of ``points``, and those after ``carve_tracked`` at ``centres``
    (gate 0.6 m, drones up to 1.2 m)."""
    from cldet.core.clustering import cluster_points, summarize_clusters
    from cldet.core.tracking import carve_tracked

    labels = cluster_points(points, 1.0, 1)
    extent = ClusterTable.from_clusters(summarize_clusters(points, labels)).extent
    return labels, carve_tracked(points, labels, extent, centres, 0.6, 1.2)


def test_a_tracked_blob_chained_to_rain_is_carved_out_of_the_wide_cluster() -> None:
    rng = np.random.default_rng(0)
    drone = np.array([3.0, 1.0, 1.0])
    pts = _chained_blob(rng, drone)
    labels, out = _carve(pts, drone[None, :] + 0.2)
    assert np.all(labels == 0)  # merged: the cluster's centroid lies 0.5 m from the drone
    assert np.all(out[:30] == 1) and np.all(out[30:] == 0)
    # no track predicted there, or none in a wide cluster: nothing changes
    assert np.array_equal(_carve(pts, np.zeros((0, 3)))[1], labels)
    assert np.array_equal(_carve(pts, drone[None, :] + 3.0)[1][:30], labels[:30])
    alone, out = _carve(pts[:30], drone[None, :])
    assert np.array_equal(out, alone)


def test_a_tracked_piece_of_a_wider_surface_is_not_carved_out() -> None:
    # a track on a piece of a hedge (3 m by 1 m of returns 0.1 m apart) or of a railing (3 m,
    # returns 5 cm apart) predicts into it, but the returns around that piece are about as
    # many as within it (the hedge is no taller than the gate is wide), or a body below it: no
    # compact object there. Nor is a drone a little wider than max_size_m split from its arms:
    # its cluster does not reach beyond the shell, it merged with nothing
    yy, zz = np.meshgrid(np.arange(0.0, 3.0, 0.1), np.arange(0.0, 1.0, 0.1))
    hedge = np.stack([np.full(yy.size, 5.0), yy.ravel(), zz.ravel()], axis=1)
    rail = np.column_stack([np.full(60, 5.0), np.arange(60) * 0.05, np.full(60, 0.5)])
    # a person 1.8 m tall, a track on their head and shoulders (their legs hidden a while)
    rng = np.random.default_rng(1)
    az, z = rng.uniform(0, 2 * np.pi, 400), rng.uniform(0.0, 1.8, 400)
    person = np.column_stack([5.0 + 0.2 * np.cos(az), 1.5 + 0.2 * np.sin(az), z])
    # a drone a little wider than max_size_m: a dense body, a few returns on its arms
    body = rng.normal(0.0, 0.1, (40, 3)) + [5.0, 1.5, 0.5]
    arms = np.array([[5.0 + x, 1.5, 0.5] for x in (-0.7, -0.65, 0.65, 0.7)])
    drone = np.concatenate([body, arms])
    for surface in (hedge, rail, person, drone):
        labels, out = _carve(surface, np.array([[5.0, 1.5, 0.5 if surface is not person else 1.6]]))
        assert np.array_equal(out, labels)


def test_the_chain_drops_a_head_of_lone_returns_but_not_a_far_drone_approaching() -> None:
    cfg = TrackingConfig(crowd_radius_m=0.0)

    def chain_start(items: list[tuple[np.ndarray, float, int]]) -> tuple[int, int]:
        """The chain's first hit index, with chain_head_ratio and without."""
        tables = [_table([item]) for item in items]
        out = []
        for ratio in (0.25, 0.0):
            _, chain = _run(tables, cfg.model_copy(update={"chain_head_ratio": ratio}))
            assert len(chain) == 1 and len(chain[0][0].times_s) == len(tables)
            out.append(chain[0][1])
        return out[0], out[1]

    # a track begun on lone returns (rain, up to 1.3 m from the drone) that its gate led onto
    # a drone 3 m out, 40 returns a scan
    step = 0.25 * np.array([1.0, 0.3, 0.1])
    rain = [(np.array([3.0, 0.0, 1.0]) - (5 - k) * step, 0.0, 1) for k in range(5)]
    drone = [(np.array([3.0, 0.1 * k, 1.0]), 0.3, 40) for k in range(20)]
    assert chain_start(rain + drone) == (5, 0)
    # a drone passing at 6 m/s from 15 m out to 3 m and on: few returns far out, as many per
    # area as near
    path = [np.array([15.0 - 0.6 * k, 3.0, 1.0]) for k in range(30)]
    passing = [(p, 0.3, max(1, round(40 * (3.0 / np.linalg.norm(p)) ** 2))) for p in path]
    assert chain_start(passing) == (0, 0)


def _lagged_crossing(
    speed: float, start: tuple[float, float, float], n: int = 40
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A drone crossing along x at ``speed`` m/s from ``start``, seen once a scan (10 Hz) at a
    random instant of the 100 ms scan: per scan, that instant's lag after the frame's time, the
    position seen then (3 cm noise) and the position at the frame's time."""
    rng = np.random.default_rng(4)
    lags = rng.uniform(-0.05, 0.05, n)
    noise = rng.normal(0, 0.03, (n, 3))
    t = 0.1 * np.arange(n)
    path = np.asarray(start) + speed * np.outer(t, [1.0, 0.0, 0.0])
    return lags, path + speed * np.outer(lags, [1.0, 0.0, 0.0]) + noise, path


def _step_crossing(
    tracker: CandidateTracker, lags: np.ndarray, seen: np.ndarray, known: bool
) -> Iterator[int]:
    """Feed ``tracker`` the crossing's detections, with their lags where ``known``; yields each
    scan's index after its step."""
    for k, at in enumerate(seen):
        table = replace(_table([(at, 0.3, 3)]), dt=np.array([lags[k]]) if known else None)
        tracker.step(k, 0.1 * k, table)
        yield k


def test_a_fast_drone_dated_inside_the_scan_is_tracked_with_the_right_speed() -> None:
    """A drone crossing at 20 m/s, seen once a scan at a random instant of the 100 ms scan
    (where in the scan it was hit decides where it was): with the lags known
    (``ClusterTable.dt``) one track follows it all the way, at the right speed, with consistent
    innovations; dated at the frame's time instead, each detection is off by up to 1 m along
    the path, and the track breaks up. An undated tracker (``dated=False``) keeps the lags with
    its detections, for the fits over them, and tracks as if they were unknown."""
    cfg = TrackingConfig()
    lags, seen, _ = _lagged_crossing(20.0, (-40.0, 15.0, 8.0))
    n = len(lags)

    def records(known: bool, dated: bool = True) -> list[TrackRecord]:
        tracker = CandidateTracker(cfg, dated=dated)
        for _ in _step_crossing(tracker, lags, seen, known):
            pass
        return tracker.records()

    # a track is born at rest (its speed unknown, 5 m/s sigma): at 20 m/s the first two births
    # lose it; the third follows it to the end
    rec = max(records(known=True), key=lambda r: len(r.frames))
    assert len(rec.frames) >= 0.85 * n and rec.frames[-1] == n - 1
    assert rec.dt is not None and np.allclose(rec.dt, lags[rec.frames])
    assert np.median(np.abs(rec.speed[5:] - 20.0)) < 0.2  # m/s
    assert np.nanmedian(rec.nis[5:]) < 3.0  # chi^2, 3 dof: a consistent filter's median is 2.4
    blind = records(known=False)
    assert len(blind) > 1 and max(len(r.frames) for r in blind) < n / 2
    undated = records(known=True, dated=False)
    assert [r.frames.tolist() for r in undated] == [r.frames.tolist() for r in blind]
    for r, b in zip(undated, blind, strict=True):
        np.testing.assert_array_equal(r.positions, b.positions)
        np.testing.assert_array_equal(r.speed, b.speed)
        assert r.dt is not None and np.allclose(r.dt, lags[r.frames])


def test_an_undated_trackers_output_state_measures_each_detection_at_its_lag() -> None:
    """An undated tracker associates as if each detection were seen at the frame's time; its
    output states (``active``, what the causal estimate reports) measure each at its lag. A
    drone crossing at 8 m/s, seen once a scan at a random instant of it: one track all along
    either way, and the output state at each frame's time about 4 cm from the drone, against
    15 cm with the lags unknown (up to 0.4 m along the path for each detection)."""
    lags, seen, path = _lagged_crossing(8.0, (-15.0, 15.0, 8.0))

    def output_rms(known: bool) -> float:
        tracker = CandidateTracker(TrackingConfig(), dated=False)
        errors = []
        for k in _step_crossing(tracker, lags, seen, known):
            (position,) = tracker.active().position
            errors.append(np.linalg.norm(position - path[k]))
        assert [len(r.frames) for r in tracker.records()] == [len(lags)]
        return float(np.sqrt(np.mean(np.square(errors[5:]))))

    assert output_rms(known=True) < 0.06 and output_rms(known=False) > 0.1


def test_windowed_velocity_is_the_fit_of_each_detections_recent_past() -> None:
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.05, 0.3, 40))
    p = rng.normal(size=(40, 3))
    v = windowed_velocity(t, p, 0.5)
    for k in range(40):
        recent = (t >= t[k] - 0.5) & (t <= t[k])
        fit = constant_velocity_fit(t[recent], p[recent])[1] if recent.sum() > 1 else np.zeros(3)
        np.testing.assert_allclose(v[k], fit, atol=1e-9)
    assert not windowed_velocity(t, p, 0.0).any()  # each detection alone: no motion
