"""Candidate tracks: every cluster seeds or extends a constant-velocity Kalman track.

Offline multi-target tracking over the per-frame clusters of a whole sequence. No track is
"the drone" yet: all plausible movers (the drone, a walking person, a bird, speckle, branches)
keep their own candidate track, and ``cldet.core.selection`` picks the drone afterwards from
whole-sequence evidence. Per frame:

1. every active track is predicted to the frame time (constant velocity, white acceleration
   PSD ``accel_psd``);
2. cluster j may join track i if its normalised innovation squared |z - p|^2 / S is below
   ``gate_chi2`` (chi^2 with 3 dof; S = predicted position variance + centroid variance)
   and |z - p| is below ``max_gate_m``;
3. one-to-one assignment minimising the summed NIS (Hungarian, ``scipy``);
4. unassigned clusters start new tracks (zero velocity, speed sigma ``init_speed_sigma``);
5. a track not updated for ``max_miss_s`` ends.

All tracks share the frame's dt, so the filter runs vectorised over tracks; each track's
covariance is one 2x2 (see ``cldet.core.smoothing``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from cldet.config import TrackingConfig
from cldet.types import Cluster

__all__ = ["CandidateTracker", "ClusterTable", "TrackRecord"]


@dataclass(frozen=True)
class ClusterTable:
    """The clusters of one frame as arrays (what the tracker and the selection need)."""

    centroid: NDArray[np.float64]  # (K,3) metres
    extent: NDArray[np.float64]  # (K,) largest box edge, metres
    n_points: NDArray[np.int64]  # (K,)
    n_mid360: NDArray[np.int64]  # (K,)
    n_avia: NDArray[np.int64]  # (K,)

    @staticmethod
    def from_clusters(clusters: tuple[Cluster, ...]) -> ClusterTable:
        """Stack a frame's clusters."""
        k = len(clusters)
        if k == 0:
            z = np.zeros(0, dtype=np.int64)
            return ClusterTable(np.zeros((0, 3)), np.zeros(0), z, z, z)
        return ClusterTable(
            centroid=np.array([c.centroid for c in clusters], dtype=np.float64),
            extent=np.array([float(np.max(c.upper - c.lower)) for c in clusters]),
            n_points=np.array([c.n_points for c in clusters], dtype=np.int64),
            n_mid360=np.array([c.n_mid360 for c in clusters], dtype=np.int64),
            n_avia=np.array([c.n_avia for c in clusters], dtype=np.int64),
        )

    def __len__(self) -> int:
        return len(self.n_points)


@dataclass(frozen=True)
class TrackRecord:
    """One candidate track: the detections it took, in time order."""

    track_id: int
    frames: NDArray[np.int64]  # (H,) frame indices of its detections
    clusters: NDArray[np.int64]  # (H,) cluster index within each of those frames
    nis: NDArray[np.float64]  # (H,) normalised innovation squared of each update (NaN at birth)
    speed: NDArray[np.float64]  # (H,) filtered speed after each update, m/s


@dataclass
class _Hits:
    frames: list[int] = field(default_factory=list)
    clusters: list[int] = field(default_factory=list)
    nis: list[float] = field(default_factory=list)
    speed: list[float] = field(default_factory=list)


class CandidateTracker:
    """Feed ``step`` frame by frame, then ``records`` gives every candidate track."""

    def __init__(self, cfg: TrackingConfig) -> None:
        self.cfg = cfg
        self._x = np.zeros((0, 3, 2))  # states of active tracks
        self._P = np.zeros((0, 2, 2))
        self._last_t = np.zeros(0)  # last update time, s
        self._ids = np.zeros(0, dtype=np.int64)
        self._hits: dict[int, _Hits] = {}
        self._t: float | None = None
        self._next_id = 0

    def step(self, frame_index: int, t_s: float, table: ClusterTable) -> None:
        """Predict every active track to ``t_s`` seconds and associate this frame's clusters."""
        cfg = self.cfg
        if self._t is not None and len(self._ids):
            dt = t_s - self._t
            F = np.array([[1.0, dt], [0.0, 1.0]])
            Q = cfg.accel_psd * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
            self._x = self._x @ F.T
            self._P = F @ self._P @ F.T + Q
            keep = t_s - self._last_t <= cfg.max_miss_s
            if not keep.all():
                self._x, self._P = self._x[keep], self._P[keep]
                self._last_t, self._ids = self._last_t[keep], self._ids[keep]
        self._t = t_s
        k = len(table)
        if k == 0:
            return
        z = table.centroid
        r2 = cfg.meas_sigma_m**2
        assigned = np.zeros(k, dtype=bool)
        n_tr = len(self._ids)
        if n_tr:
            diff = z[None, :, :] - self._x[:, None, :, 0]  # (T,K,3)
            d2 = np.einsum("tkd,tkd->tk", diff, diff)
            s = self._P[:, 0, 0][:, None] + r2  # (T,1)
            nis = d2 / s
            ok = (nis <= cfg.gate_chi2) & (d2 <= cfg.max_gate_m**2)
            if ok.any():
                cost = np.where(ok, nis, 1e9)
                rows, cols = linear_sum_assignment(cost)
                good = ok[rows, cols]
                rows, cols = rows[good], cols[good]
                if len(rows):
                    nu = diff[rows, cols]  # (A,3)
                    s_a = s[rows, 0]
                    gain = self._P[rows, :, 0] / s_a[:, None]  # (A,2)
                    self._x[rows] += nu[:, :, None] * gain[:, None, :]
                    self._P[rows] -= gain[:, :, None] * self._P[rows, 0, :][:, None, :]
                    self._last_t[rows] = t_s
                    speeds = np.linalg.norm(self._x[rows, :, 1], axis=1)
                    for a, (i, j) in enumerate(zip(rows, cols, strict=True)):
                        h = self._hits[int(self._ids[i])]
                        h.frames.append(frame_index)
                        h.clusters.append(int(j))
                        h.nis.append(float(nis[i, j]))
                        h.speed.append(float(speeds[a]))
                    assigned[cols] = True
        new = np.flatnonzero(~assigned)
        if len(new):
            m = len(new)
            x = np.zeros((m, 3, 2))
            x[:, :, 0] = z[new]
            P = np.tile(np.diag([r2, cfg.init_speed_sigma**2]), (m, 1, 1))
            ids = np.arange(self._next_id, self._next_id + m)
            self._next_id += m
            for tid, j in zip(ids, new, strict=True):
                self._hits[int(tid)] = _Hits([frame_index], [int(j)], [float("nan")], [0.0])
            self._x = np.concatenate([self._x, x])
            self._P = np.concatenate([self._P, P])
            self._last_t = np.concatenate([self._last_t, np.full(m, t_s)])
            self._ids = np.concatenate([self._ids, ids])

    def records(self) -> list[TrackRecord]:
        """Every candidate track so far (ended or active), by track id."""
        return [
            TrackRecord(
                track_id=tid,
                frames=np.asarray(h.frames, dtype=np.int64),
                clusters=np.asarray(h.clusters, dtype=np.int64),
                nis=np.asarray(h.nis, dtype=np.float64),
                speed=np.asarray(h.speed, dtype=np.float64),
            )
            for tid, h in sorted(self._hits.items())
        ]
