"""Candidate tracks: every cluster seeds or extends a constant-velocity Kalman track.

Multi-target tracking over the per-frame clusters of a sequence. No track is
"the drone" yet: all plausible movers (the drone, a walking person, a bird, speckle, branches)
keep their own candidate track, and ``cldet.core.selection`` picks the drone afterwards from
whole-sequence evidence. Per frame:

1. every active track is predicted to the frame time (constant velocity, white acceleration
   PSD ``accel_psd``);
2. cluster j may join track i if its normalised innovation squared |z - p|^2 / S is below
   ``gate_chi2`` (chi^2 with 3 dof; S = predicted position variance + centroid variance)
   and |z - p| is below ``max_gate_m``. Each detection keeps its cluster's ``lag`` after the
   frame's time (its points' mean firing time, ``ClusterTable.dt``) for the fits over the
   track's detections. A ``dated`` tracker also measures the position then: p + lag v, with
   S = [1, lag] P [1, lag]^T + R, and the update uses that H (a fast drone moves metres within
   a scan; without it each detection's place in the scan reads as noise of the whole track);
   an undated one (the estimator's default, ``frames.point_times`` 'fit') associates and
   filters every cluster at the frame's time, as a close drone's jittering centroid two
   detections 0.04 s apart would otherwise read as speed, and keeps a second state per track
   for output (``active``, what the causal estimate reports) that measures each at its lag;
3. one-to-one assignment minimising the summed NIS (Hungarian, ``scipy``);
4. unassigned clusters start new tracks (zero velocity, speed sigma ``init_speed_sigma``);
5. a track not updated for ``max_miss_s`` ends;
6. a confirmed drone-sized track (>= ``raw_min_cluster_hits`` cluster detections spread over
   at least ``raw_min_spread_m``: it has moved; its last cluster no larger than ``max_size_m``)
   that got no cluster searches the frame's raw points,
   background included, within ``raw_gate_m`` of its prediction: a drone that stops right at
   static structure (hovering over a car) is learned as background but must not vanish.

Before association the estimator lets the confirmed drone-sized tracks that have flown carve
their objects out of clusters wider than a drone (``carve_tracked``, ``carve_gate_m``): near the
sensor the 1 m linkage chains rain returns into one wide cluster, and a drone flying there
joins it.

All tracks share the frame's dt, so the filter runs vectorised over tracks; each track's
covariance is one 2x2 (see ``cldet.core.smoothing``).
"""

from __future__ import annotations

from bisect import insort
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from cldet.config import TrackingConfig
from cldet.core.smoothing import process_noise
from cldet.types import Cluster

__all__ = [
    "ActiveTracks",
    "MIN_TRACK_HITS",
    "CandidateTracker",
    "ClusterTable",
    "TrackRecord",
    "carve_tracked",
    "constant_velocity_fit",
    "crowding",
    "cross_section",
    "widen_box",
]

MIN_TRACK_HITS = 2  # detections a candidate track needs to be scored (one is no evidence)


@dataclass(frozen=True)
class ClusterTable:
    """The clusters of one frame as arrays (what the tracker and the selection need)."""

    centroid: NDArray[np.float64]  # (K,3) metres
    extent: NDArray[np.float64]  # (K,) largest box edge, metres
    n_points: NDArray[np.int64]  # (K,)
    n_mid360: NDArray[np.int64]  # (K,)
    n_avia: NDArray[np.int64]  # (K,)
    height: NDArray[np.float64] | None = (
        None  # (K,) lowest point above local ground, m; NaN unknown
    )
    size: NDArray[np.float64] | None = None  # (K,3) box edges along x, y, z, metres
    crowd: NDArray[np.int64] | None = None  # (K,) other clusters within the crowd radius
    # (K,) a static surface at or in front of the cluster when it was seen (StaticView.screened)
    screened: NDArray[np.bool_] | None = None
    # (K,) the Mid-360 points' summed squared deviations from their mean z, m^2 (Cluster)
    mid360_z_ss: NDArray[np.float64] | None = None
    # (K,) when the cluster was seen: its points' mean time after the frame's observation time,
    # s (a fast drone moves metres within a scan); None: at it
    dt: NDArray[np.float64] | None = None

    def crowds(self) -> NDArray[np.int64]:
        """(K,) how many other clusters of the frame lie near each one (0: not counted)."""
        return np.zeros(len(self), dtype=np.int64) if self.crowd is None else self.crowd

    def lags(self) -> NDArray[np.float64]:
        """(K,) each cluster's observation time after the frame's, seconds (0: unknown)."""
        return np.zeros(len(self)) if self.dt is None else self.dt

    def sizes(self) -> NDArray[np.float64]:
        """(K,3) each cluster's box edges (x, y, z), metres (NaN: unknown)."""
        return np.full((len(self), 3), np.nan) if self.size is None else self.size

    def mid360_z_spreads(self) -> NDArray[np.float64]:
        """(K,) each cluster's Mid-360 points' summed squared deviations from their mean z, m^2
        (NaN: unknown)."""
        return np.full(len(self), np.nan) if self.mid360_z_ss is None else self.mid360_z_ss

    def heights(self) -> NDArray[np.float64]:
        """(K,) each cluster's height above the local ground, metres (NaN: unknown)."""
        return np.full(len(self), np.nan) if self.height is None else self.height

    @staticmethod
    def from_clusters(clusters: tuple[Cluster, ...]) -> ClusterTable:
        """Stack a frame's clusters."""
        k = len(clusters)
        if k == 0:
            z = np.zeros(0, dtype=np.int64)
            return ClusterTable(np.zeros((0, 3)), np.zeros(0), z, z, z)
        size = np.array([c.upper - c.lower for c in clusters], dtype=np.float64)
        return ClusterTable(
            centroid=np.array([c.centroid for c in clusters], dtype=np.float64),
            extent=size.max(axis=1),
            n_points=np.array([c.n_points for c in clusters], dtype=np.int64),
            n_mid360=np.array([c.n_mid360 for c in clusters], dtype=np.int64),
            n_avia=np.array([c.n_avia for c in clusters], dtype=np.int64),
            size=size,
            mid360_z_ss=np.array([c.mid360_z_ss for c in clusters], dtype=np.float64),
        )

    def __len__(self) -> int:
        return len(self.n_points)


def crowding(
    centroid: NDArray[np.float64], n_points: NDArray[np.int64], radius_m: float
) -> NDArray[np.int64]:
    """(K,) how many other clusters of (K,3) centroids lie within ``radius_m`` of each with a
    point count within a factor of two of its own: what a track there could continue on by
    chance instead (single rain returns are alike; none of them imitates a drone's ten-point
    cluster, and a wall's or a person's hundred points are not mistaken for it either)."""
    k = len(centroid)
    if k < 2 or radius_m <= 0:
        return np.zeros(k, dtype=np.int64)
    pairs = cKDTree(centroid).query_pairs(radius_m, output_type="ndarray")
    if len(pairs) == 0:
        return np.zeros(k, dtype=np.int64)
    i, j = pairs[:, 0], pairs[:, 1]
    ni, nj = n_points[i], n_points[j]
    alike = (2 * nj >= ni) & (2 * ni >= nj)  # within a factor of two either way
    count = np.bincount(i[alike], minlength=k) + np.bincount(j[alike], minlength=k)
    return count.astype(np.int64)


@dataclass(frozen=True)
class TrackRecord:
    """One candidate track: the detections it took, in time order."""

    track_id: int
    frames: NDArray[np.int64]  # (H,) frame indices of its detections
    clusters: NDArray[np.int64]  # (H,) cluster index within each of those frames, -1: raw gate
    positions: NDArray[np.float64]  # (H,3) measured positions (cluster centroid / raw-gate mean)
    n_points: NDArray[np.int64]  # (H,) points in the cluster / in the raw gate
    nis: NDArray[np.float64]  # (H,) normalised innovation squared of each update (NaN at birth)
    speed: NDArray[np.float64]  # (H,) filtered speed after each update, m/s
    # (H,) each detection's time after its frame's observation time, s (``ClusterTable.dt``);
    # None: at it
    dt: NDArray[np.float64] | None = None

    def lags(self) -> NDArray[np.float64]:
        """(H,) each detection's time after its frame's observation time, seconds."""
        return np.zeros(len(self.frames)) if self.dt is None else self.dt

    @property
    def raw(self) -> NDArray[np.bool_]:
        """(H,) the detection came from the raw-point gate, not from a foreground cluster."""
        return self.clusters < 0

    def part(self, start: int, stop: int) -> TrackRecord:
        """Its detections ``start:stop``, under the same id."""
        return replace(
            self,
            frames=self.frames[start:stop],
            clusters=self.clusters[start:stop],
            positions=self.positions[start:stop],
            n_points=self.n_points[start:stop],
            nis=self.nis[start:stop],
            speed=self.speed[start:stop],
            dt=None if self.dt is None else self.dt[start:stop],
        )

    def after(self, head: TrackRecord) -> TrackRecord:
        """Its detections after those of ``head`` (all earlier than its first), under its id."""
        dt = None
        if head.dt is not None or self.dt is not None:
            dt = np.concatenate([head.lags(), self.lags()])
        return replace(
            self,
            frames=np.concatenate([head.frames, self.frames]),
            clusters=np.concatenate([head.clusters, self.clusters]),
            positions=np.concatenate([head.positions, self.positions]),
            n_points=np.concatenate([head.n_points, self.n_points]),
            nis=np.concatenate([head.nis, self.nis]),
            speed=np.concatenate([head.speed, self.speed]),
            dt=dt,
        )


def cross_section(
    n_mid360: NDArray[np.integer],
    n_avia: NDArray[np.integer],
    positions: NDArray[np.float64],
    cfg: TrackingConfig,
) -> NDArray[np.float64]:
    """(H,) the area (m^2) that returned these points at this range: points / density * r^2.

    A LiDAR puts a fixed number of points per steradian on a surface in each scan
    (``mid360_points_per_sr``, ``avia_points_per_sr``), so an object of projected area A at
    range r returns about density * A / r^2 points.
    """
    r2 = np.einsum("ij,ij->i", positions, positions)
    return (n_mid360 / cfg.mid360_points_per_sr + n_avia / cfg.avia_points_per_sr) * r2


def constant_velocity_fit(
    t: NDArray[np.float64], p: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Least-squares constant velocity through positions ``p`` (H,3) at times ``t`` (H,): the
    position at the mean time, the velocity (zero when all times are equal), the mean time."""
    tm = float(t.mean())
    tc = t - tm
    den = float(tc @ tc)
    mean = p.mean(axis=0)
    v = (tc @ (p - mean)) / den if den > 0 else np.zeros(3)
    return mean, v, tm


def windowed_velocity(
    t: NDArray[np.float64], p: NDArray[np.float64], window_s: float
) -> NDArray[np.float64]:
    """(H,3) per detection, the least-squares constant velocity (``constant_velocity_fit``) of
    the detections ``p`` at times ``t`` (H,) (increasing) taken at most ``window_s`` before it,
    itself included: the object's motion as seen up to then (zero where those detections share
    one time)."""
    h = len(t)
    if h == 0:
        return np.zeros((0, 3))
    tt = t - t[0]  # the sums are taken from the first detection on: no cancellation
    first = np.searchsorted(tt, tt - window_s, side="left")
    last = np.arange(1, h + 1)
    s_t = np.concatenate([[0.0], np.cumsum(tt)])
    s_tt = np.concatenate([[0.0], np.cumsum(tt * tt)])
    s_p = np.vstack([np.zeros(3), np.cumsum(p, axis=0)])
    s_tp = np.vstack([np.zeros(3), np.cumsum(tt[:, None] * p, axis=0)])
    n = (last - first).astype(np.float64)
    st, stt = s_t[last] - s_t[first], s_tt[last] - s_tt[first]
    sp, stp = s_p[last] - s_p[first], s_tp[last] - s_tp[first]
    den = stt - st * st / n
    ok = den > 1e-12 * np.maximum(stt, 1.0)
    v = np.zeros((h, 3))
    v[ok] = (stp[ok] - st[ok, None] * sp[ok] / n[ok, None]) / den[ok, None]
    return v


@dataclass(frozen=True)
class ActiveTracks:
    """The active candidate tracks' Kalman states (per axis: position, velocity)."""

    ids: NDArray[np.int64]  # (T,)
    position: NDArray[np.float64]  # (T,3) metres, at the last step's time
    velocity: NDArray[np.float64]  # (T,3) m/s
    pos_var: NDArray[np.float64]  # (T,) per-axis position variance, m^2


def widen_box(
    lower: list[float], upper: list[float], point: NDArray[np.floating] | tuple[float, ...]
) -> float:
    """Widen the box ``lower``..``upper`` (per axis, in place) to hold ``point`` (3,); returns
    its largest edge. Python floats: a few comparisons a detection, without numpy's per-call
    cost (min and max are exact, so the box is numpy's to the bit)."""
    for k in range(3):
        x = float(point[k])
        lower[k] = min(lower[k], x)
        upper[k] = max(upper[k], x)
    return max(upper[0] - lower[0], upper[1] - lower[1], upper[2] - lower[2])


@dataclass
class _Hits:
    frames: list[int] = field(default_factory=list)
    clusters: list[int] = field(default_factory=list)
    positions: list[NDArray[np.float64]] = field(default_factory=list)
    n_points: list[int] = field(default_factory=list)
    nis: list[float] = field(default_factory=list)
    speed: list[float] = field(default_factory=list)
    dt: list[float] = field(default_factory=list)
    n_cluster_hits: int = 0
    last_extent: float = 0.0
    # the box around its cluster detections, per axis (``widen_box``)
    lower: list[float] = field(default_factory=lambda: [np.inf] * 3)
    upper: list[float] = field(default_factory=lambda: [-np.inf] * 3)
    spread: float = 0.0  # largest edge of that box, metres
    cluster_points: list[int] = field(default_factory=list)  # its clusters' sizes, sorted

    def add(
        self,
        frame: int,
        cluster: int,
        pos: NDArray[np.float64],
        n: int,
        nis: float,
        speed: float,
        extent: float = 0.0,
        dt: float = 0.0,
    ) -> None:
        self.frames.append(frame)
        self.dt.append(dt)
        self.clusters.append(cluster)
        self.positions.append(pos)
        self.n_points.append(n)
        self.nis.append(nis)
        self.speed.append(speed)
        if cluster >= 0:
            insort(self.cluster_points, n)
            self.n_cluster_hits += 1
            self.last_extent = extent
            self.spread = widen_box(self.lower, self.upper, pos)

    def may_use_raw(self, min_hits: int, min_spread_m: float, max_size_m: float) -> bool:
        return (
            self.n_cluster_hits >= min_hits
            and self.last_extent <= max_size_m
            and self.spread >= min_spread_m
        )


class CandidateTracker:
    """Feed ``step`` frame by frame, then ``records`` gives every candidate track."""

    def __init__(self, cfg: TrackingConfig, dated: bool = True) -> None:
        """``dated``: the filter measures each cluster at its lag (``ClusterTable.dt``);
        otherwise at the frame's time, the lags only recorded with the detections."""
        self.cfg = cfg
        self.dated = dated
        self._x = np.zeros((0, 3, 2))  # states of active tracks
        self._P = np.zeros((0, 2, 2))
        # undated: the same tracks' states with each detection measured at its lag, for output
        self._xo = np.zeros((0, 3, 2))
        self._Po = np.zeros((0, 2, 2))
        self._last_t = np.zeros(0)  # last update time, s
        self._raw_ok: set[int] = set()  # ids of the tracks the raw gate may continue
        self._ids = np.zeros(0, dtype=np.int64)
        self._hits: dict[int, _Hits] = {}  # the active tracks'
        # ended tracks of two detections or more, compacted (most tracks are clutter seen once)
        self._ended: list[TrackRecord] = []
        self._t: float | None = None
        self._next_id = 0

    def step(
        self,
        frame_index: int,
        t_s: float,
        table: ClusterTable,
        raw_points: NDArray[np.floating] | None = None,
    ) -> NDArray[np.int64]:
        """Predict every active track to ``t_s`` seconds and associate this frame's clusters.

        ``raw_points`` (N,3), all of the frame's points (background included), let a confirmed
        moving track that got no cluster continue on raw points near its prediction.

        Returns:
            (K,) the id of the track each cluster of ``table`` joined or started.
        """
        cfg = self.cfg
        if self._t is not None and len(self._ids):
            dt = t_s - self._t
            F = np.array([[1.0, dt], [0.0, 1.0]])
            Q = process_noise(dt, cfg.accel_psd)
            self._x = self._x @ F.T
            self._P = F @ self._P @ F.T + Q
            if not self.dated:
                self._xo = self._xo @ F.T
                self._Po = F @ self._Po @ F.T + Q
            keep = t_s - self._last_t <= cfg.max_miss_s
            if not keep.all():
                ended = self._ids[~keep].tolist()
                self._raw_ok.difference_update(ended)
                for tid in ended:
                    self._end(tid)
                self._x, self._P = self._x[keep], self._P[keep]
                if not self.dated:
                    self._xo, self._Po = self._xo[keep], self._Po[keep]
                self._last_t, self._ids = self._last_t[keep], self._ids[keep]
        self._t = t_s
        k = len(table)
        z = table.centroid
        seen = table.lags()  # each cluster seen this long after t_s, recorded with it
        lag = seen if self.dated else np.zeros_like(seen)  # the filter measures p + lag * v
        r2 = cfg.meas_sigma_m**2
        assigned = np.zeros(k, dtype=bool)
        n_tr = len(self._ids)
        updated = np.zeros(n_tr, dtype=bool)
        owner = np.full(k, -1, dtype=np.int64)
        if n_tr and k:
            pred = self._x[:, None, :, 0] + lag[None, :, None] * self._x[:, None, :, 1]
            diff = z[None, :, :] - pred  # (T,K,3)
            d2 = np.einsum("tkd,tkd->tk", diff, diff)
            # H = [1, lag]: S = P00 + 2 lag P01 + lag^2 P11 + R, per track and cluster
            P = self._P
            s = (
                P[:, 0, 0][:, None]
                + lag[None, :] * (2.0 * P[:, 0, 1][:, None] + lag[None, :] * P[:, 1, 1][:, None])
                + r2
            )  # (T,K)
            nis = d2 / s
            # the hard gate grows with the time unseen at the drone's top speed: a fast drone
            # seen every few scans jumps metres between its detections
            unseen = t_s - self._last_t
            hard = cfg.max_gate_m + cfg.gate_speed * np.maximum(unseen - 0.1, 0.0)
            ok = (nis <= cfg.gate_chi2) & (d2 <= (hard**2)[:, None])
            if ok.any():
                cost = np.where(ok, nis, 1e9)
                rows, cols = linear_sum_assignment(cost)
                good = ok[rows, cols]
                rows, cols = rows[good], cols[good]
                if len(rows):
                    _lagged_update(self._x, self._P, rows, z[cols], lag[cols], r2)
                    if not self.dated:
                        _lagged_update(self._xo, self._Po, rows, z[cols], seen[cols], r2)
                    self._last_t[rows] = t_s
                    speeds = np.linalg.norm(self._x[rows, :, 1], axis=1)
                    for a, (i, j) in enumerate(zip(rows, cols, strict=True)):
                        self._hits[int(self._ids[i])].add(
                            frame_index,
                            int(j),
                            z[j],
                            int(table.n_points[j]),
                            float(nis[i, j]),
                            float(speeds[a]),
                            float(table.extent[j]),
                            float(seen[j]),
                        )
                        if cfg.raw_gate_m > 0:  # (the raw gate off: nothing reads the verdict)
                            self._judge_raw(int(self._ids[i]))
                    assigned[cols] = True
                    updated[rows] = True
                    owner[cols] = self._ids[rows]
        if (
            cfg.raw_gate_m > 0
            and raw_points is not None
            and len(raw_points)
            and n_tr
            and not updated.all()
        ):
            self._raw_continue(frame_index, t_s, np.flatnonzero(~updated), raw_points, z[assigned])
        new = np.flatnonzero(~assigned)
        if len(new):
            m = len(new)
            x = np.zeros((m, 3, 2))
            # a track is born where its first cluster was seen, at rest, its speed unknown
            x[:, :, 0] = z[new]
            P = np.tile(np.diag([r2, cfg.init_speed_sigma**2]), (m, 1, 1))
            ids = np.arange(self._next_id, self._next_id + m)
            self._next_id += m
            for tid, j in zip(ids, new, strict=True):
                hits = _Hits()
                hits.add(
                    frame_index,
                    int(j),
                    z[j],
                    int(table.n_points[j]),
                    float("nan"),
                    0.0,
                    float(table.extent[j]),
                    float(seen[j]),
                )
                self._hits[int(tid)] = hits
                if cfg.raw_min_cluster_hits <= 1:
                    self._judge_raw(int(tid))
            self._x = np.concatenate([self._x, x])
            self._P = np.concatenate([self._P, P])
            if not self.dated:
                self._xo = np.concatenate([self._xo, x])
                self._Po = np.concatenate([self._Po, P])
            self._last_t = np.concatenate([self._last_t, np.full(m, t_s)])
            self._ids = np.concatenate([self._ids, ids])
            owner[new] = ids
        return owner

    def _raw_continue(
        self,
        frame_index: int,
        t_s: float,
        missed: NDArray[np.int64],
        raw: NDArray[np.floating],
        taken: NDArray[np.float64],
    ) -> None:
        """Continue confirmed moving tracks that got no cluster on raw points near the prediction.

        Only the tracks ``_judge_raw`` admitted are continued.

        The raw points within ``raw_gate_m`` of the prediction (or, failing that, of the last
        detection: the drone braked to hover) form the detection when the object is isolated
        (see ``_isolated_blob``), and when no cluster taken by another track this frame lies
        within twice the gate: then this track is a duplicate of that one, and feeding it the
        object's leftovers (and the structure beside it) would only pull it away.
        """
        cfg = self.cfg
        g = cfg.raw_gate_m
        if g <= 0:
            return
        tree: cKDTree | None = None  # built once, when a track first needs it
        if not self._raw_ok:
            return
        ok_ids = np.fromiter(self._raw_ok, dtype=np.int64, count=len(self._raw_ok))
        for i in missed[np.isin(self._ids[missed], ok_ids)]:
            hits = self._hits[int(self._ids[i])]
            # where it would be: the constant-velocity prediction, or stopped where it was last
            # seen (a drone braking to hover)
            for centre, check_nis in ((self._x[i, :, 0], True), (hits.positions[-1], False)):
                if len(taken) and np.min(np.sum((taken - centre) ** 2, axis=1)) <= 4 * g * g:
                    continue
                if tree is None:
                    tree = cKDTree(raw)
                zr_n = _isolated_blob(raw, tree, np.asarray(centre, dtype=np.float64), g)
                if zr_n is None:
                    continue
                zr, n_in = zr_n
                nu = zr - self._x[i, :, 0]
                s = self._P[i, 0, 0] + cfg.raw_meas_sigma_m**2
                nis = float(nu @ nu / s)
                if check_nis and nis > cfg.gate_chi2:
                    continue
                gain = self._P[i, :, 0] / s
                self._x[i] += nu[:, None] * gain[None, :]
                self._P[i] -= np.outer(gain, self._P[i, 0, :])
                if not self.dated:
                    r2_raw = cfg.raw_meas_sigma_m**2
                    _lagged_update(
                        self._xo, self._Po, np.array([i]), zr[None, :], np.zeros(1), r2_raw
                    )
                self._last_t[i] = t_s
                hits.add(frame_index, -1, zr, n_in, nis, float(np.linalg.norm(self._x[i, :, 1])))
                break

    def _judge_raw(self, track_id: int) -> None:
        """After a cluster hit: may the raw gate continue this track? (confirmed, drone-sized,
        it has moved, and its last detection had a drone's cross-section, counted as Mid-360
        points: speckle tracks are not worth the search)."""
        cfg = self.cfg
        hits = self._hits[track_id]
        ok = hits.may_use_raw(cfg.raw_min_cluster_hits, cfg.raw_min_spread_m, cfg.max_size_m)
        ok = (
            ok
            and cross_section(
                np.array([hits.n_points[-1]]),
                np.zeros(1, dtype=np.int64),
                hits.positions[-1][None, :],
                cfg,
            )[0]
            >= cfg.min_cross_section_m2
        )
        if ok:
            self._raw_ok.add(track_id)
        else:
            self._raw_ok.discard(track_id)

    def active_ids(self) -> NDArray[np.int64]:
        """(T,) the active tracks' ids at the last ``step`` (read-only)."""
        ids = self._ids.view()
        ids.flags.writeable = False
        return ids

    def active(self) -> ActiveTracks:
        """The active tracks' filtered states at the last ``step``: for an undated tracker,
        those of its output filter, which measures each detection at its lag (the association
        takes them at the frame's time)."""
        x, P = (self._x, self._P) if self.dated else (self._xo, self._Po)
        return ActiveTracks(
            ids=self._ids.copy(),
            position=x[:, :, 0].copy(),
            velocity=x[:, :, 1].copy(),
            pos_var=P[:, 0, 0].copy(),
        )

    def small_predictions(self, t_s: float) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """The ids (T,) of the confirmed drone-sized tracks (``raw_min_cluster_hits`` cluster
        detections or more, the last no larger than ``max_size_m``) and where they would be at
        ``t_s`` (T,3), by their constant velocity; the tracks themselves are not changed."""
        cfg = self.cfg
        sel = [
            i
            for i, tid in enumerate(self._ids.tolist())
            if self._hits[tid].n_cluster_hits >= cfg.raw_min_cluster_hits
            and self._hits[tid].last_extent <= cfg.max_size_m
        ]
        if not sel or self._t is None:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
        x = self._x[sel]
        return self._ids[sel], np.asarray(x[:, :, 0] + (t_s - self._t) * x[:, :, 1])

    def is_confirmed_mover(self, track_id: int) -> bool:
        """Enough cluster hits, drone-sized, and it has moved (the raw-gate criterion)."""
        cfg = self.cfg
        hits = self._hits.get(track_id)
        return hits is not None and hits.may_use_raw(
            cfg.raw_min_cluster_hits, cfg.raw_min_spread_m, cfg.max_size_m
        )

    def spread(self, track_id: int) -> float:
        """Largest edge of the box around a track's cluster detections, metres."""
        return self._hits[track_id].spread

    def median_points(self, track_id: int) -> float:
        """The median count of points in a track's cluster detections (0 when it has none)."""
        counts = self._hits[track_id].cluster_points  # sorted as they come: O(1) here
        h = len(counts)
        if not h:
            return 0.0
        return float(counts[h // 2]) if h % 2 else 0.5 * (counts[h // 2 - 1] + counts[h // 2])

    def last_hit(self, track_id: int) -> tuple[int, int, NDArray[np.float64], float]:
        """A track's latest detection: frame index, cluster index (-1: raw gate), position, NIS."""
        hits = self._hits[track_id]
        return hits.frames[-1], hits.clusters[-1], hits.positions[-1], hits.nis[-1]

    def last_points(self, track_id: int) -> int:
        """Points in a track's latest detection."""
        return self._hits[track_id].n_points[-1]

    @property
    def next_id(self) -> int:
        """The id the next new track gets (ids are never reused)."""
        return self._next_id

    def _end(self, track_id: int) -> None:
        """Forget an ended track's running state; keep its detections if it is a track at all."""
        hits = self._hits.pop(track_id)
        if len(hits.frames) >= MIN_TRACK_HITS:
            self._ended.append(_to_record(track_id, hits))

    def record(self, track_id: int) -> TrackRecord | None:
        """One track's detections so far (active or ended; None: unknown or a lone detection)."""
        hits = self._hits.get(track_id)
        if hits is not None:
            return _to_record(track_id, hits) if len(hits.frames) >= MIN_TRACK_HITS else None
        for rec in reversed(self._ended):  # the followed track ended recently
            if rec.track_id == track_id:
                return rec
        return None

    def records(self) -> list[TrackRecord]:
        """Every candidate track so far (ended or active) of at least ``MIN_TRACK_HITS``
        detections, by track id. A lone detection is no track: nothing scores it."""
        live = [
            _to_record(tid, h) for tid, h in self._hits.items() if len(h.frames) >= MIN_TRACK_HITS
        ]
        return sorted(self._ended + live, key=lambda r: r.track_id)


def _lagged_update(
    x: NDArray[np.float64],
    P: NDArray[np.float64],
    rows: NDArray[np.intp],
    z: NDArray[np.float64],
    lag: NDArray[np.float64],
    r2: float,
) -> None:
    """In place: the states ``x`` (T,3,2) and covariances ``P`` (T,2,2) of tracks ``rows`` (A,)
    updated with detections ``z`` (A,3) measured ``lag`` (A,) after the states' time, each with
    variance ``r2``: H = [1, lag], S = P00 + 2 lag P01 + lag^2 P11 + R (the association's own
    S, term for term)."""
    xa, Pa = x[rows], P[rows]
    nu = z - (xa[:, :, 0] + lag[:, None] * xa[:, :, 1])  # (A,3)
    s = Pa[:, 0, 0] + lag * (2.0 * Pa[:, 0, 1] + lag * Pa[:, 1, 1]) + r2
    hp = Pa[:, 0, :] + lag[:, None] * Pa[:, 1, :]  # H P
    gain = hp / s[:, None]  # (A,2): P H^T / S
    x[rows] += nu[:, :, None] * gain[:, None, :]
    P[rows] -= gain[:, :, None] * hp[:, None, :]


def _to_record(tid: int, h: _Hits) -> TrackRecord:
    """A track's hits as arrays."""
    return TrackRecord(
        track_id=tid,
        frames=np.asarray(h.frames, dtype=np.int64),
        clusters=np.asarray(h.clusters, dtype=np.int64),
        positions=np.asarray(h.positions, dtype=np.float64).reshape(-1, 3),
        n_points=np.asarray(h.n_points, dtype=np.int64),
        nis=np.asarray(h.nis, dtype=np.float64),
        speed=np.asarray(h.speed, dtype=np.float64),
        dt=np.asarray(h.dt, dtype=np.float64) if any(h.dt) else None,
    )


CARVE_SHELL_RATIO = 0.5
"""``carve_tracked`` takes a blob only where the shell out to twice its radius holds at most
this fraction of the returns within it: a compact body's neighbours are the lone returns it
chained to; a line through the gate returns about as much in the shell as within, a surface
three times as much."""


def carve_tracked(
    points: NDArray[np.floating],
    labels: NDArray[np.int32],
    extent: NDArray[np.float64],
    centres: NDArray[np.float64],
    gate_m: float,
    max_size_m: float,
) -> NDArray[np.int32]:
    """``labels`` (from ``cluster_points``; ``extent`` (K,), each cluster's largest box edge)
    with the isolated blobs at ``centres`` carved out of clusters wider than ``max_size_m``,
    each as a new cluster (ids after the existing ones).

    At each centre (where a confirmed drone-sized track predicts its object) the points of a
    wide cluster within ``gate_m`` are found, the centre moved to their mean; when the points
    within ``gate_m`` of that stand isolated among all ``points`` (``_isolated`` with
    ``CARVE_SHELL_RATIO``, counting what lies below), those within ``gate_m`` of their own mean
    are taken, if the wide cluster reaches beyond the shell (twice ``gate_m``): a compact
    object whose returns merely chain to others through the linkage (rain near the sensor)
    comes apart; a piece of a wider surface or of a line (a hedge, a wall, a branch, a
    railing), a person's head and shoulders, or an object a little wider than a drone do not.
    """
    k = len(extent)
    wide = extent > max_size_m
    if len(centres) == 0 or not wide.any():
        return labels
    valid = labels >= 0
    in_wide = np.flatnonzero(valid)[wide[labels[valid]]]
    pts = np.asarray(points, dtype=np.float64)
    out = labels.copy()
    g2 = gate_m * gate_m
    changed = False
    for c in np.asarray(centres, dtype=np.float64):
        d = pts[in_wide] - c
        near = in_wide[np.einsum("ij,ij->i", d, d) <= g2]
        near = near[out[near] < k]  # not carved already
        if len(near) == 0:
            continue
        inside = _isolated(pts - pts[near].mean(axis=0), gate_m, CARVE_SHELL_RATIO, below=True)
        if inside is None:
            continue
        d = pts - pts[inside].mean(axis=0)  # centred on the isolated blob itself
        d2 = np.einsum("ij,ij->i", d, d)
        taken = np.flatnonzero((d2 <= g2) & (out >= 0) & (out < k))
        taken = taken[extent[out[taken]] > max_size_m]
        if len(taken) == 0:
            continue
        # a merger: the cluster reaches beyond the shell (else it is one object a little wider
        # than a drone, or a drone with a fringe, and carving would split it in two)
        if not np.any(np.isin(out, np.unique(out[taken])) & (d2 > 4.0 * g2)):
            continue
        out[taken] = out.max() + 1
        changed = True
    return out if changed else labels


def _isolated(
    d: NDArray[np.float64], gate_m: float, shell_ratio: float = 1.0, below: bool = False
) -> NDArray[np.bool_] | None:
    """Which of the points at offsets ``d`` (N,3) from a centre lie within ``gate_m`` of it, if
    they are isolated (else None).

    Isolated: no more points in the shell ``gate_m..2 gate_m`` around the centre than
    ``shell_ratio`` times those in the gate itself, ignoring what lies below unless ``below``
    (a car roof, a lamp post under a hovering drone). A wall, a tree or the ground fails the
    test; with ``shell_ratio`` below 1 a pole or a branch through the gate does too (it returns
    as much along the shell's width as along the gate's), and with ``below`` a person's head
    and shoulders (their body below).
    """
    d2 = np.einsum("ij,ij->i", d, d)
    inside = d2 <= gate_m * gate_m
    n_in = int(inside.sum())
    shell = ~inside & (d2 <= 4.0 * gate_m * gate_m)
    n_shell = int(np.sum(shell if below else shell & (d[:, 2] >= -0.5 * gate_m)))
    if n_in == 0 or n_shell > shell_ratio * n_in:
        return None
    return inside


def _isolated_blob(
    raw: NDArray[np.floating], tree: cKDTree, centre: NDArray[np.float64], gate_m: float
) -> tuple[NDArray[np.float64], int] | None:
    """Mean and count of the raw points within ``gate_m`` of ``centre`` if they are isolated
    (``_isolated``). ``tree`` indexes ``raw``."""
    near = np.asarray(tree.query_ball_point(centre, 2.0 * gate_m), dtype=np.intp)
    if len(near) == 0:
        return None
    p = np.asarray(raw[near], dtype=np.float64)
    inside = _isolated(p - centre, gate_m)
    if inside is None:
        return None
    return p[inside].mean(axis=0), int(inside.sum())
