"""Track scoring helpers (cldet.core.selection)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from cldet.config import load_config
from cldet.core.estimator import _weigher
from cldet.core.features import FEATURE_NAMES
from cldet.core.prior import load_prior
from cldet.core.selection import LEARNED_FLOOR, TrackWeigher


def test_learned_weighings_multiply_each_within_its_floor() -> None:
    def half(f: Any) -> Any:
        return np.full(len(f), 0.5)

    def sure(f: Any) -> Any:
        return np.ones(len(f))

    weigher = TrackWeigher(((half, 0.2), (sure, 0.5)))
    assert weigher.floor == pytest.approx(0.1)
    np.testing.assert_allclose(weigher(np.zeros((3, 4))), [0.6, 0.6, 0.6])


def test_a_models_scorer_weighs_with_the_prior_unless_the_prior_is_off() -> None:
    # a model that calls every track clutter: it weighs each by its floor alone
    model: Any = SimpleNamespace(scorer=object(), drone_probability=lambda f: np.zeros(len(f)))
    features = np.random.default_rng(0).uniform(0.0, 5.0, (4, len(FEATURE_NAMES)))
    prior = load_prior()
    with_prior = _weigher(model, load_config().tracking)
    off = load_config(overrides={"tracking": {"prior_scorer": False}}).tracking
    alone = _weigher(model, off)
    assert with_prior is not None and alone is not None
    np.testing.assert_allclose(alone(features), LEARNED_FLOOR)
    expected = LEARNED_FLOOR * (prior.floor + (1 - prior.floor) * prior.drone_probability(features))
    np.testing.assert_allclose(with_prior(features), expected)
    assert with_prior.floor == pytest.approx(LEARNED_FLOOR * prior.floor)
    assert _weigher(None, off) is None


def _face_centroids(
    rng: np.random.Generator, centres: np.ndarray, edge_m: float, n_points: int
) -> np.ndarray:
    """Each scan's centroid of ``n_points`` returns on a square face of ``edge_m`` facing the
    sensor along x (2 cm range noise): which parts a scan happens to hit moves the centroid of
    even a rigid object."""
    offsets = rng.uniform(-edge_m / 2, edge_m / 2, (len(centres), n_points, 3))
    offsets[:, :, 0] = rng.normal(0.0, 0.02, (len(centres), n_points))
    return centres + offsets.mean(axis=1)


def test_a_rigid_object_is_fixed_within_its_sampling_jitter_and_a_hovering_drone_is_not() -> None:
    # a balcony corner 0.7 m across, 20 returns a scan for 4 s: its centroid jitters by ~4 cm
    # with the parts each scan hits, more than the fixed 2.5 cm; a drone 0.3 m across (6
    # returns) hovering beside it wanders by 10 cm (its position controller, the wind)
    from cldet.core.selection import _is_fixed, fixed_spread, sampling_jitter

    rng = np.random.default_rng(0)
    t = np.arange(40) * 0.1
    still = np.tile([5.3, 0.0, 1.9], (40, 1))
    tc = load_config().tracking
    rigid_jitter = float(np.median(sampling_jitter(np.full(40, 0.7), np.full(40, 20))))
    drone_jitter = float(np.median(sampling_jitter(np.full(40, 0.3), np.full(40, 6))))
    assert rigid_jitter == pytest.approx(0.7 / np.sqrt(240))
    assert fixed_spread(tc, rigid_jitter) == pytest.approx(rigid_jitter)  # beyond 2.5 cm
    rigid = [_face_centroids(rng, still, 0.7, 20) for _ in range(200)]
    alone = np.mean([_is_fixed(t, r, 0.025) for r in rigid])
    caught = np.mean([_is_fixed(t, r, fixed_spread(tc, rigid_jitter)) for r in rigid])
    assert alone < 0.1, alone  # 2.5 cm alone misses nearly all
    assert caught > 0.6, caught  # about three in four: the rule's p90 sits near the theory's
    drones = []
    for _ in range(200):
        phase = rng.uniform(0, 2 * np.pi, 3)
        wander = 0.1 * np.sin(np.outer(t, [1.3, 0.9, 2.1]) + phase)
        drones.append(_face_centroids(rng, still + [0.9, 0.2, 4.2] + wander, 0.3, 6))
    assert not any(_is_fixed(t, d, fixed_spread(tc, drone_jitter)) for d in drones)


def test_rigid_now_forgives_a_tracks_head_and_not_a_hover_that_keeps_still_a_while() -> None:
    # a sign seen for 4 s whose track began on clutter 1.5 m below it (its first four scans
    # climb onto it): judged after its first second, rigid. A drone hovering for 6 s wanders by
    # decimetres for 3.8 s, then keeps still to a centimetre: judged on all but its first
    # second, not rigid; judged on its still part alone (a window of its last 2.2 s) it would
    # look rigid
    from cldet.core.selection import _is_fixed, fixed_spread, rigid_now

    rng = np.random.default_rng(1)
    tc = load_config().tracking
    t = np.arange(40) * 0.1
    sign = np.tile([3.0, 1.0, 2.5], (40, 1)) + rng.normal(0.0, 0.003, (40, 3))
    sign[:4, 2] -= [1.5, 1.1, 0.7, 0.3]
    assert rigid_now(t, sign, 0.0, tc, 1.0)
    assert not _is_fixed(t, sign, fixed_spread(tc, 0.0))  # all of it: the head spoils it
    t6 = np.arange(60) * 0.1
    settle = np.clip((3.8 - t6) / 3.8, 0.0, None)[:, None]  # wanders, then keeps still
    drone = 5.0 + 0.15 * settle * np.sin(np.outer(t6, [1.3, 0.9, 2.1]))
    drone = drone + rng.normal(0.0, 0.003, drone.shape)
    assert not rigid_now(t6, drone, 0.0, tc, 1.0)
    assert rigid_now(t6, drone, 0.0, tc, 3.8)


def _record(positions: np.ndarray, track_id: int = 7, first_frame: int = 0) -> Any:
    """A raw-gate track record (no cluster tables needed) of one detection per 0.1 s frame."""
    from cldet.core.tracking import TrackRecord

    h = len(positions)
    return TrackRecord(
        track_id=track_id,
        frames=np.arange(first_frame, first_frame + h, dtype=np.int64),
        clusters=np.full(h, -1, dtype=np.int64),
        positions=positions,
        n_points=np.full(h, 12, dtype=np.int64),
        nis=np.r_[np.nan, np.ones(h - 1)],
        speed=np.full(h, 1.0),
    )


def test_tracks_that_swap_a_drone_and_a_sign_are_cut_where_each_sits_on_the_sign() -> None:
    # a sign (5 mm of noise) tracked on its own for 2.5 s; a drone flies past it at 3 m/s, and
    # the two tracks swap objects: the drone's keeps the sign for 3 s, the sign's follows the
    # drone away. Each is cut where it sits on the sign: the sign's parts judged fixed, the
    # drone's not, and the drone's parts are whole tracks again for the chain to link
    from cldet.core.selection import _is_fixed, fixed_spread, split_rigid

    rng = np.random.default_rng(3)
    tc = load_config().tracking
    sign_at = np.array([4.0, 1.0, 3.0])
    fly_in = sign_at + np.outer(np.arange(-25, 0) * 0.1, [3.0, 0.0, 0.0])
    fly_out = sign_at + np.outer(np.arange(1, 31) * 0.1, [0.0, 3.0, 0.0])
    drone_then_sign = _record(np.vstack([fly_in, sign_at + rng.normal(0, 0.005, (30, 3))]), 7)
    sign_then_drone = _record(np.vstack([sign_at + rng.normal(0, 0.005, (25, 3)), fly_out]), 9)
    times = np.arange(60) * 0.1
    parts = split_rigid([drone_then_sign, sign_then_drone], [], times, tc)
    assert [(p.track_id, len(p.frames)) for p in parts] == [(7, 25), (10, 30), (9, 25), (11, 30)]
    assert all(np.isnan(p.nis[0]) for p in parts)  # each part is born again
    for whole, pieces in ((drone_then_sign, parts[:2]), (sign_then_drone, parts[2:])):
        np.testing.assert_array_equal(np.concatenate([p.frames for p in pieces]), whole.frames)
    fixed = [_is_fixed(times[p.frames], p.positions, fixed_spread(tc, 0.0)) for p in parts]
    assert fixed == [False, True, True, False]


def test_split_rigid_leaves_a_still_hover_a_wholly_fixed_track_and_the_switch_off_alone() -> None:
    # a drone that flies in and then hovers still to millimetres, where no other track shows a
    # fixed object, is not cut (its hover may be as still as a sign: only the sign's own track
    # tells structure). A sign's track fixed from end to end is judged whole. Switched off, a
    # track that ends on a sign another track shows is left whole too
    from cldet.core.selection import split_rigid

    rng = np.random.default_rng(4)
    tc = load_config().tracking
    spot = np.array([6.0, -2.0, 4.0])
    fly = spot + np.outer(np.arange(-20, 0) * 0.1, [0.0, 2.5, 0.0])
    hover = _record(np.vstack([fly, spot + rng.normal(0.0, 0.005, (30, 3))]))
    elsewhere = _record(spot + [3.0, 0.0, 0.0] + rng.normal(0.0, 0.005, (40, 3)), track_id=9)
    times = np.arange(60) * 0.1
    assert split_rigid([hover, elsewhere], [], times, tc) == [hover, elsewhere]
    sign = _record(spot + rng.normal(0.0, 0.005, (25, 3)), track_id=9, first_frame=50)
    times = np.arange(80) * 0.1
    off = load_config(overrides={"tracking": {"split_rigid": False}}).tracking
    assert split_rigid([hover, sign], [], times, off) == [hover, sign]
    cut = split_rigid([hover, sign], [], times, tc)
    assert [len(p.frames) for p in cut] == [20, 30, 25] and cut[2] is sign
