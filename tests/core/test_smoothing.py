"""Tests of the constant-velocity Kalman filter, the RTS smoother and the end extrapolation."""

from __future__ import annotations

import numpy as np
import pytest

from cldet.config import SmoothingConfig
from cldet.core.smoothing import (
    KalmanCV,
    decay_tau,
    extrapolate,
    rts_smooth,
    straight_run,
)

_MIN_POINTS = SmoothingConfig().straight_min_points  # the configuration's default


def _trajectory(t: np.ndarray) -> np.ndarray:
    """A smooth 3D flight: a slow turn and a climb (speeds of a few m/s)."""
    return np.stack([8 * np.cos(0.3 * t), 8 * np.sin(0.3 * t), 2 + 0.5 * t], axis=1)


def test_rts_on_a_known_trajectory_with_gaps() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(0, 12, 0.1)
    truth = _trajectory(t)
    sigma = 0.1
    z = truth + rng.normal(0, sigma, truth.shape)
    gap = (t > 4.0) & (t < 5.5)  # 1.5 s unseen
    drop = rng.random(len(t)) < 0.2  # and a fifth of the frames missing
    z[gap | drop] = np.nan
    sm = rts_smooth(t, z, np.full(len(t), sigma), q=2.0)
    err = np.linalg.norm(sm.position - truth, axis=1)
    seen = ~(gap | drop)
    assert np.sqrt(np.mean(err[seen] ** 2)) < sigma  # better than one measurement
    assert err[gap].max() < 0.5  # the gap is bridged, not held
    assert sm.measured.sum() == seen.sum()
    # the uncertainty grows inside the gap and is smallest where measured
    assert sm.pos_var[gap].max() > 2 * np.median(sm.pos_var[seen])
    # the velocity is recovered
    v_true = np.gradient(truth, t, axis=0)
    assert np.median(np.linalg.norm(sm.velocity - v_true, axis=1)) < 0.3


def test_rts_extrapolates_before_the_first_measurement() -> None:
    t = np.arange(0, 3, 0.1)
    truth = np.stack([1.0 * t, np.zeros_like(t), np.ones_like(t)], axis=1)
    z = truth.copy()
    z[:10] = np.nan
    sm = rts_smooth(t, z, np.full(len(t), 0.01), q=0.1)
    np.testing.assert_allclose(sm.position[0], truth[0], atol=0.05)
    assert sm.pos_var[0] > sm.pos_var[15]


def test_rts_errors() -> None:
    t = np.arange(3.0)
    with pytest.raises(ValueError, match="at least one measurement"):
        rts_smooth(t, np.full((3, 3), np.nan), np.ones(3), q=1.0)
    with pytest.raises(ValueError, match="shapes"):
        rts_smooth(t, np.zeros((2, 3)), np.ones(3), q=1.0)


def test_kalman_update_reduces_uncertainty_and_nis() -> None:
    kf = KalmanCV(np.zeros(3), 0.1, 5.0)
    kf.predict(0.1, 1.0)
    p_before = kf.P[0, 0]
    nis = kf.update(np.array([0.1, 0.0, 0.0]), 0.1)
    assert kf.P[0, 0] < p_before
    assert nis == pytest.approx(0.01 / (p_before + 0.01))
    kf.predict(-0.1, 1.0)  # backwards is allowed
    assert np.all(np.isfinite(kf.x))


def test_extrapolation_decays_the_velocity() -> None:
    p, v, cov = np.zeros(3), np.array([2.0, 0.0, 0.0]), np.diag([0.01, 0.1])
    near, var_near = extrapolate(p, v, cov, 0.1, q=1.0, tau_s=1.5)
    far, var_far = extrapolate(p, v, cov, 30.0, q=1.0, tau_s=1.5)
    back, _ = extrapolate(p, v, cov, -30.0, q=1.0, tau_s=1.5)
    assert near[0] == pytest.approx(0.2, rel=0.05)  # like constant velocity at first
    assert far[0] == pytest.approx(3.0, rel=1e-3)  # saturates at v * tau
    assert back[0] == pytest.approx(-3.0, rel=1e-3)
    assert var_far > var_near


def test_extrapolation_holds_the_velocity_then_decays() -> None:
    p, v, cov = np.zeros(3), np.array([10.0, 0.0, 0.0]), np.diag([0.01, 0.1])
    held, _ = extrapolate(p, v, cov, 2.0, q=1.0, tau_s=1.5, hold_s=3.0)
    back, _ = extrapolate(p, v, cov, -2.0, q=1.0, tau_s=1.5, hold_s=3.0)
    far, _ = extrapolate(p, v, cov, 60.0, q=1.0, tau_s=1.5, hold_s=3.0)
    assert held[0] == pytest.approx(20.0)  # constant velocity while held
    assert back[0] == pytest.approx(-20.0)
    assert far[0] == pytest.approx(10.0 * (3.0 + 1.5), rel=1e-3)  # then decays to v*(hold+tau)


def test_straight_run_starts_where_the_flight_turned() -> None:
    # 2 s of a tight turn, then 4 s straight at 12 m/s, detections every 0.1 s with 0.15 m noise
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 6.0, 0.1)
    turn = np.stack([3 * np.sin(2 * t), 3 * np.cos(2 * t) - 3, 0 * t], axis=1)
    exit_p, exit_v = turn[19], np.array([6 * np.cos(2 * t[19]), -6 * np.sin(2 * t[19]), 0.0])
    direction = exit_v / np.linalg.norm(exit_v)
    straight = exit_p + np.outer(t - t[19], 12.0 * direction)
    z = np.where((t < t[19] + 1e-9)[:, None], turn, straight) + rng.normal(0, 0.15, (len(t), 3))
    run = straight_run(t, z, 0.4, 0.0, _MIN_POINTS)
    assert run is not None
    assert run.duration_s == pytest.approx(t[-1] - t[19], abs=0.35)  # begins at the turn
    np.testing.assert_allclose(run.velocity, 12.0 * direction, atol=0.3)
    # a random walk of the same scale is never straight for long
    walk = np.cumsum(rng.normal(0, 1.0, (len(t), 3)), axis=0)
    walk_run = straight_run(t, walk, 0.4, 0.0, _MIN_POINTS)
    assert walk_run is None or walk_run.duration_s < 1.0


def test_straight_run_allows_for_the_smear_of_a_scan() -> None:
    # at 20 m/s a 0.1 s scan spreads a detection's points over 2 m: centroids scatter ~0.6 m
    # along the path; straight only once the scan's smear is allowed for
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 3.0, 0.1)
    v = np.array([20.0, 0.0, 0.0])
    z = np.outer(t, v) + np.outer(rng.uniform(-1.0, 1.0, len(t)), v / 20.0)
    no_smear = straight_run(t, z, 0.3, 0.0, _MIN_POINTS)
    assert no_smear is None or no_smear.duration_s < 1.0
    run = straight_run(t, z, 0.3, 0.1, _MIN_POINTS)
    assert run is not None and run.duration_s == pytest.approx(t[-1])
    # where the run ends: the fitted line at the last detection's time lies far nearer the
    # path than the last (smeared) detection does, so extrapolation starts from the line
    end = t[-1] * v
    assert np.linalg.norm(run.position - end) < 0.2 < np.linalg.norm(z[-1] - end)


@pytest.mark.parametrize("speed", [0.5, 3.0, 10.0, 20.0, 30.0])
def test_the_extrapolated_velocity_decays_no_faster_than_a_drone_brakes(speed: float) -> None:
    # whatever the speed, the decayed extrapolation never stops short of where a multirotor
    # braking as hard as it can (6 m/s^2) would still be: v t - a t^2 / 2 until it stops
    a, tau = 6.0, 1.5
    v = np.array([speed, 0.0, 0.0])
    t = np.linspace(0.0, 10.0, 101)
    braking = np.where(t < speed / a, speed * t - 0.5 * a * t**2, speed**2 / (2 * a))

    def travelled(max_decel: float) -> np.ndarray:
        tau_s = decay_tau(v, tau, max_decel)
        return np.array(
            [extrapolate(np.zeros(3), v, np.zeros((2, 2)), d, 0.0, tau_s)[0][0] for d in t]
        )

    assert np.all(travelled(a) >= braking - 1e-9)
    assert decay_tau(v, tau, a) == max(tau, speed / a)
    assert decay_tau(v, tau, 0.0) == tau  # off
    if speed / a > tau:  # the bare 1.5 s decay stops a fast drone sooner than it can brake
        assert np.any(travelled(0.0) < braking - 1e-6)
    if speed >= 20.0:  # by metres: 3.3 m at 20 m/s, 30 m at 30 m/s
        assert np.min(travelled(0.0) - braking) < -3.0
