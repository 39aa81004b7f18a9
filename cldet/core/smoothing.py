"""Constant-velocity Kalman filter and Rauch-Tung-Striebel smoother for one 3D track.

The motion model is constant velocity driven by white acceleration of power spectral density
``q`` (m^2/s^3), the same on x, y and z, and measurements are isotropic 3D positions. With the
same model on every axis and isotropic noise, the three axes share one 2x2 covariance
(position, velocity) and never correlate, so a track is a (3,2) state [position, velocity per
axis] and a single 2x2 covariance: cheap, and exact for this model.

Times are seconds here (relative to any origin); the estimator converts from integer ns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "KalmanCV",
    "SmoothedTrack",
    "decay_tau",
    "extrapolate",
    "process_noise",
    "rts_smooth",
    "straight_run",
    "transition",
]


def transition(dt: float) -> NDArray[np.float64]:
    """(2,2) constant-velocity transition over ``dt`` seconds."""
    return np.array([[1.0, dt], [0.0, 1.0]])


def process_noise(dt: float, q: float) -> NDArray[np.float64]:
    """(2,2) process noise of white acceleration with PSD ``q`` over ``dt`` seconds."""
    dt = abs(dt)
    return q * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])


class KalmanCV:
    """One constant-velocity track: state (3,2) [position, velocity] per axis, covariance (2,2)."""

    def __init__(
        self, position: NDArray[np.floating], pos_sigma: float, speed_sigma: float
    ) -> None:
        self.x = np.zeros((3, 2))
        self.x[:, 0] = position
        self.P = np.diag([pos_sigma**2, speed_sigma**2])

    def predict(self, dt: float, q: float) -> None:
        """Advance by ``dt`` seconds (may be negative: a backward prediction)."""
        F = transition(dt)
        self.x = self.x @ F.T
        self.P = F @ self.P @ F.T + process_noise(dt, q)

    def innovation(
        self, z: NDArray[np.floating], sigma: float
    ) -> tuple[NDArray[np.float64], float]:
        """Innovation (3,) of a position ``z`` and its per-axis variance S."""
        return np.asarray(z, dtype=np.float64) - self.x[:, 0], float(self.P[0, 0] + sigma**2)

    def nis(self, z: NDArray[np.floating], sigma: float) -> float:
        """Normalised innovation squared (chi^2 with 3 dof under the model)."""
        nu, s = self.innovation(z, sigma)
        return float(nu @ nu / s)

    def update(self, z: NDArray[np.floating], sigma: float) -> float:
        """Fuse a position measurement of 1-sigma ``sigma``; returns its NIS."""
        nu, s = self.innovation(z, sigma)
        gain = self.P[:, 0] / s  # (2,)
        self.x = self.x + np.outer(nu, gain)
        self.P = self.P - np.outer(gain, self.P[0, :])
        self.P = 0.5 * (self.P + self.P.T)
        return float(nu @ nu / s)

    @property
    def position(self) -> NDArray[np.float64]:
        return self.x[:, 0].copy()

    @property
    def velocity(self) -> NDArray[np.float64]:
        return self.x[:, 1].copy()


@dataclass(frozen=True)
class SmoothedTrack:
    """Result of the forward-backward smoother at every input time."""

    position: NDArray[np.float64]  # (T,3) metres
    velocity: NDArray[np.float64]  # (T,3) m/s
    pos_var: NDArray[np.float64]  # (T,) per-axis position variance, m^2
    cov: NDArray[np.float64]  # (T,2,2) per-axis [position, velocity] covariance
    measured: NDArray[np.bool_]  # (T,) a measurement was fused at this time


def rts_smooth(
    t_s: NDArray[np.floating],
    z: NDArray[np.floating],
    sigma: NDArray[np.floating],
    q: float,
    init_speed_sigma: float = 5.0,
) -> SmoothedTrack:
    """Kalman filter forward, Rauch-Tung-Striebel backward, over times ``t_s`` (T,) seconds.

    Args:
        t_s: increasing times, seconds.
        z: (T,3) measured positions; rows with NaN are missing (the filter only predicts).
        sigma: (T,) 1-sigma of each measurement, metres.
        q: white-acceleration PSD, m^2/s^3.
        init_speed_sigma: prior speed uncertainty at the first measurement, m/s.

    Returns:
        Smoothed positions, velocities and per-axis variances at every ``t_s``. Times before
        the first measurement are extrapolated backwards by the smoother itself.

    Raises:
        ValueError: no measurement at all, or shapes disagree.
    """
    t = np.asarray(t_s, dtype=np.float64)
    zz = np.asarray(z, dtype=np.float64)
    n = len(t)
    if zz.shape != (n, 3) or len(sigma) != n:
        raise ValueError(f"shapes disagree: t {t.shape}, z {zz.shape}, sigma {np.shape(sigma)}")
    have = np.all(np.isfinite(zz), axis=1)
    if not have.any():
        raise ValueError("rts_smooth needs at least one measurement")
    first = int(np.argmax(have))
    xf = np.zeros((n, 3, 2))
    Pf = np.zeros((n, 2, 2))
    xp = np.zeros((n, 3, 2))
    Pp = np.zeros((n, 2, 2))
    kf = KalmanCV(zz[first], float(sigma[first]), init_speed_sigma)
    xp[first], Pp[first] = kf.x, kf.P
    xf[first], Pf[first] = kf.x, kf.P
    for k in range(first + 1, n):
        kf.predict(t[k] - t[k - 1], q)
        xp[k], Pp[k] = kf.x, kf.P
        if have[k]:
            kf.update(zz[k], float(sigma[k]))
        xf[k], Pf[k] = kf.x, kf.P
    xs = xf.copy()
    Ps = Pf.copy()
    for k in range(n - 2, first - 1, -1):
        F = transition(t[k + 1] - t[k])
        C = Pf[k] @ F.T @ np.linalg.inv(Pp[k + 1])
        xs[k] = xf[k] + (xs[k + 1] - xp[k + 1]) @ C.T
        Ps[k] = Pf[k] + C @ (Ps[k + 1] - Pp[k + 1]) @ C.T
    for k in range(first - 1, -1, -1):  # before the first measurement: predict backwards
        F = transition(t[k] - t[k + 1])
        xs[k] = xs[k + 1] @ F.T
        Ps[k] = F @ Ps[k + 1] @ F.T + process_noise(t[k + 1] - t[k], q)
    return SmoothedTrack(
        position=xs[:, :, 0].copy(),
        velocity=xs[:, :, 1].copy(),
        pos_var=Ps[:, 0, 0].copy(),
        cov=Ps,
        measured=have,
    )


def extrapolate(
    position: NDArray[np.floating],
    velocity: NDArray[np.floating],
    cov: NDArray[np.floating],
    dt: float,
    q: float,
    tau_s: float,
    hold_s: float = 0.0,
) -> tuple[NDArray[np.float64], float]:
    """Position and per-axis variance ``dt`` seconds (either sign) from an end of the track.

    The velocity holds for ``hold_s`` seconds, then decays with time constant ``tau_s``: the
    displacement is v * (h + tau * (1 - exp(-(|dt| - h) / tau))) with h = min(|dt|, hold_s),
    which saturates at v * (hold_s + tau) instead of growing without bound. The variance is
    the constant-velocity one (cov propagated over the effective time, plus the
    white-acceleration noise over |dt|).
    """
    a = abs(dt)
    held = min(a, hold_s)
    eff = (held + tau_s * (1.0 - np.exp(-(a - held) / tau_s))) * np.sign(dt)
    F = transition(float(eff))
    p = np.asarray(position, dtype=np.float64) + np.asarray(velocity, dtype=np.float64) * eff
    var = float((F @ np.asarray(cov) @ F.T + process_noise(a, q))[0, 0])
    return p, var


def decay_tau(velocity: NDArray[np.floating], tau_s: float, max_decel_mps2: float) -> float:
    """The time constant of the velocity's decay beyond a track's end (``extrapolate``) for a
    track leaving at ``velocity``: ``tau_s``, or longer where that decay would brake faster
    than ``max_decel_mps2`` (0: no bound). The decay starts at speed / tau; a multirotor brakes
    by tilting against its motion, at most about g tan(tilt limit), 4-7 m/s^2 for 25-35 deg:
    a drone seen at 20 m/s cannot have stopped 1.5 s later, as tau 1.5 s would have it."""
    if max_decel_mps2 <= 0:
        return tau_s
    return max(tau_s, float(np.linalg.norm(velocity)) / max_decel_mps2)


@dataclass(frozen=True)
class StraightRun:
    """The longest run of detections, ending at the track's last one, that a constant velocity
    explains (see :func:`straight_run`)."""

    duration_s: float  # from the run's first detection to its last, s
    velocity: NDArray[np.float64]  # (3,) the constant velocity fitted to the run, m/s
    n: int  # detections in the run
    position: NDArray[np.float64]  # (3,) the fitted line at the last detection's time, m


def straight_run(
    t: NDArray[np.float64],
    z: NDArray[np.float64],
    max_rms_m: float,
    scan_s: float,
    min_points: int,
) -> StraightRun | None:
    """The longest suffix of detections ``z`` (H,3) at times ``t`` (H,), increasing, whose
    least-squares constant-velocity fit leaves an RMS residual (3D, per detection) of at most
    ``max_rms_m`` plus the smear of a scan: a scan collects its points over ``scan_s`` seconds,
    so at speed v a detection's points spread over v * scan_s along the path (RMS v * scan_s /
    sqrt(12) about their mean); None when no suffix of ``min_points`` or more qualifies.

    What inertia says about the time beyond the track: a drone seen flying straight at a steady
    speed for T seconds is likely still doing so for about as long after it was last seen,
    where one seen turning or stopping is not. O(H): every suffix's fit comes from cumulative
    sums. For the run *starting* the track, pass the detections reversed in time (``-t[::-1]``,
    ``z[::-1]``) and negate the velocity.
    """
    n_all = len(t)
    if n_all < min_points:
        return None
    # suffix sums, the last detection first; times relative to it, positions to its position
    tr = (t - t[-1])[::-1]
    zr = (z - z[-1])[::-1]
    n = np.arange(1, n_all + 1, dtype=np.float64)
    s_t = np.cumsum(tr)
    s_tt = np.cumsum(tr * tr)
    s_z = np.cumsum(zr, axis=0)
    s_tz = np.cumsum(tr[:, None] * zr, axis=0)
    s_zz = np.cumsum(np.einsum("ij,ij->i", zr, zr))
    var_t = s_tt - s_t * s_t / n  # sum of (t - mean)^2
    cov_tz = s_tz - s_t[:, None] * s_z / n[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        sse = s_zz - np.einsum("ij,ij->i", s_z, s_z) / n
        sse -= np.where(var_t > 0, np.einsum("ij,ij->i", cov_tz, cov_tz) / var_t, 0.0)
        velocity = cov_tz / var_t[:, None]
    rms = np.sqrt(np.maximum(sse, 0.0) / n)
    smear = np.linalg.norm(velocity, axis=1) * (scan_s / np.sqrt(12.0))
    ok = np.flatnonzero((var_t > 0) & (n >= min_points) & (rms <= max_rms_m + smear))
    if not len(ok):
        return None
    k = int(ok[-1])
    # the line at the last detection's time (tr = 0): mean(z) - v * mean(t), relative to z[-1]
    position = z[-1] + (s_z[k] - velocity[k] * s_t[k]) / n[k]
    return StraightRun(duration_s=float(-tr[k]), velocity=velocity[k], n=k + 1, position=position)
