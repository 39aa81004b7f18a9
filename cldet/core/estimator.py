"""The estimator: one interface, two methods (``track``, ours, and ``cl-det``, the baseline).

An estimator sees a sequence twice, in order: ``observe`` every frame (pass 1: learn the static
background), then ``process`` every frame (pass 2: the per-frame verb, returning that frame's
foreground and clusters), then ``finish`` once (association, selection, smoothing: the method is
offline). Memory stays small: per frame only the clusters are kept.

``track`` (:class:`TrackEstimator`):

1. both LiDARs fused in the Mid-360 frame (the Avia fires ~14 ms later: < 0.2 m at 15 m/s,
   well inside the clustering radius); self-returns and far returns dropped (``frames``);
2. static background removed (``cldet.core.background``: per-direction static range over time
   bins, dilated);
3. the foreground clustered exactly (``cldet.core.clustering``: DBSCAN eps 1 m, min 1 point, as
   a far drone gives 1-3 points);
4. every cluster seeds or extends a candidate Kalman track (``cldet.core.tracking``);
   a confirmed moving track that gets no cluster continues on the raw points (background
   included) within ``raw_gate_m`` of its prediction, so a drone stopping at static structure
   does not vanish;
5. ``finish``: the drone's chain of tracks chosen by whole-sequence evidence
   (``cldet.core.selection``); a forward-backward RTS smoother (``cldet.core.smoothing``)
   fills the gaps; before the first and after the last detection the track's own motion is
   extrapolated, its velocity decaying with time constant ``extrapolation_tau_s`` (a drone
   does not fly straight for ever); the centroid bias correction (``cldet.core.bias``) is
   applied last. Only when no candidate track exists at all is the configured fallback
   position used.

Each estimate's source: DETECTED (the chosen track had a cluster, or raw points, in that
frame; ``n_points`` is their count), SMOOTHED (between detections), PREDICTED (before the
first or after the last detection), FALLBACK (no track at all). ``sigma_m`` is the smoother's
per-axis 1-sigma position uncertainty (the model is isotropic).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from cldet.config import CldetConfig
from cldet.core.background import FOREGROUND, BackgroundModel
from cldet.core.bias import apply_bias
from cldet.core.clustering import cluster_points, summarize_clusters
from cldet.core.frames import valid_points
from cldet.core.selection import ScoredTrack, score_tracks, select_chain
from cldet.core.smoothing import extrapolate, rts_smooth
from cldet.core.tracking import CandidateTracker, ClusterTable
from cldet.types import Cluster, Estimate, LidarFrame, Source

__all__ = [
    "Estimator",
    "FrameDetections",
    "SequenceEstimate",
    "TrackEstimator",
    "TrackEvent",
    "estimate_sequence",
    "fuse_points",
    "make_estimator",
]

NS_PER_S = 1_000_000_000
_LOST_AFTER_S = 0.5  # a gap without detection longer than this is reported as lost/reacquired


@dataclass(frozen=True)
class FrameDetections:
    """What ``process`` returns for one frame (plain data for channels and visualisation)."""

    stamp_ns: int
    foreground: NDArray[np.float32]  # (M,3) foreground points, metres, Mid-360 frame
    labels: NDArray[np.int32]  # (M,) cluster id per foreground point, -1 noise
    clusters: tuple[Cluster, ...]


@dataclass(frozen=True)
class TrackEvent:
    """Something worth a log line: "acquired", "lost", "reacquired", "predicted", "switched"."""

    stamp_ns: int
    kind: str
    text: str


@dataclass(frozen=True)
class SequenceEstimate:
    """The result of ``finish``."""

    estimates: tuple[Estimate, ...]  # one per processed frame stamp, in time order
    chosen: dict[int, int]  # stamp_ns -> cluster_id chosen in that frame (absent when none)
    events: tuple[TrackEvent, ...]


class Estimator(Protocol):
    """Two passes over a sequence, then ``finish``."""

    name: str

    def observe(self, frame: LidarFrame) -> None:
        """Pass 1: learn the background (called for every frame, in order)."""

    def process(self, frame: LidarFrame) -> FrameDetections:
        """Pass 2: the per-frame verb (called for every frame, in order)."""

    def finish(self) -> SequenceEstimate:
        """After pass 2: association, selection, smoothing."""


def fuse_points(frame: LidarFrame, cfg: CldetConfig) -> tuple[NDArray[np.float32], int]:
    """Both LiDARs' valid points in one (N,3) array, Mid-360 first; and the Mid-360 count."""
    fc = cfg.frames
    mid = valid_points(frame.mid360, fc.min_range_m, fc.max_range_m)
    avia = valid_points(frame.avia, fc.min_range_m, fc.max_range_m)
    if len(avia) == 0:
        return mid, len(mid)
    return np.concatenate([mid, avia]), len(mid)


class TrackEstimator:
    """The ``track`` method (see the module docstring)."""

    name = "track"

    def __init__(self, config: CldetConfig) -> None:
        self.config = config
        self.background = BackgroundModel(config.background)
        self._tracker = CandidateTracker(config.tracking)
        self._stamps: list[int] = []
        self._tables: list[ClusterTable] = []
        self._last_observed: int | None = None

    def observe(self, frame: LidarFrame) -> None:
        """Pass 1: count the frame's points into the background model."""
        if self._last_observed is not None and frame.stamp_ns < self._last_observed:
            raise ValueError(f"frames out of order: {frame.stamp_ns} after {self._last_observed}")
        self._last_observed = frame.stamp_ns
        pts, _ = fuse_points(frame, self.config)
        self.background.observe(frame.stamp_ns, pts)

    def process(self, frame: LidarFrame) -> FrameDetections:
        """Pass 2: remove the background, cluster the foreground, advance the candidate tracks."""
        if self._stamps and frame.stamp_ns <= self._stamps[-1]:
            raise ValueError(f"frames out of order: {frame.stamp_ns} after {self._stamps[-1]}")
        cfg = self.config
        index = len(self._stamps)
        pts, n_mid = fuse_points(frame, cfg)
        lab = self.background.classify(pts)
        fg_mask = lab == FOREGROUND
        fg_idx = np.flatnonzero(fg_mask)
        if len(fg_idx) > cfg.clustering.max_points:  # keep the nearest
            r2 = np.einsum("ij,ij->i", pts[fg_idx], pts[fg_idx])
            fg_idx = np.sort(fg_idx[np.argsort(r2, kind="stable")[: cfg.clustering.max_points]])
        fg = pts[fg_idx]
        n_mid_fg = int(np.searchsorted(fg_idx, n_mid))
        labels = cluster_points(fg, cfg.clustering.eps_m, cfg.clustering.min_samples)
        clusters = summarize_clusters(fg, labels, n_mid_fg)
        table = ClusterTable.from_clusters(clusters)
        if len(clusters):
            # a cluster whose continuation below is hidden by the background (a person's legs
            # in the ground's margin) may reach the ground: its height evidence says so
            low = table.low_z()
            bottom = np.column_stack([table.centroid[:, :2], low])
            hidden = self.background.hidden_below(bottom)
            if hidden.any():
                table = replace(table, lower_z=np.where(hidden, self.background.ground_z(), low))
        self._stamps.append(frame.stamp_ns)
        self._tables.append(table)
        self._tracker.step(index, (frame.stamp_ns - self._stamps[0]) / NS_PER_S, table, pts)
        return FrameDetections(
            stamp_ns=frame.stamp_ns, foreground=fg, labels=labels, clusters=clusters
        )

    # ------------------------------------------------------------------ finish
    def finish(self) -> SequenceEstimate:
        """Select the drone's chain of tracks, fill gaps from raw points, smooth, extrapolate."""
        cfg = self.config
        n = len(self._stamps)
        if n == 0:
            return SequenceEstimate((), {}, ())
        stamps = np.asarray(self._stamps, dtype=np.int64)
        t_s = (stamps - stamps[0]) / NS_PER_S
        tc = cfg.tracking
        ground = tc.ground_z_m if tc.ground_z_m is not None else self.background.ground_z()
        scored = score_tracks(
            self._tracker.records(),
            self._tables,
            t_s,
            ground,
            tc,
            free_sky_deg=self.config.background.floating_any_range_above_deg,
        )
        chain = select_chain(scored, tc)
        if not chain:
            pos = np.asarray(tc.fallback_position, dtype=np.float64)
            est = tuple(Estimate(int(s), pos.copy(), Source.FALLBACK, 0, 1e3) for s in stamps)
            ev = TrackEvent(int(stamps[0]), "lost", "no candidate track: fallback position")
            return SequenceEstimate(est, {}, (ev,))

        z = np.full((n, 3), np.nan)
        sigma = np.full(n, tc.meas_sigma_m)
        n_points = np.zeros(n, dtype=np.int64)
        chosen: dict[int, int] = {}
        raw = np.zeros(n, dtype=bool)
        events: list[TrackEvent] = []
        for k, (tr, i0, i1) in enumerate(chain):
            rec = tr.record
            for h in range(i0, i1):
                f, c = int(rec.frames[h]), int(rec.clusters[h])
                z[f] = rec.positions[h]
                n_points[f] = int(rec.n_points[h])
                if c >= 0:
                    chosen[int(stamps[f])] = c
                else:
                    raw[f] = True
                    sigma[f] = tc.raw_meas_sigma_m
            if k > 0:
                events.append(
                    TrackEvent(
                        int(stamps[rec.frames[i0]]),
                        "switched",
                        f"drone track continues as candidate {rec.track_id} (score {tr.score:.1f})",
                    )
                )
        have = np.all(np.isfinite(z), axis=1)
        idx = np.flatnonzero(have)
        first, last = int(idx[0]), int(idx[-1])
        seg = slice(first, last + 1)
        sm = rts_smooth(t_s[seg], z[seg], sigma[seg], cfg.smoothing.accel_psd, tc.init_speed_sigma)
        pos = np.zeros((n, 3))
        var = np.zeros(n)
        pos[seg] = sm.position
        var[seg] = sm.pos_var
        q = cfg.smoothing.accel_psd
        for f in list(range(first)) + list(range(last + 1, n)):
            k_end = 0 if f < first else -1
            dt = t_s[f] - t_s[first if f < first else last]
            pos[f], var[f] = extrapolate(
                sm.position[k_end],
                sm.velocity[k_end],
                sm.cov[k_end],
                dt,
                q,
                cfg.smoothing.extrapolation_tau_s,
            )
        pos = apply_bias(pos, cfg.bias)

        estimates = []
        for f in range(n):
            if have[f]:
                source = Source.DETECTED
            elif first < f < last:
                source = Source.SMOOTHED
            else:
                source = Source.PREDICTED
            estimates.append(
                Estimate(
                    stamp_ns=int(stamps[f]),
                    position=pos[f],
                    source=source,
                    n_points=int(n_points[f]) if have[f] else 0,
                    sigma_m=float(np.sqrt(max(var[f], 0.0))),
                )
            )
        events.extend(_gap_events(stamps, t_s, have, raw, first, last, chain))
        events.sort(key=lambda e: e.stamp_ns)
        return SequenceEstimate(tuple(estimates), chosen, tuple(events))


def _gap_events(
    stamps: NDArray[np.int64],
    t_s: NDArray[np.float64],
    have: NDArray[np.bool_],
    raw: NDArray[np.bool_],
    first: int,
    last: int,
    chain: list[tuple[ScoredTrack, int, int]],
) -> list[TrackEvent]:
    """acquired / lost / reacquired / predicted events of the final track."""
    out = [
        TrackEvent(
            int(stamps[first]),
            "acquired",
            f"drone acquired (candidate {chain[0][0].record.track_id}, score {chain[0][0].score:.1f},"
            f" {len(chain)} candidate track(s) chained)",
        )
    ]
    if first > 0:
        out.append(
            TrackEvent(
                int(stamps[0]), "predicted", "before the first detection: track extrapolated"
            )
        )
    idx = np.flatnonzero(have)
    for a, b in zip(idx[:-1], idx[1:], strict=True):
        if t_s[b] - t_s[a] > _LOST_AFTER_S:
            out.append(TrackEvent(int(stamps[a + 1]), "lost", f"no detection after {t_s[a]:.1f} s"))
            out.append(
                TrackEvent(
                    int(stamps[b]), "reacquired", f"detected again after {t_s[b] - t_s[a]:.1f} s"
                )
            )
    n_raw = int(raw.sum())
    if n_raw:
        f = int(np.argmax(raw))
        out.append(
            TrackEvent(
                int(stamps[f]),
                "raw-gate",
                f"{n_raw} frame(s) detected from raw points near the track",
            )
        )
    if last < len(stamps) - 1:
        out.append(
            TrackEvent(
                int(stamps[last + 1]), "predicted", "after the last detection: track extrapolated"
            )
        )
    return out


def make_estimator(config: CldetConfig) -> Estimator:
    """The estimator the configuration's ``method`` names."""
    if config.method == "track":
        return TrackEstimator(config)
    if config.method == "cl-det":
        from cldet.core.cldet_baseline import ClDetEstimator

        return ClDetEstimator(config)
    raise ValueError(f"unknown method {config.method!r}")  # unreachable: validated by config


def estimate_sequence(
    frames: Callable[[], Iterable[LidarFrame]], config: CldetConfig
) -> tuple[list[FrameDetections], SequenceEstimate]:
    """Run both passes over a re-iterable frame source (``frames()`` is called twice), then finish."""
    estimator = make_estimator(config)
    for frame in frames():
        estimator.observe(frame)
    detections = [estimator.process(frame) for frame in frames()]
    return detections, estimator.finish()
