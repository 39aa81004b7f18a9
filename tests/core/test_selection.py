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
