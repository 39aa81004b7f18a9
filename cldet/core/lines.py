"""Track-before-detect for sparse fast movers: constant-velocity lines through space-time.

A drone passing at 10-23 m/s, 20-90 m out, returns one or two points in one scan out of three
or five. The Kalman tracker (``cldet.core.tracking``) cannot follow it: between two sightings
it moved further than any gate that keeps clutter out, so every sighting starts a new track of
one detection, and no single frame says "drone". Over a few seconds, though, the sightings lie
on one straight line in space-time, and nothing else does: rain and dust returns are
independent from scan to scan, static clutter does not move, a walking person is slow.

The search, over the clusters of the whole sequence (offline, inside ``refine``; the causal
estimate runs it over its last few seconds, from seeds seen lately, while it follows no track):

1. candidates: drone-sized clusters (``max_size_m``) whose points are not a lone return from
   something far smaller than a drone (``min_cross_section_m2``, see
   ``cldet.core.tracking.cross_section``: near-sensor rain and dust drop out here), and
   isolated: no other cluster of the same frame within ``line_isolation_m``. A drone in flight
   is a small object in free air; where returns crowd (rain close to the sensor, a bush's
   fringe, a crowd) any line through them would collect inliers by chance, and the Kalman
   tracker, not the line search, follows what moves there;
2. seeds: every pair of candidates at most ``line_seed_s`` apart whose implied speed lies
   between ``line_min_speed`` (slower movers are the Kalman tracker's) and ``max_speed``;
3. each seed's line is scored by the frames within ``line_seed_s`` of it that have a
   candidate within ``line_tol_m`` of the line (one per frame);
4. a line must sweep at least ``line_min_sweep_deg`` as seen from the sensor: lone returns
   along one beam at varying ranges (rain, dust, multipath) line up with any line that runs
   along the line of sight, so such a line is no evidence of a mover (a drone flying straight
   at the sensor is left to the Kalman tracker: its returns grow as it comes);
5. greedily, best seed first: its inliers are refitted (least squares, constant velocity) and
   the line is grown at both ends, each end predicted from the fit of its own nearest inliers
   (a pass that curves gently is followed piece by piece), until no frame within
   ``line_window_s`` of an end adds an inlier (a long straight pass bridges its unseen
   stretches); a line with inliers at ``line_min_hits`` distinct places or more (``_places``:
   static clutter seen over and over is one place)
   becomes a candidate track and its detections are taken (no other line may use them).

The lines are candidate tracks like the tracker's: ``cldet.core.selection`` scores them with
the same per-detection evidence and chains them with the others; the best whole-sequence
explanation wins. A line's detections count with an NIS of at most the 95 % point (they lie
within the tolerance by construction).
"""

from __future__ import annotations

import math
from typing import TypeVar

import numba
import numpy as np
from numpy.typing import NDArray

from cldet.config import TrackingConfig
from cldet.core.tracking import (
    ClusterTable,
    TrackRecord,
    constant_velocity_fit,
    cross_section,
)

__all__ = ["find_lines"]

_NIS95 = 7.81  # 95 % point of chi^2, 3 dof: a detection at the tolerance
_END_FIT = 8  # inliers nearest an end that predict the line beyond it
# a sequence crowded with candidates keeps its closest seed pairs only: this many per frame, so
# that the cap scales with the sequence's length (and at least _MIN_SEED_CAP)
_SEEDS_PER_FRAME = 2_500
_MIN_SEED_CAP = 200_000
_Speed = TypeVar("_Speed", float, NDArray[np.float64])


class _Pool:
    """The candidate detections of the whole sequence, indexed per frame."""

    def __init__(
        self, tables: list[ClusterTable], times_s: NDArray[np.float64], cfg: TrackingConfig
    ) -> None:
        frames, clusters, positions, lags = [], [], [], []
        for f, table in enumerate(tables):
            if not len(table):
                continue
            cross = cross_section(table.n_mid360, table.n_avia, table.centroid, cfg)
            ok = (table.extent <= cfg.max_size_m) & (cross >= cfg.min_cross_section_m2)
            if len(table) > 1:
                # isolated: no other cluster of the frame within line_isolation_m
                ok &= _isolated(table.centroid, cfg.line_isolation_m)
            keep = np.flatnonzero(ok)
            frames.append(np.full(len(keep), f, dtype=np.int64))
            clusters.append(keep.astype(np.int64))
            positions.append(table.centroid[keep])
            lags.append(table.lags()[keep])
        self.frame = np.concatenate(frames) if frames else np.zeros(0, dtype=np.int64)
        self.cluster = np.concatenate(clusters) if clusters else np.zeros(0, dtype=np.int64)
        self.pos = (
            np.concatenate(positions).astype(np.float64, copy=False)
            if positions
            else np.zeros((0, 3))
        )
        self.t = times_s[self.frame]
        # when in its scan each candidate was seen (the found line's fit uses it; the seeds
        # and counts, whose tolerance allows for a scan's smear, do not: two candidates of
        # neighbouring frames may be seen almost at once)
        self.lag = np.concatenate(lags) if lags else np.zeros(0)
        self.times = times_s
        n = len(tables)
        self.start = np.searchsorted(self.frame, np.arange(n + 1))  # candidates of frame f
        self.frames = np.flatnonzero(np.diff(self.start) > 0)  # those with candidates, in order
        self.used = np.zeros(len(self.frame), dtype=bool)

    def nearest(
        self, frames: NDArray[np.int64], points: NDArray[np.float64], tol: float
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Per (frame, point): the distance to that frame's nearest unused candidate within tol
        (inf: none), and that candidate's index in the pool (-1: none); only the frame's three
        candidates nearest the point are looked at (a point crowded by taken candidates finds
        none). ``frames``: one frame index per point."""
        dist = np.full(len(points), np.inf)
        idx = np.full(len(points), -1, dtype=np.int64)
        _nearest_kernel(
            np.asarray(frames, dtype=np.int64),
            np.ascontiguousarray(points, dtype=np.float64),
            float(tol),
            self.start,
            self.pos,
            self.used,
            dist,
            idx,
        )
        return dist, idx


@numba.njit(cache=True)
def _isolated(centroid: NDArray[np.float64], radius: float) -> NDArray[np.bool_]:
    """(K,) whether no other of the points ``centroid`` (K,3) lies within ``radius`` (at most,
    compared squared, as a KD-tree's ball query counts); a frame holds a few clusters, so
    every pair is measured."""
    k = len(centroid)
    r2 = radius * radius
    out = np.ones(k, dtype=np.bool_)
    for i in range(k):
        for j in range(i + 1, k):
            if _dist2(centroid, j, centroid[i, 0], centroid[i, 1], centroid[i, 2]) <= r2:
                out[i] = False
                out[j] = False
    return out


@numba.njit(cache=True, inline="always")
def _dist2(pos: NDArray[np.float64], c: int, x: float, y: float, z: float) -> float:
    """Squared distance from candidate ``c`` to (x, y, z), summed x, y, z as numpy and the
    KD-tree do."""
    dx = pos[c, 0] - x
    dy = pos[c, 1] - y
    dz = pos[c, 2] - z
    return dx * dx + dy * dy + dz * dz


@numba.njit(cache=True)
def _nearest_kernel(
    frames: NDArray[np.int64],
    points: NDArray[np.float64],
    tol: float,
    start: NDArray[np.int64],
    pos: NDArray[np.float64],
    used: NDArray[np.bool_],
    dist: NDArray[np.float64],
    idx: NDArray[np.int64],
) -> None:
    """``_Pool.nearest`` (fills ``dist`` and ``idx``): a frame holds a few candidates, so every
    one of them is measured."""
    tol2 = tol * tol  # within tol: compared squared, as a KD-tree's distance bound is
    for q in range(len(points)):
        f = frames[q]
        # the three nearest within tol, nearest first (ties: the lower index)
        d3 = np.full(3, np.inf)
        i3 = np.full(3, -1, dtype=np.int64)
        for c in range(start[f], start[f + 1]):
            d2 = _dist2(pos, c, points[q, 0], points[q, 1], points[q, 2])
            if not d2 < tol2:
                continue
            d = np.sqrt(d2)
            if not d < d3[2]:
                continue
            k = 2
            while k > 0 and d < d3[k - 1]:
                d3[k] = d3[k - 1]
                i3[k] = i3[k - 1]
                k -= 1
            d3[k] = d
            i3[k] = c
        for k in range(3):
            if i3[k] >= 0 and not used[i3[k]]:
                dist[q] = d3[k]
                idx[q] = i3[k]
                break


@numba.njit(cache=True)
def _pairs_kernel(
    pos: NDArray[np.float64],
    times_s: NDArray[np.float64],
    frames: NDArray[np.int64],
    start: NDArray[np.int64],
    reach: float,
    max_speed: float,
    min_speed: float,
    after_s: float,
    out: NDArray[np.int64],
) -> int:
    """The seed pairs of ``_seeds`` in its order (earlier frame, later frame, then the
    candidates' own order), written to ``out`` while it has room; returns how many there are
    (call again with a larger ``out`` when that is more than its rows)."""
    n = 0
    nf = len(frames)
    for i in range(nf):
        a = frames[i]
        if times_s[a] < after_s - reach:
            continue
        for j in range(i + 1, nf):
            b = frames[j]
            dt = times_s[b] - times_s[a]
            if dt > reach:
                break
            if times_s[b] < after_s:
                continue
            r = max_speed * dt
            lo = min_speed * dt
            for ia in range(start[a], start[a + 1]):
                for ib in range(start[b], start[b + 1]):
                    d2 = _dist2(pos, ib, pos[ia, 0], pos[ia, 1], pos[ia, 2])
                    if d2 <= r * r and np.sqrt(d2) >= lo:
                        if n < len(out):
                            out[n, 0] = ia
                            out[n, 1] = ib
                        n += 1
    return n


def _seeds(
    pool: _Pool, times_s: NDArray[np.float64], cfg: TrackingConfig, after_s: float = -np.inf
) -> NDArray[np.int64]:
    """(S,2) candidate pairs (earlier, later) whose implied speed a drone could fly, the later
    one at ``after_s`` or after."""
    reach = min(cfg.line_seed_s, cfg.line_window_s)
    args = (
        pool.pos,
        times_s,
        pool.frames,
        pool.start,
        float(reach),
        float(cfg.max_speed),
        float(cfg.line_min_speed),
        float(after_s),
    )
    out = np.empty((4 * len(pool.frame), 2), dtype=np.int64)
    n = _pairs_kernel(*args, out)
    if n > len(out):
        out = np.empty((n, 2), dtype=np.int64)
        _pairs_kernel(*args, out)
    out = out[:n]
    cap = max(_SEEDS_PER_FRAME * len(times_s), _MIN_SEED_CAP)
    if len(out) > cap:
        gap = pool.t[out[:, 1]] - pool.t[out[:, 0]]
        out = out[np.argsort(gap, kind="stable")[:cap]]
    return out


def _count(
    pool: _Pool,
    seeds: NDArray[np.int64],
    times_s: NDArray[np.float64],
    cfg: TrackingConfig,
    half_scan_s: float,
) -> NDArray[np.int64]:
    """Per seed: distinct places along its line (within the window around it) where a frame
    has a candidate on the line."""
    a, b = seeds[:, 0], seeds[:, 1]
    ta, tb = pool.t[a], pool.t[b]
    v = (pool.pos[b] - pool.pos[a]) / (tb - ta)[:, None]
    speed = np.linalg.norm(v, axis=1)
    tol = _tolerance(speed, cfg, half_scan_s)
    counts = np.zeros(len(seeds), dtype=np.int64)
    _count_kernel(
        pool.pos,
        pool.t,
        pool.frames,
        times_s[pool.frames],
        pool.start,
        np.ascontiguousarray(a),
        np.ascontiguousarray(b),
        v,
        speed,
        tol,
        float(cfg.line_seed_s),  # a seed pair predicts well only near itself
        counts,
    )
    return counts


@numba.njit(cache=True)
def _count_kernel(
    pos: NDArray[np.float64],
    t: NDArray[np.float64],
    frames: NDArray[np.int64],
    frame_t: NDArray[np.float64],
    start: NDArray[np.int64],
    a: NDArray[np.int64],
    b: NDArray[np.int64],
    v: NDArray[np.float64],
    speed: NDArray[np.float64],
    tol: NDArray[np.float64],
    w: float,
    counts: NDArray[np.int64],
) -> None:
    """``_count`` (fills ``counts``): for each seed, the frames within ``w`` of it (and whose
    window of ``w`` plus the seed's reach, ``w`` again, holds the seed's start), the nearest
    candidate to the seed's line at the frame's time; one within the seed's tolerance marks
    the place along the line (twice the tolerance long) it lies in; a static clump counts once."""
    places = np.empty(len(frames), dtype=np.int64)
    for s in range(len(a)):
        ta, tb = t[a[s]], t[b[s]]
        m = 0
        q = np.searchsorted(frame_t, ta - w)
        while q < len(frames):
            tf = frame_t[q]
            if tf > tb + w:
                break
            if tf >= ta - w and tf - w - w <= ta < tf + w:
                dt = tf - ta
                px = pos[a[s], 0] + v[s, 0] * dt
                py = pos[a[s], 1] + v[s, 1] * dt
                pz = pos[a[s], 2] + v[s, 2] * dt
                best = np.inf
                f = frames[q]
                for c in range(start[f], start[f + 1]):
                    d = np.sqrt(_dist2(pos, c, px, py, pz))
                    if d < best:
                        best = d
                if best <= tol[s]:
                    places[m] = np.int64(np.floor(dt * speed[s] / (2.0 * tol[s])))
                    m += 1
            q += 1
        if m:
            srt = np.sort(places[:m])
            n = 1
            for k in range(1, m):
                if srt[k] != srt[k - 1]:
                    n += 1
            counts[s] = n


def _tolerance(speed: _Speed, cfg: TrackingConfig, half_scan_s: float) -> _Speed:
    """How far a cluster on the line may lie from its position at the frame's time: the
    centroid's noise plus the drone's travel over half a scan (a scan's points are taken over
    its whole duration)."""
    return cfg.line_tol_m + speed * half_scan_s


def _grow(
    pool: _Pool,
    seed: NDArray[np.int64],
    times_s: NDArray[np.float64],
    cfg: TrackingConfig,
    half_scan_s: float,
) -> NDArray[np.int64]:
    """The inliers (pool indices, in time order) of the line grown from a seed pair."""
    members: dict[int, int] = {int(pool.frame[i]): int(i) for i in seed}
    while True:
        idx = np.array(sorted(members.values(), key=lambda i: pool.frame[i]))
        t0, t1 = times_s[pool.frame[idx[0]]], times_s[pool.frame[idx[-1]]]
        # the frames within line_window_s of the inliers (times_s is increasing)
        lo = int(np.searchsorted(times_s, t0 - cfg.line_window_s, side="left"))
        hi = int(np.searchsorted(times_s, t1 + cfg.line_window_s, side="right"))
        window = np.arange(lo, hi)
        todo = window[pool.start[window + 1] > pool.start[window]]  # frames with candidates
        todo = todo[[f not in members for f in todo.tolist()]]
        if not len(todo):
            return idx
        tf = times_s[todo]
        part = np.where(tf < t0, 0, np.where(tf > t1, 2, 1))
        pred = np.empty((len(todo), 3))
        tol = np.empty(len(todo))
        # the frames before the first inlier follow the fit of the first _END_FIT inliers, those
        # between them the fit of all, those after the last the fit of the last _END_FIT (one
        # fit when there are no more inliers than that)
        ends = (slice(None, _END_FIT), slice(None), slice(-_END_FIT, None))
        whole: tuple[NDArray[np.float64], NDArray[np.float64], float] | None = None
        for k, end in enumerate(ends):
            on = part == k
            if not on.any():
                continue
            if len(idx) <= _END_FIT:
                whole = whole or constant_velocity_fit(pool.t[idx], pool.pos[idx])
                p0, v, tm = whole
            else:
                p0, v, tm = constant_velocity_fit(pool.t[idx[end]], pool.pos[idx[end]])
            # (np.outer and np.linalg.norm of a 3-vector, without their call overhead)
            pred[on] = p0 + (tf[on] - tm)[:, None] * v[None, :]
            tol[on] = _tolerance(math.sqrt(float(v @ v)), cfg, half_scan_s)
        d, j = pool.nearest(todo, pred, float(tol.max()))
        hit = d <= tol
        if not hit.any():
            return idx
        members.update(zip(todo[hit].tolist(), j[hit].tolist(), strict=True))


def _sweep_deg(p: NDArray[np.float64]) -> float:
    """The angle the points span as seen from the sensor, degrees (first to farthest)."""
    u = p / np.maximum(np.linalg.norm(p, axis=1), 1e-9)[:, None]
    return float(np.degrees(np.arccos(np.clip(np.min(u @ u[0]), -1.0, 1.0))))


def _places(p: NDArray[np.float64], v: NDArray[np.float64], size: float) -> int:
    """Distinct places of ``size`` metres along direction ``v`` that the points ``p`` occupy.
    ``find_lines`` sizes them by the centroid's noise (2 ``line_tol_m``), not by the line's
    tolerance: that includes the scan's smear (a timing spread), and at 20 m/s would merge
    the sightings of consecutive scans, 2 m apart, into one place."""
    speed = float(np.linalg.norm(v))
    if speed == 0.0:
        return 1
    along = (p - p[0]) @ (v / speed)
    return len(np.unique(np.floor(along / size)))


def find_lines(
    tables: list[ClusterTable],
    times_s: NDArray[np.float64],
    cfg: TrackingConfig,
    first_id: int,
    half_scan_s: float = 0.05,
    seeds_after_s: float = -np.inf,
) -> list[TrackRecord]:
    """Candidate tracks of sparse fast movers (see the module docstring).

    Args:
        tables: every frame's clusters.
        times_s: (N,) each frame's observation time, seconds.
        cfg: the tracking configuration (``line_*``, ``max_speed``, ``max_size_m``,
            ``min_cross_section_m2``).
        first_id: the track id of the first line (after the tracker's ids).
        half_scan_s: half a scan's duration: a scan's points are taken up to this long before
            or after the frame's observation time, so a line's tolerance grows by its speed
            times this.
        seeds_after_s: lines start only from pairs whose later detection is this late or
            later (they still grow back from there): the causal search looks for lines seen
            lately, at a third of the cost.

    Returns:
        One TrackRecord per line found, ids from ``first_id`` on.
    """
    if not cfg.line_search or len(tables) < cfg.line_min_hits:
        return []
    pool = _Pool(tables, times_s, cfg)
    seeds = _seeds(pool, times_s, cfg, seeds_after_s)
    if not len(seeds):
        return []
    counts = _count(pool, seeds, times_s, cfg, half_scan_s)
    order = np.argsort(-counts, kind="stable")
    order = order[counts[order] >= 3]  # the pair and one more place: worth growing
    lines: list[TrackRecord] = []
    tried = np.zeros(len(pool.frame), dtype=bool)  # inliers of a line already grown
    for s in order:
        if pool.used[seeds[s]].any() or tried[seeds[s]].all():
            continue  # taken, or it would grow into a line already grown
        idx = _grow(pool, seeds[s], times_s, cfg, half_scan_s)
        tried[idx] = True
        t, p = pool.t[idx] + pool.lag[idx], pool.pos[idx]
        p0, v, tm = constant_velocity_fit(t, p)
        speed = float(np.linalg.norm(v))
        tol = _tolerance(speed, cfg, half_scan_s)
        if (
            speed < cfg.line_min_speed
            or speed > cfg.max_speed
            or _places(p, v, 2.0 * cfg.line_tol_m) < cfg.line_min_hits
            or _sweep_deg(p) < cfg.line_min_sweep_deg
        ):
            continue
        pool.used[idx] = True
        res = p - (p0 + np.outer(t - tm, v))
        nis = _NIS95 * np.minimum(np.einsum("ij,ij->i", res, res) / tol**2, 1.0)
        frames, clusters = pool.frame[idx], pool.cluster[idx]
        lines.append(
            TrackRecord(
                track_id=first_id + len(lines),
                frames=frames,
                clusters=clusters,
                positions=p,
                n_points=np.array(
                    [tables[f].n_points[c] for f, c in zip(frames, clusters, strict=True)],
                    dtype=np.int64,
                ),
                nis=nis,
                speed=np.full(len(idx), speed),
                dt=pool.lag[idx] if np.any(pool.lag[idx]) else None,
            )
        )
    return lines
