"""The estimator: one interface, two methods (``track``, ours, and ``cl-det``, the baseline).

An estimator sees a sequence once, in stamp order, through one per-frame verb
(KISS-ICP's shape): ``register_frame(frame)`` uses only the past and returns that frame's
foreground, clusters and the *causal* estimate. After the last frame ``refine()`` works over
what was stored per frame (the clusters and the candidate tracks, never the raw points) and
returns the *refined* track: the best whole-sequence choice, smoothed and gap-filled.

``track`` (:class:`TrackEstimator`), per frame:

1. both LiDARs fused in the Mid-360 frame (the Avia fires ~14 ms later: < 0.3 m at 20 m/s,
   well inside the clustering radius); self-returns and far returns dropped (``frames``);
2. the static background, learned online over a sliding window, removed
   (``cldet.core.background``; the first ``background.bin_s`` is its warm-up); once
   ``background.replay_s`` has passed, the frames before it are judged again against the
   background learned by then, for the refinement: more clusters there, and tracks over them
   (``_replay``: the only raw points ever kept are those frames'; the causal estimates stay);
3. the foreground clustered exactly (``cldet.core.clustering``: DBSCAN eps 1 m, min 1 point, as
   a far drone gives 1-3 points); each cluster's height above the local ground comes from the
   fitted ground (``cldet.core.ground``), set to 0 when the cluster may continue below what is
   seen (cut by the bottom of the Mid-360's field of view, ``fov_bottom_deg`` in the sensor's
   own frame, or hidden by the ground's background margin one cell below); where a confirmed
   drone-sized track that has flown predicts its object inside a cluster wider than a drone,
   the isolated blob there is carved out as a cluster of its own (``tracking.carve_gate_m``,
   ``cldet.core.tracking.carve_tracked``: rain near the sensor chains into one wide cluster
   that a close drone joins);
4. every cluster seeds or extends a candidate Kalman track (``cldet.core.tracking``), taken at
   the frame's time (the stamp plus ``frames.scan_offset_s``, the middle of the scan); each
   detection keeps when its points were taken, their mean firing time where the clouds record
   it (``fuse_timed``), and the fits over a track's detections (the line search, the
   refinement's smoother and straight runs, and the tracker's output state) measure it there
   (``frames.point_times``: 'fit'; 'track' dates it in the tracker's filter too, 'off'
   nowhere); a confirmed moving track that gets no cluster continues on the raw points near its
   prediction; the points of confirmed small moving tracks are withheld from the background
   (``background.protect_tracks``), so a drone that stops to hover is not learned: once their
   half-second mean lies ``background.protect_min_moved_m`` from its first value, or while
   their clusters are dense (``background.protect_dense_points``) and either their
   detections lie within a drone's size or the track is too young for a running mean
   (``_protects``); and from then on while the track lives (``background.protect_hold``);
5. the causal choice: the active track with the highest running evidence (the per-detection
   weights of ``cldet.core.selection``, times its static and speed factors so far, re-weighed
   by the learned scorer as the refinement does: ``_learned_factor``; a challenger must
   beat the current choice by ``_SWITCH_RATIO`` (both as chains: see below); no track is
   reported before its own evidence reaches ``tracking.causal_confirm``, and none is chosen
   before it has lived
   ``tracking.causal_judge_s``, from when on it is judged static or rigidly fixed: for its
   first second a still object, say a sign overhead, looks like a drone that just arrived;
   rigid also by its detections after its first second alone, ``tracking.causal_robust_still``:
   ``_rigid``);
   the estimate is that track's filtered state moved back from the points' time to the stamp.
   In a frame the followed track misses, the estimate follows the line of the straight run
   that ends its detections, where one does (``smoothing.causal_straight_coast``: the filter
   takes a sparse fast pass's smeared last detections as speed). When the followed track is
   lost and no other is chosen, the estimate carries its motion on from the past alone
   (``_coast_from``): along the line of a straight run that ended it, held for
   ``smoothing.straight_hold_factor`` times as long as the run lasted, as the refinement does;
   else from the track's last state (the tracker predicted it at constant velocity until it
   ended), the velocity decaying from then. The lost chain's evidence keeps competing for
   ``link_max_gap_s`` (``tracking.causal_keep_lost``), as the refinement weighs whole chains:
   a track that could continue it (``_continues``: the refinement's link from the lost
   track's last detection before the track's first, from where it was or where its motion
   carried it, ``link_jump``) competes with the chain's evidence added to its own (counted whole,
   where the refinement counts a track only up to the next one's start), any other only once
   its own exceeds the chain's; a challenger must beat the followed chain's total by
   ``_SWITCH_RATIO``, what two continuations of one chain share cancelling. While no track is
   followed, the line search of the refinement (``cldet.core.lines``) runs every
   ``tracking.causal_line_every_s`` over the last ``tracking.causal_line_window_s``
   (``_search_lines``): a line seen lately whose evidence reaches ``causal_confirm`` is
   followed along its fit, as a lost straight track is, whatever a lost chain's evidence (a
   line is a coast, not a chosen track). From then on the line is the lost chain, where
   there was none, where it outweighs it, or where it continues it (keeping the larger of
   the two evidences): a track that turns up while the pass is out of reach must outweigh it, as it would a
   lost track's.
   A sparse fast pass, one return in a few scans, never makes a Kalman track to follow.

``refine``: the candidate tracks plus the constant-velocity lines of sparse fast movers
(``cldet.core.lines``, track-before-detect); the drone's chain of tracks chosen by
whole-sequence evidence (``cldet.core.selection``: hand-set factors re-weighed by the
packaged prior of ``cldet.core.prior`` and by a model's own scorer where one is given), carried
on at its ends by weak tracks that touch it (``selection.extend_chain``); a
forward-backward RTS smoother (``cldet.core.smoothing``) fills
the gaps; before the first and after the last detection the track's own motion is
extrapolated, its velocity decaying with time constant ``extrapolation_tau_s`` (no faster than a
multirotor brakes: ``max_decel_mps2``), or held still
where carrying it on contradicts what was not seen, or where the static scene shows it came
to rest at its end (``_stop_unseen``), and kept clear of the ground: a path carried on does
not pass through it, keeping the height above it that it had at that end, up to
``terrain_clearance_m`` (``_clear_of_ground``; a pass over a slope climbs with it, and so does
the causal estimate's coast); the centroid
bias correction (``cldet.core.bias``) is applied last. Only when no candidate track exists at
all is the configured fallback position used.

Each estimate's source: DETECTED (the chosen track had a cluster, or raw points, in that
frame; ``n_points`` is their count), SMOOTHED (between detections), PREDICTED (before the
first or after the last detection, or, causally, a frame the chosen track was not seen in),
FALLBACK (no track at all). ``sigma_m`` is the per-axis 1-sigma position uncertainty.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray

from cldet.config import CldetConfig, SmoothingConfig, TrackingConfig
from cldet.core.background import FOREGROUND, MARGIN, BackgroundModel, StaticView
from cldet.core.bias import apply_bias
from cldet.core.clustering import cluster_points, summarize_clusters
from cldet.core.features import (
    FEATURE_NAMES,
    TrackDetections,
    track_detections,
    track_features,
)
from cldet.core.frames import valid_mask
from cldet.core.ground import GroundModel
from cldet.core.lines import find_lines
from cldet.core.model import LearnedModel
from cldet.core.prior import load_prior
from cldet.core.selection import (
    FIXED_JUDGE_S,
    FIXED_MEAN_HITS,
    LEARNED_FLOOR,
    ScoredTrack,
    TrackScorer,
    TrackWeigher,
    detection_weights,
    extend_chain,
    fixed_spread,
    link_jump,
    link_reach,
    rigid_now,
    sampling_jitter,
    score_tracks,
    select_chain,
    split_rigid,
)
from cldet.core.smoothing import decay_tau, extrapolate, rts_smooth, straight_run
from cldet.core.stats import median
from cldet.core.tracking import (
    ActiveTracks,
    CandidateTracker,
    ClusterTable,
    TrackRecord,
    carve_tracked,
    constant_velocity_fit,
    cross_section,
    crowding,
    widen_box,
    windowed_velocity,
)
from cldet.errors import FrameOrderError
from cldet.stamps import NS_PER_S
from cldet.types import ClassEstimate, Cluster, Estimate, LidarFrame, Source

__all__ = [
    "Estimator",
    "FrameDetections",
    "SequenceEstimate",
    "TrackEstimator",
    "TrackEvent",
    "fuse_points",
    "fuse_timed",
]

_LOST_AFTER_S = 0.5  # a gap without detection longer than this is reported as lost/reacquired
_SWITCH_RATIO = 1.3  # causal choice: a challenger must have this much more evidence
_JUDGE_STATIC_S = 1.0  # causal, without causal_judge_s: a track is judged static after this
_LEARNED_EVERY = 5  # causal: a track's learned factor and rigidity are redone after this many hits
_T = TypeVar("_T")
# the eight corners of a box: which axes take the upper bound, corner m's bit d for axis d
_BOX_CORNERS = np.array([[(m >> d) & 1 for d in range(3)] for m in range(8)], dtype=bool)


@dataclass(frozen=True)
class FrameDetections:
    """What ``register_frame`` returns for one frame (plain data for channels and views)."""

    stamp_ns: int
    foreground: NDArray[np.float32]  # (M,3) foreground points, metres, Mid-360 frame
    labels: NDArray[np.int32]  # (M,) cluster id per foreground point, -1 noise
    clusters: tuple[Cluster, ...]
    estimate: Estimate | None = None  # the causal estimate (None: the method makes none)

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickled with its clusters as one array: ``annotate`` spools every frame's detections
        (``cldet.io.spool``), and a tuple of small dataclasses of arrays pickles slowly."""
        packed = np.array(
            [
                (
                    c.cluster_id,
                    *c.centroid,
                    *c.lower,
                    *c.upper,
                    c.n_points,
                    c.n_mid360,
                    c.n_avia,
                    c.mid360_z_ss,
                )
                for c in self.clusters
            ],
            dtype=np.float64,
        ).reshape(-1, 14)
        return (
            _unpack_detections,
            (self.stamp_ns, self.foreground, self.labels, packed, self.estimate),
        )


def _unpack_detections(
    stamp_ns: int,
    foreground: NDArray[np.float32],
    labels: NDArray[np.int32],
    packed: NDArray[np.float64],
    estimate: Estimate | None,
) -> FrameDetections:
    """``FrameDetections.__reduce__`` undone (every value as it was: float64 holds the counts)."""
    clusters = tuple(
        Cluster(
            cluster_id=int(row[0]),
            centroid=row[1:4],
            lower=row[4:7],
            upper=row[7:10],
            n_points=int(row[10]),
            n_mid360=int(row[11]),
            n_avia=int(row[12]),
            mid360_z_ss=float(row[13]),
        )
        for row in packed
    )
    return FrameDetections(stamp_ns, foreground, labels, clusters, estimate)


@dataclass(frozen=True)
class TrackEvent:
    """Something worth a log line: "acquired", "lost", "reacquired", "predicted", "switched"."""

    stamp_ns: int
    kind: str
    text: str


@dataclass(frozen=True)
class SequenceEstimate:
    """The result of ``refine``."""

    estimates: tuple[Estimate, ...]  # refined: one per frame stamp, in time order
    chosen: dict[int, int]  # stamp_ns -> cluster_id chosen in that frame (absent when none)
    events: tuple[TrackEvent, ...]
    causal: tuple[Estimate, ...] = ()  # the causal estimate of every frame, as it was made
    classes: tuple[ClassEstimate, ...] = ()  # the drone type as evidence grew (with a model)


@dataclass(frozen=True)
class Candidates:
    """What ``refine`` chooses from: every candidate track and the frames' cluster tables."""

    records: list[TrackRecord]  # the tracker's tracks and the line search's (split_rigid: cut)
    tables: list[ClusterTable]  # one per frame
    times_s: NDArray[np.float64]  # (F,) each frame's observation time, s from the first stamp
    stamps_ns: NDArray[np.int64]  # (F,)
    view: StaticView | None = None  # the static scene after the last frame (None: unknown)
    ground: GroundModel | None = None  # the ground after the last frame (None: unknown)


class Estimator(Protocol):
    """One per-frame verb over a sequence in stamp order, then ``refine``."""

    name: str

    def register_frame(self, frame: LidarFrame) -> FrameDetections:
        """The per-frame verb: uses only this and earlier frames (stamps strictly increasing)."""

    def refine(self) -> SequenceEstimate:
        """After the last frame: the refined track over what was stored per frame."""


def check_order(last_ns: int | None, stamp_ns: int) -> None:
    """Raise :class:`FrameOrderError` unless ``stamp_ns`` comes strictly after ``last_ns``."""
    if last_ns is not None and stamp_ns <= last_ns:
        kind = "repeats the stamp of the previous frame" if stamp_ns == last_ns else "comes before"
        raise FrameOrderError(
            f"frame stamped {stamp_ns} ns {kind} {last_ns} ns: frames must be in strictly"
            " increasing stamp order"
        )


@dataclass(frozen=True)
class _HeadFrame:
    """One frame of the head ``_replay`` judges again: its fused points, the Mid-360's count,
    the points' times, and the foreground's indices and cluster labels as first found."""

    points: NDArray[np.float32]
    n_mid: int
    p_times: NDArray[np.float32]
    fg_idx: NDArray[np.intp]
    labels: NDArray[np.int32]


def _extended(table: ClusterTable, wider: ClusterTable) -> ClusterTable:
    """``wider`` (a frame's clusters and more after them), its first clusters' values those of
    ``table`` (the frame's clusters as first found, left as they were judged)."""
    k = len(table)
    out = {}
    for name in ("height", "crowd", "screened", "mid360_z_ss", "dt", "size"):
        old, new = getattr(table, name), getattr(wider, name)
        if old is None or new is None:
            out[name] = new
            continue
        new = new.copy()
        new[:k] = old
        out[name] = new
    return replace(wider, **out)


@dataclass(frozen=True)
class _Coast:
    """Where the causal estimate coasts from once the followed track is lost."""

    t_s: float  # observation time of ``origin``, s from the first stamp
    origin: NDArray[np.float64]  # (3,)
    velocity: NDArray[np.float64]  # (3,) m/s, held ``hold_s`` then decaying
    hold_s: float
    sigma_m: float  # the last followed estimate's 1-sigma


@dataclass(frozen=True)
class _Lost:
    """The causal choice's chain after its last track was lost: its evidence and the lost
    track's detections, against which other tracks are judged (see ``_decide``)."""

    score: float  # the chain's evidence when it was lost
    times_s: NDArray[np.float64]  # (H,) the lost track's detection times, s
    positions: NDArray[np.float64]  # (H,3) its detections
    velocity: NDArray[np.float64]  # (H,3) its motion at each (``windowed_velocity``), m/s


@dataclass
class _Evidence:
    """A candidate track's running evidence for the causal choice."""

    weight: float = 0.0  # summed per-detection weights after the first detection
    hits: int = 0
    first_t_s: float = 0.0
    last_t_s: float = 0.0
    first_position: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    both: int = 0  # detections seen by both LiDARs in one cluster
    # the box around its detections and around its running means, per axis (``widen_box``)
    lower: list[float] = field(default_factory=lambda: [np.inf] * 3)
    upper: list[float] = field(default_factory=lambda: [-np.inf] * 3)
    moved: float = 0.0  # largest edge of the box around its detections, metres
    recent: deque[tuple[float, float, float]] = field(
        default_factory=lambda: deque(maxlen=FIXED_MEAN_HITS)
    )
    recent_sum: list[float] = field(default_factory=lambda: [0.0] * 3)
    mean_lower: list[float] = field(default_factory=lambda: [np.inf] * 3)
    mean_upper: list[float] = field(default_factory=lambda: [-np.inf] * 3)
    means: int = 0  # running means of FIXED_MEAN_HITS detections taken into the box
    mean_moved: float = 0.0  # largest edge of the box around those means, metres
    first_mean: tuple[float, float, float] = (0.0, 0.0, 0.0)
    last_mean: tuple[float, float, float] = (0.0, 0.0, 0.0)
    jitter_sum: float = 0.0  # summed sampling jitter of the detections (selection.sampling_jitter)
    protected: bool = False  # protected from the background once (``background.protect_hold``)

    def add(
        self,
        t_s: float,
        weight: float,
        position: NDArray[np.float64],
        both: bool,
        jitter_m: float = 0.0,
    ) -> None:
        self.jitter_sum += jitter_m
        if self.hits:
            self.weight += weight
        else:
            self.first_t_s = t_s
            self.first_position = np.array(position, dtype=np.float64)
        self.last_t_s = t_s
        self.hits += 1
        self.both += int(both)
        p = (float(position[0]), float(position[1]), float(position[2]))
        self.moved = widen_box(self.lower, self.upper, p)
        total = self.recent_sum
        if len(self.recent) == FIXED_MEAN_HITS:
            old = self.recent[0]
            for k in range(3):
                total[k] -= old[k]
        self.recent.append(p)
        for k in range(3):
            total[k] += p[k]
        if len(self.recent) == FIXED_MEAN_HITS:
            mean = (
                total[0] / FIXED_MEAN_HITS,
                total[1] / FIXED_MEAN_HITS,
                total[2] / FIXED_MEAN_HITS,
            )
            self.mean_moved = widen_box(self.mean_lower, self.mean_upper, mean)
            if self.means == 0:
                self.first_mean = mean
            self.last_mean = mean
            self.means += 1

    @property
    def displaced(self) -> float:
        """From the first running mean to the latest, metres (0 before the first)."""
        return float(np.linalg.norm(np.array(self.last_mean) - np.array(self.first_mean)))

    @property
    def lived(self) -> float:
        """Seconds from the first detection to the last."""
        return self.last_t_s - self.first_t_s

    def score(self, cfg: TrackingConfig, rigid: bool = False) -> float:
        """Running evidence; "static" and "fixed" (see ``cldet.core.selection``: here the box
        around the running means, whose edge is about twice the spread) are judged once the
        track has lived ``causal_judge_s`` (when 0: ``_JUDGE_STATIC_S``, fixed
        ``FIXED_JUDGE_S``); the fixed spread grows to the detections' mean sampling jitter
        times ``fixed_sampling_factor`` as in the refinement. ``rigid``: judged fixed from its
        detections after its head (``selection.rigid_now``; ``tracking.causal_robust_still``)."""
        lived = self.lived
        factor = 1.0
        judge_fixed = cfg.causal_judge_s or FIXED_JUDGE_S
        judge_static = cfg.causal_judge_s or _JUDGE_STATIC_S
        if lived >= judge_fixed and (
            rigid
            or (
                self.means > FIXED_MEAN_HITS
                and self.mean_moved < 2.0 * fixed_spread(cfg, self.jitter_sum / self.hits)
            )
        ):
            factor = cfg.fixed_factor
        elif lived >= judge_static and self.moved < 2.0 * cfg.static_spread_m:
            factor = cfg.static_factor
        return self.weight * factor * (1.0 + 0.5 * self.both / max(self.hits, 1))


def fuse_points(frame: LidarFrame, cfg: CldetConfig) -> tuple[NDArray[np.float32], int]:
    """Both LiDARs' valid points in one (N,3) array, Mid-360 first; and the Mid-360 count."""
    pts, n_mid, _ = fuse_timed(frame, cfg)
    return pts, n_mid


def _timed(
    points: NDArray[np.float32],
    times: NDArray[np.float32] | None,
    shift_s: float,
    cfg: CldetConfig,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """One LiDAR's valid points and their times after the frame's stamp: the recorded times
    shifted by ``shift_s`` (its own stamp's lag), else the configured ``scan_offset_s``."""
    fc = cfg.frames
    p = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
    keep = valid_mask(p, fc.min_range_m, fc.max_range_m)
    if times is None or len(times) != len(p) or fc.point_times == "off":
        t = np.full(len(p), fc.scan_offset_s, dtype=np.float32)
    else:
        t = np.asarray(times, dtype=np.float32) + np.float32(shift_s)
    if keep.all():
        return p, t
    return p[keep], t[keep]


def fuse_timed(
    frame: LidarFrame, cfg: CldetConfig
) -> tuple[NDArray[np.float32], int, NDArray[np.float32]]:
    """``fuse_points`` and each point's time after the frame's stamp, seconds: its firing time
    where the cloud recorded it (``Cloud.times``; the Avia's counted from its own stamp) and
    ``frames.point_times`` is not 'off', else the middle of the scan (``frames.scan_offset_s``)."""
    mid, t_mid = _timed(frame.mid360, frame.mid360_times, 0.0, cfg)
    lag = 0.0 if frame.avia_stamp_ns is None else (frame.avia_stamp_ns - frame.stamp_ns) / NS_PER_S
    avia, t_avia = _timed(frame.avia, frame.avia_times, lag, cfg)
    if len(avia) == 0:
        return mid, len(mid), t_mid
    return np.concatenate([mid, avia]), len(mid), np.concatenate([t_mid, t_avia])


def seen_times(t_s: NDArray[np.float64], lags: NDArray[np.float64]) -> NDArray[np.float64]:
    """When each detection was seen: its frame's observation time ``t_s`` plus its ``lags``
    (its points' mean time in the scan; 0 where undated), kept in order where an Avia
    detection's lag overtakes the next frame's. What every fit over a track's detections uses
    (``frames.point_times``): the refinement's smoother and straight runs, and the causal
    estimate's straight coasts and lines, the same fits from the past alone."""
    return np.maximum.accumulate(t_s + lags)


def _cluster_lags(
    labels: NDArray[np.integer], times: NDArray[np.float32], k: int, offset_s: float
) -> NDArray[np.float64]:
    """(K,) each cluster's mean point time after the frame's observation time (its stamp plus
    ``offset_s``), seconds: where in the scan its object was seen (0 where the points' times
    were not recorded: they are all dated at the offset)."""
    ok = labels >= 0
    lab = labels[ok]
    n = np.bincount(lab, minlength=k)[:k]
    total = np.bincount(lab, weights=times[ok].astype(np.float64), minlength=k)[:k]
    # the times are float32: measured from the offset as float32 too, the points of a cloud
    # without recorded times (all dated at the offset) give lags of exactly 0
    return total / np.maximum(n, 1) - float(np.float32(offset_s))


class TrackEstimator:
    """The ``track`` method (see the module docstring)."""

    name = "track"

    def __init__(self, config: CldetConfig, model: LearnedModel | None = None) -> None:
        self.config = config
        self.model = model  # learned scorer and type classifier (None: the hand-set defaults)
        self._candidates: Candidates | None = None
        sensor = config.sensor
        self.background = BackgroundModel(
            config.background,
            field_bottom_deg=config.tracking.fov_bottom_deg,
            ground_plane=GroundModel.from_pose(sensor.height_m, sensor.roll_deg, sensor.pitch_deg)
            if sensor.ground_from_pose
            else None,
        )
        self._tracker = CandidateTracker(
            config.tracking, dated=config.frames.point_times == "track"
        )
        self._stamps: list[int] = []
        self._tables: list[ClusterTable] = []
        self._times = np.zeros(1024)  # observation time of each frame, s from the first stamp
        self._evidence: dict[int, _Evidence] = {}
        # the learned re-weighing the causal choice applies to evidence (the refinement's), and
        # per track the hits its last factor was computed at and the factor
        self._weigher = _weigher(model, config.tracking)
        self._learned: dict[int, tuple[int, float]] = {}
        self._rigid_cache: dict[int, tuple[int, bool]] = {}  # causal_robust_still: (hits, rigid)
        self._choice: int | None = None  # causal: the track followed
        # causal (``tracking.causal_keep_lost``): the chain lost, the evidence the followed
        # track carries on from a lost chain it continues, and the followed chain's evidence
        self._lost: _Lost | None = None
        self._base = 0.0
        self._value = 0.0
        # the followed track's filtered state at the last frame it was followed (obs time s,
        # position, velocity), and, once it is lost, where the causal estimate coasts from
        self._state: tuple[float, NDArray[np.float64], NDArray[np.float64]] | None = None
        self._coast: _Coast | None = None
        # the straight run ending a followed track, by (track, its last detection's frame)
        self._run_coast: tuple[int, int, _Coast | None] | None = None
        self._line_t = -np.inf  # when the causal line search last ran (s)
        self._causal: list[Estimate] = []
        # where protected movers were last seen: (position (3,), time s); a cluster there is
        # protected too (a hovering drone's track may end and restart without moving again)
        self._zones: dict[int, tuple[NDArray[np.float64], float]] = {}  # by track id
        # the first ``background.replay_s`` of frames, kept to be judged again once (``_replay``),
        # and what that gave the refinement: wider cluster tables of those frames, and by
        # track id the detections found before a track's first
        self._head: list[_HeadFrame] | None = [] if config.background.replay_s > 0 else None
        self._replayed_tables: dict[int, ClusterTable] = {}
        self._prefixes: dict[int, TrackRecord] = {}
        self._replayed: list[TrackRecord] = []  # tracks the head alone shows
        self._offset_s = config.frames.scan_offset_s
        fc = config.tracking
        self._fov_tan = np.tan(np.radians(fc.fov_bottom_deg))

    # ------------------------------------------------------------- per frame
    def register_frame(self, frame: LidarFrame) -> FrameDetections:
        """Background, clusters, candidate tracks and the causal estimate of one frame."""
        check_order(self._stamps[-1] if self._stamps else None, frame.stamp_ns)
        cfg = self.config
        index = len(self._stamps)
        pts, n_mid, p_times = fuse_timed(frame, cfg)
        bg = self.background
        bg.advance(frame.stamp_ns)
        t0_ns = self._stamps[0] if self._stamps else frame.stamp_ns
        since_s = (frame.stamp_ns - t0_ns) / NS_PER_S
        t_s = since_s + self._offset_s
        if self._head is not None and since_s >= cfg.background.replay_s:
            self._replay()
        cells, ranges = bg.directions(pts)  # for classify and update alike
        labels_bg = bg.classify(pts, (cells, ranges))
        if self._zones:
            self._reclaim(pts, labels_bg)
        fg_idx = self._nearest(np.flatnonzero(labels_bg == FOREGROUND), pts)
        labels = cluster_points(pts[fg_idx], cfg.clustering.eps_m, cfg.clustering.min_samples)
        labels[labels >= cfg.clustering.max_clusters] = -1  # ids rank by size: the smallest go
        fg, labels, clusters, table = self._frame_table(pts, n_mid, p_times, fg_idx, labels, t_s)
        if self._head is not None:
            self._head.append(_HeadFrame(pts, n_mid, p_times, fg_idx, labels))
        self._stamps.append(frame.stamp_ns)
        self._tables.append(table)
        if index == len(self._times):
            self._times = np.concatenate([self._times, np.zeros(len(self._times))])
        self._times[index] = t_s
        owner = self._tracker.step(index, t_s, table, pts)
        self._forget_ended()
        keep = self._account(index, t_s, table, owner, labels, fg_idx, pts)
        if keep is None:
            bg.update(frame.stamp_ns, pts, (cells, ranges))
        else:
            bg.update(frame.stamp_ns, pts[keep], (cells[keep], ranges[keep]))
        estimate = self._decide(index, frame.stamp_ns, owner)
        self._causal.append(estimate)
        return FrameDetections(
            stamp_ns=frame.stamp_ns,
            foreground=fg,
            labels=labels,
            clusters=clusters,
            estimate=estimate,
        )

    def _nearest(
        self, fg_idx: NDArray[np.intp], pts: NDArray[np.float32], n: int | None = None
    ) -> NDArray[np.intp]:
        """The foreground points' indices; the nearest ``n`` (``clustering.max_points``) where
        more."""
        n = self.config.clustering.max_points if n is None else max(n, 0)
        if len(fg_idx) <= n:
            return fg_idx
        r2 = np.einsum("ij,ij->i", pts[fg_idx], pts[fg_idx])
        return np.sort(fg_idx[np.argsort(r2, kind="stable")[:n]])

    def _frame_table(
        self,
        pts: NDArray[np.float32],
        n_mid: int,
        p_times: NDArray[np.float32],
        fg_idx: NDArray[np.intp],
        labels: NDArray[np.int32],
        t_s: float,
        carve: bool = True,
    ) -> tuple[NDArray[np.float32], NDArray[np.int32], tuple[Cluster, ...], ClusterTable]:
        """A frame's foreground points (``pts[fg_idx]``, labelled ``labels``), their labels once
        wide clusters are carved where tracks predict their objects (with ``carve``), the
        clusters, and the cluster table with heights, crowding, screening and lags."""
        cfg = self.config
        fg = pts[fg_idx]
        n_mid_fg = int(np.searchsorted(fg_idx, n_mid))
        clusters = summarize_clusters(fg, labels, n_mid_fg)
        table = ClusterTable.from_clusters(clusters)
        tc = cfg.tracking
        if carve and tc.carve_gate_m > 0 and np.any(table.extent > tc.max_size_m):
            # the drone-sized tracks that have flown carve their objects out of wider clusters
            ids, at = self._tracker.small_predictions(t_s)
            flown = np.array([self._has_flown(int(i)) for i in ids], dtype=bool)
            carved = carve_tracked(
                fg, labels, table.extent, at[flown], tc.carve_gate_m, tc.max_size_m
            )
            if carved is not labels:
                labels = carved
                clusters = summarize_clusters(fg, labels, n_mid_fg)
                table = ClusterTable.from_clusters(clusters)
        if len(clusters):
            crowd = crowding(table.centroid, table.n_points, tc.crowd_radius_m)
            screened = self.background.view().screened(table.centroid)
            # the clusters' lags (None: all seen at the frame's time, the points undated)
            dt = (
                _cluster_lags(labels, p_times[fg_idx], len(clusters), self._offset_s)
                if cfg.frames.point_times != "off"
                else None
            )
            table = replace(
                table, height=self._heights(clusters), crowd=crowd, screened=screened, dt=dt
            )
        return fg, labels, clusters, table

    def _replay(self) -> None:
        """The first ``background.replay_s`` judged again against the background learned since,
        for the refinement: more clusters in those frames, and tracks over them (once; then
        the frames go).

        While the window holds only a few bins, a cell's static range is the nearest range of
        any one of them (``static_fraction``): a drone there from the start is learned where
        it was a bin before. Receding along its line of sight, or crossing empty sky, where
        nothing behind it shows the spot see-through, it can stay background for seconds, and
        the refinement would carry its first later detection back over the frames it missed.
        By ``replay_s`` the cells it has left are empty again. A return is added where it is
        foreground now, was not then, and its cell has returned nothing at or in front of its
        range in the last ``seen_through_bins`` bins, at least one (whatever was there has
        gone: a far surface hit only now and then, not yet learned, stays out while it keeps
        returning); at most ``clustering.max_points`` foreground returns a frame in all, the
        nearest.
        The added returns form clusters of their own, after the frame's (whose ids and values
        stay: the tracks and the causal estimates made are untouched). A fresh tracker runs
        over the head's frames with them. Where one of its tracks took added clusters and then
        the first cluster of a track of the estimator's, its detections before that go before
        that track's in the refinement; one that took added clusters and none of the
        estimator's tracks' is a candidate of its own. The estimator's tracks are those of two
        detections or more when the replay runs (``candidates`` before ``replay_s`` runs it
        then, over the frames so far).
        """
        head, self._head = self._head, None
        if not head:
            return
        cfg = self.config
        n_back = max(cfg.background.seen_through_bins, 1)
        tracker = CandidateTracker(cfg.tracking, dated=self._tracker.dated)
        added: list[int] = []
        for index, h in enumerate(head):
            t_s = float(self._times[index])
            table = self._tables[index]
            k = len(table)
            cells, ranges = self.background.directions(h.points)
            now = np.flatnonzero(self.background.classify(h.points, (cells, ranges)) == FOREGROUND)
            new = np.setdiff1d(now, h.fg_idx, assume_unique=True)
            new = new[self.background.vacated(h.points[new], n_back, (cells[new], ranges[new]))]
            # the nearest, in the room the frame's own left (none where they were capped)
            new = self._nearest(new, h.points, cfg.clustering.max_points - len(h.fg_idx))
            extra = cluster_points(h.points[new], cfg.clustering.eps_m, cfg.clustering.min_samples)
            extra[extra >= max(cfg.clustering.max_clusters - k, 0)] = -1
            if np.any(extra >= 0):
                extra[extra >= 0] += k
                union = np.concatenate([h.fg_idx, new])
                order = np.argsort(union, kind="stable")
                fg_idx = union[order]
                labels = np.concatenate([h.labels, extra])[order]
                _, _, _, wider = self._frame_table(
                    h.points, h.n_mid, h.p_times, fg_idx, labels, t_s, carve=False
                )
                table = _extended(table, wider)
                self._replayed_tables[index] = table
            tracker.step(index, t_s, table, h.points)
            added.append(k)
        # a track found there that runs into the first detection of one of the tracker's is
        # that object found earlier (a drone learned where it just was, then found again):
        # its detections before that one go before the tracker's track. One that shares no
        # detection with the tracker's is a candidate of its own; one that merely crosses
        # them would only duplicate a track already weighed
        n = len(head)
        starts: dict[tuple[int, int], int] = {}
        known: set[tuple[int, int]] = set()  # the tracker's detections in those frames
        for r in self._tracker.records():
            if r.frames[0] >= n:
                continue
            if r.clusters[0] >= 0:
                starts[(int(r.frames[0]), int(r.clusters[0]))] = r.track_id
            inside = (r.frames < n) & (r.clusters >= 0)  # (raw-gate detections are no cluster)
            known.update(zip(r.frames[inside].tolist(), r.clusters[inside].tolist(), strict=True))
        took = np.asarray(added)
        first_id = 1 << 40  # after every id the tracker and the line search give
        for r in tracker.records():
            hindsight = r.clusters >= took[r.frames]  # the clusters the replay added
            pairs = list(zip(r.frames.tolist(), r.clusters.tolist(), strict=True))
            shared = [j for j, pair in enumerate(pairs) if pair in known]
            if not shared:
                if np.any(hindsight):
                    self._replayed.append(replace(r, track_id=first_id + r.track_id))
                continue
            j = shared[0]  # its first detection one of the tracker's took: that track's first?
            tid = starts.get(pairs[j])
            if (
                tid is not None
                and np.any(hindsight[:j])
                and (tid not in self._prefixes or self._prefixes[tid].frames[0] > r.frames[0])
            ):
                self._prefixes[tid] = r.part(0, j)
        self._candidates = None

    def _forget_ended(self) -> None:
        """Drop the causal evidence of tracks the tracker has ended (their ids never return).

        Most tracks are clutter seen once: without this the evidence would grow with the
        sequence. Swept when it holds twice the active tracks, so the cost stays per frame.
        """
        active = self._tracker.active_ids()
        if len(self._evidence) > 2 * len(active) + 64:
            alive = set(active.tolist())
            self._evidence = {k: v for k, v in self._evidence.items() if k in alive}
            self._learned = {k: v for k, v in self._learned.items() if k in alive}
            self._rigid_cache = {k: v for k, v in self._rigid_cache.items() if k in alive}

    def _heights(self, clusters: tuple[Cluster, ...]) -> NDArray[np.float64]:
        """(K,) each cluster's lowest point above the local ground, 0 where it may continue."""
        lo = np.array([c.lower for c in clusters])
        hi = np.array([c.upper for c in clusters])
        centroid = np.array([c.centroid for c in clusters])
        # the box's eight corners: with a tilted sensor "lowest" is along the ground's up
        corners = np.where(_BOX_CORNERS[None, :, :], hi[:, None, :], lo[:, None, :])  # (K,8,3)
        height = self.background.ground.height_above(corners.reshape(-1, 3)).reshape(-1, 8)
        height = height.min(axis=1)
        tc = self.config.tracking
        bottom = np.column_stack([centroid[:, :2], lo[:, 2]])
        may_continue = self.background.hidden_below(bottom)
        if tc.fov_cut_m > 0:
            # cut by the bottom of the Mid-360's field of view (the sensor's own frame), where
            # that edge passes low enough for a ground mover to reach up through it
            horiz = np.hypot(bottom[:, 0], bottom[:, 1])
            with np.errstate(invalid="ignore"):
                may_continue |= (bottom[:, 2] <= self._fov_tan * horiz + tc.fov_cut_m) & ~(
                    height >= tc.ground_mover_max_m
                )
        return np.where(may_continue & np.isfinite(height), 0.0, height)

    def _account(
        self,
        index: int,
        t_s: float,
        table: ClusterTable,
        owner: NDArray[np.int64],
        labels: NDArray[np.int32],
        fg_idx: NDArray[np.intp],
        pts: NDArray[np.float32],
    ) -> NDArray[np.bool_] | None:
        """Add this frame's detections to the tracks' evidence; the points the background may learn.

        Returns a mask over ``pts`` (None: all), without the points of confirmed small movers.
        """
        tc = self.config.tracking
        tracker = self._tracker
        protect = self.config.background.protect_tracks
        keep: NDArray[np.bool_] | None = None
        if len(owner):
            w = detection_weights(
                table.extent,
                table.heights(),
                np.zeros(len(owner), dtype=bool),
                np.array([tracker.last_hit(int(t))[3] for t in owner]),
                cross_section(table.n_mid360, table.n_avia, table.centroid, tc),
                tc,
                table.crowds(),
            )
            both = (table.n_mid360 > 0) & (table.n_avia > 0)
            jitter = sampling_jitter(table.extent, table.n_points)
            self._zones = {k: z for k, z in self._zones.items() if t_s - z[1] <= tc.max_miss_s}
            zone = self._zone_of(table) if protect else np.full(len(owner), -1)
            for j, tid in enumerate(owner.tolist()):
                self._evidence.setdefault(tid, _Evidence()).add(
                    t_s, float(w[j]), table.centroid[j], bool(both[j]), float(jitter[j])
                )
                if not protect:
                    continue
                # a confirmed small mover's cluster opens (or moves) its protected place; a
                # small cluster in such a place keeps it (the track may have restarted there)
                if self._protects(tid):
                    where = tid
                elif zone[j] >= 0:
                    where = int(zone[j])
                else:
                    continue
                self._zones[where] = (table.centroid[j].copy(), t_s)
                if keep is None:
                    keep = np.ones(len(pts), dtype=bool)
                keep[fg_idx[labels == j]] = False
        # raw-gate detections of this frame (tracks that got no cluster)
        if tc.raw_gate_m <= 0:
            return keep
        active = tracker.active()
        gate2 = tc.raw_gate_m**2
        for tid in active.ids.tolist():
            f, c, pos, nis = tracker.last_hit(tid)
            if f != index or c >= 0:
                continue
            n_raw = np.array([tracker.last_points(tid)])
            w = detection_weights(
                np.zeros(1),
                np.full(1, np.nan),
                np.ones(1, dtype=bool),
                np.array([nis]),
                cross_section(n_raw, np.zeros(1, dtype=np.int64), pos[None, :], tc),
                tc,
            )
            self._evidence.setdefault(tid, _Evidence()).add(t_s, float(w[0]), pos, False)
            if protect and self._protects(tid):
                self._zones[tid] = (np.asarray(pos, dtype=np.float64).copy(), t_s)
                if keep is None:
                    keep = np.ones(len(pts), dtype=bool)
                d = pts - pos.astype(np.float32)
                keep &= np.einsum("ij,ij->i", d, d) > gate2
        return keep

    def _protects(self, track_id: int) -> bool:
        """Whether a confirmed mover is protected: its running mean now lies
        ``background.protect_min_moved_m`` or more from the first one (a flight; the box around
        all the means would grow with a long life's scatter alone); or its clusters are dense
        (a median of ``background.protect_dense_points`` points or more) and either its
        detections still lie within a drone's size (``max_size_m``: a hover) or it is too
        young for a running mean (one compact object that jumped, say after being hidden).
        Sparse returns cannot tell a small body from a larger thing lit in different places
        each scan (a far hedge, a pole, a swaying edge): their centroids scatter within a
        drone's size for a while, and wider while their mean stays; such tracks are learned.

        With ``background.protect_hold`` a track once protected stays so while it lives: a
        drone hovering beside a wall or foliage merges now and then with foreground fringe
        beside it into a cluster wider than a drone, which is no confirmed mover in that frame;
        its points in those frames were learned, and a hover learned in three bins (the
        recurring-range rule) is lost."""
        ev = self._evidence.get(track_id)
        if self.config.background.protect_hold and ev is not None and ev.protected:
            return True
        protected = self._protects_now(track_id)
        if protected and ev is not None:
            ev.protected = True
        return protected

    def _has_flown(self, track_id: int) -> bool:
        """Whether a track's running mean now lies ``background.protect_min_moved_m`` or more
        from its first value: a flight, not a swaying clump or a flickering edge."""
        ev = self._evidence.get(track_id)
        moved = self.config.background.protect_min_moved_m
        return ev is not None and bool(ev.means) and ev.displaced >= moved

    def _protects_now(self, track_id: int) -> bool:
        """``_protects`` judged on this frame alone (without ``background.protect_hold``)."""
        tracker = self._tracker
        if not tracker.is_confirmed_mover(track_id):
            return False
        bc = self.config.background
        ev = self._evidence.get(track_id)
        if self._has_flown(track_id):
            return True
        dense = bc.protect_dense_points
        young = ev is None or ev.means == 0
        if tracker.spread(track_id) > self.config.tracking.max_size_m and (dense == 0 or not young):
            return False  # scattered wider than a drone, and not a young dense track
        return dense == 0 or tracker.median_points(track_id) >= dense

    def _reclaim(self, pts: NDArray[np.float32], labels: NDArray[np.uint8]) -> None:
        """Points background only through dilation (MARGIN) near a protected mover's last place
        are foreground again: dilation forgives beam divergence and sway of static surfaces,
        not a drone hovering right beside one (in place: ``labels`` is changed)."""
        margin = np.flatnonzero(labels == MARGIN)
        if len(margin) == 0:
            return
        places = np.array([z for z, _ in self._zones.values()], dtype=np.float64)  # a few
        d = pts[margin].astype(np.float64)[:, None, :] - places[None, :, :]
        d2 = np.einsum("mzk,mzk->mz", d, d).min(axis=1)
        # nearer than reclaim_m (strictly, compared squared: as a KD-tree's bounded query)
        labels[margin[d2 < self.config.background.reclaim_m**2]] = FOREGROUND

    def _zone_of(self, table: ClusterTable) -> NDArray[np.int64]:
        """(K,) the protected place each small cluster lies in (within ``max_gate_m``), or -1."""
        tc = self.config.tracking
        out = np.full(len(table), -1, dtype=np.int64)
        if not self._zones:
            return out
        keys = np.fromiter(self._zones.keys(), dtype=np.int64)
        places = np.array([z for z, _ in self._zones.values()])
        d2 = np.sum((table.centroid[:, None, :] - places[None, :, :]) ** 2, axis=2)  # (K,Z)
        best = np.argmin(d2, axis=1)
        ok = (d2[np.arange(len(table)), best] <= tc.max_gate_m**2) & (table.extent <= tc.max_size_m)
        out[ok] = keys[best[ok]]
        return out

    def _decide(self, index: int, stamp_ns: int, owner: NDArray[np.int64]) -> Estimate:
        """The causal estimate: the active track with the most evidence so far."""
        tc = self.config.tracking
        active = self._tracker.active()
        row = {}
        if self._choice is not None and not np.any(active.ids == self._choice):
            self._lose(self._choice)
        lost = self._lost
        if lost is not None and self._times[index] - lost.times_s[-1] > tc.link_max_gap_s:
            self._lost = lost = None  # nothing can continue it any more
        table = self._tables[index]
        seen_now = dict(zip(owner.tolist(), table.n_points.tolist(), strict=True))
        # eligible track -> (evidence carried on from the lost chain, hand-set score, hits)
        hand: dict[int, tuple[float, float, int]] = {}
        for i, tid in enumerate(active.ids.tolist()):
            ev = self._evidence.get(tid)
            if ev is None:
                continue
            row[tid] = i
            if tid != self._choice and ev.lived < tc.causal_judge_s:
                continue  # not chosen before it can be judged static or fixed
            h = ev.score(tc, self._rigid(tid, ev))
            if tid == self._choice:
                base = self._base
            elif lost is not None and self._continues(tid):
                base = lost.score
            elif lost is not None and h <= lost.score:
                continue  # neither continues the lost chain nor can outweigh it
            else:
                base = 0.0
            hand[tid] = (base, h, ev.hits)
        # the learned factor lies in [floor, 1]: a track whose value (its evidence plus what it
        # carries on) is below the least that another, surely eligible, keeps once weighed
        # cannot win, and is not scored (the scorer costs a feature vector); the followed one
        # always is (its value decides whether to switch)
        floor = self._weigher.floor if self._weigher is not None else 1.0
        top = max(
            (
                b + floor * h
                for b, h, _ in hand.values()
                if lost is None or b > 0.0 or floor * h > lost.score
            ),
            default=0.0,
        )
        best: int | None = None
        best_key: tuple[float, int] = (0.0, 0)
        own: dict[int, float] = {}  # weighed evidence of the tracks scored
        best_base = 0.0
        for tid, (base, h, hits) in hand.items():
            if base + h < top and tid != self._choice:
                continue
            sc = own[tid] = h * self._learned_factor(tid, hits)
            if tid != self._choice and lost is not None and base == 0.0 and sc <= lost.score:
                continue  # weighed, it no longer outweighs the lost chain
            # ties (young tracks) go to the one seen with more points now: the surer object
            key = (base + sc, seen_now.get(tid, 0))
            if key > best_key:
                best, best_key, best_base = tid, key, base
        choice = self._choice
        if choice is not None and choice in row:
            # the followed chain against the best: what both carry on from one lost chain
            # cancels (both continue it: their own evidence decides, as in the refinement)
            common = min(self._base, best_base)
            if (self._base - common + own[choice]) * _SWITCH_RATIO >= best_key[0] - common:
                best = choice
        if best is None or own.get(best, 0.0) <= 0.0 or own[best] < tc.causal_confirm:
            best = self._choice if self._choice in row else None
        if best is not None and best == self._choice:
            best = self._hand_over(best, row, active, index, seen_now)
        if best is None and self._choice is not None:
            self._coast = self._coast_from(self._choice, index)
        self._follow(best, own)
        if best is None:
            self._search_lines(index)
            return self._hold(stamp_ns, index)
        i = row[best]
        self._coast = None
        self._state = (
            float(self._times[index]),
            active.position[i].copy(),
            active.velocity[i].copy(),
        )
        f, c, _, _ = self._tracker.last_hit(best)
        seen = f == index
        sigma = float(np.sqrt(max(active.pos_var[i], 0.0)))
        if not seen and self.config.smoothing.causal_straight_coast:
            run = self._straight_coast(best, f, index, sigma)
            if run is not None:  # missed: a straight run's line carries on, as when lost
                return self._coast_estimate(run, stamp_ns, index)
        pos = active.position[i] - active.velocity[i] * self._offset_s
        n = 0
        if seen and c >= 0:
            n = int(self._tables[index].n_points[c])
        pos = apply_bias(pos[None, :], self.config.bias)[0]
        return Estimate(stamp_ns, pos, Source.DETECTED if seen else Source.PREDICTED, n, sigma)

    def _per_track(
        self,
        cache: dict[int, tuple[int, _T]],
        track_id: int,
        hits: int,
        judge: Callable[[TrackRecord, TrackDetections], _T],
        default: _T,
    ) -> _T:
        """A judgement of a track from its detections so far, kept in ``cache`` and made
        again once its detections have grown by a quarter (at least ``_LEARNED_EVERY``), so
        that a long track costs O(H log H) in all; ``default`` where it has no record."""
        done = cache.get(track_id)
        if done is not None and hits < max(done[0] + _LEARNED_EVERY, 1.25 * done[0]):
            return done[1]
        rec = self._tracker.record(track_id)
        if rec is None:
            return default
        value = judge(rec, track_detections(rec, self._tables, self.config.tracking))
        cache[track_id] = (hits, value)
        return value

    def _rigid(self, track_id: int, ev: _Evidence) -> bool:
        """Whether a track is rigidly fixed by its detections after its first
        ``causal_judge_s`` (its head), seen ``FIXED_JUDGE_S`` since (``selection.rigid_now``;
        ``tracking.causal_robust_still``: the box around all its running means, which one
        stray early detection widens for good, is not the only judge); see ``_per_track``."""
        tc = self.config.tracking
        head = tc.causal_judge_s or _JUDGE_STATIC_S
        if not tc.causal_robust_still or ev.lived < head + FIXED_JUDGE_S:
            return False

        def rigid(rec: TrackRecord, det: TrackDetections) -> bool:
            jitter = median(sampling_jitter(det.extent, rec.n_points))
            return rigid_now(self._times[rec.frames], rec.positions, jitter, tc, head)

        return self._per_track(self._rigid_cache, track_id, ev.hits, rigid, False)

    def _learned_factor(self, track_id: int, hits: int) -> float:
        """The learned re-weighing of a track's running evidence (:class:`TrackWeigher`), as in
        the refinement, from its detections so far (see ``_per_track``)."""
        weigher = self._weigher
        if weigher is None:
            return 1.0

        def learned(rec: TrackRecord, det: TrackDetections) -> float:
            features = track_features(rec, det, self._times[rec.frames])
            return float(weigher(features[None, :])[0])

        return self._per_track(self._learned, track_id, hits, learned, 1.0)

    def _lose(self, track_id: int) -> None:
        """The followed track has ended: its chain's evidence keeps competing
        (``tracking.causal_keep_lost``), as the refinement weighs whole chains."""
        if not self.config.tracking.causal_keep_lost:
            return
        rec = self._tracker.record(track_id)
        if rec is not None:
            times = self._times[rec.frames].copy()
            velocity = windowed_velocity(times, rec.positions, self.config.tracking.link_velocity_s)
            self._lost = _Lost(self._value, times, rec.positions, velocity)

    def _continues(self, track_id: int) -> bool:
        """The track can continue the lost chain, as the refinement links tracks: from the
        lost track's last detection before the track's first, within ``link_max_gap_s``, the
        jump (``link_jump``: from where it was, or from where its motion carried it; a fast
        pass reappears farther on) is at most ``link_reach``."""
        ev = self._evidence.get(track_id)
        return ev is not None and self._extends(ev.first_t_s, ev.first_position)

    def _extends(self, first_t_s: float, first_position: NDArray[np.float64]) -> bool:
        """Something first seen at ``first_position`` at ``first_t_s`` can continue the lost
        chain (``_continues``)."""
        lost = self._lost
        if lost is None:
            return False
        k = int(np.searchsorted(lost.times_s, first_t_s, side="left")) - 1
        if k < 0:
            return False
        tc = self.config.tracking
        gap = first_t_s - float(lost.times_s[k])
        part = slice(k, k + 1)
        jump = link_jump(
            lost.times_s[part], lost.positions[part], lost.velocity[part], first_t_s, first_position
        )
        return gap <= tc.link_max_gap_s and float(jump[0]) <= float(link_reach(gap, tc))

    def _follow(self, track_id: int | None, own: dict[int, float]) -> None:
        """Make ``track_id`` the causal choice (None: none); ``own``: the weighed evidence of
        the tracks scored this frame. A track that continues the lost chain carries its
        evidence on; one that does not has outweighed it: the chain is given up."""
        if track_id is not None and track_id != self._choice:
            continues = self._continues(track_id)
            self._base = self._lost.score if continues and self._lost is not None else 0.0
            if not continues:
                self._lost = None
        self._choice = track_id
        if track_id is None or not self.config.tracking.causal_keep_lost:
            return  # the chain's value serves only a lost chain
        sc = own.get(track_id)
        if sc is None:  # a track that took the followed one's object over (``_hand_over``)
            ev = self._evidence[track_id]
            rigid = self._rigid(track_id, ev)
            sc = ev.score(self.config.tracking, rigid) * self._learned_factor(track_id, ev.hits)
        self._value = self._base + sc

    def _hand_over(
        self,
        chosen: int,
        row: dict[int, int],
        active: ActiveTracks,
        index: int,
        seen_now: dict[int, int],
    ) -> int:
        """The followed track, or the track that took its object this frame.

        When the followed track got nothing this frame but another track got a cluster within
        the hard gate of it, that track has taken over the object (two tracks on one object:
        the younger won the assignment); the choice moves to it. ``seen_now``: the tracks that
        got a cluster this frame.
        """
        if self._tracker.last_hit(chosen)[0] == index:
            return chosen
        here = active.position[row[chosen]]
        gate2 = self.config.tracking.max_gate_m**2
        best, best_d2 = chosen, gate2
        for tid in seen_now:
            i = row.get(tid)
            if i is None or tid == chosen:
                continue
            d2 = float(np.sum((active.position[i] - here) ** 2))
            if d2 <= best_d2:
                best, best_d2 = tid, d2
        return best

    def _coast_from(self, track_id: int, index: int) -> _Coast | None:
        """Where the causal estimate goes on from when the followed track is lost, from its
        past alone: the line of a straight run that ends it, held for a multiple of the run
        (as the refinement extrapolates a track's end, ``_extrapolation_ends``), else its last
        filtered state (already predicted at constant velocity through the misses before the
        tracker ended it, so the decay starts later than the refinement's would)."""
        if self._state is None or not self._causal:
            return None
        t_state, position, velocity = self._state
        sigma_m = self._causal[-1].sigma_m
        rec = self._tracker.record(track_id)
        if rec is not None and len(rec.frames):
            run = self._straight_coast(track_id, int(rec.frames[-1]), index, sigma_m)
            if run is not None:
                return run
        return _Coast(t_state, position, velocity, 0.0, sigma_m)

    def _straight_coast(
        self, track_id: int, last_frame: int, index: int, sigma_m: float
    ) -> _Coast | None:
        """The line of the straight run ending a track's detections (up to ``last_frame``),
        held for a multiple of the run (``_extrapolation_ends``); None when no run of a transit
        ends it. Computed once per track and last detection."""
        cached = self._run_coast
        if cached is not None and cached[:2] == (track_id, last_frame):
            run = cached[2]
        else:
            run = None
            rec = self._tracker.record(track_id)
            if rec is not None and len(rec.frames):
                t = seen_times(self._times[rec.frames], rec.lags())
                p = rec.positions
                origin, v, hold_s = _extrapolation_ends(
                    t, p, p[-1:], np.zeros((1, 3)), self._scan_s(index), self.config.smoothing
                )[-1]
                if hold_s > 0.0:  # a straight run: from its line at its last detection
                    run = _Coast(float(t[-1]), origin, v, hold_s, sigma_m)
            self._run_coast = (track_id, last_frame, run)
        # the run is cached; the uncertainty it starts from is the caller's
        return None if run is None else replace(run, sigma_m=sigma_m)

    def _scan_s(self, index: int) -> float:
        """How long the scan of frame ``index`` collected its points: a frame period."""
        return float(self._times[index] - self._times[index - 1]) if index else 0.0

    def _search_lines(self, index: int) -> None:
        """While no track is followed: every ``causal_line_every_s`` the line search
        (``cldet.core.lines``) over the last ``causal_line_window_s``; the best line whose
        running evidence (scored as the refinement scores tracks) reaches ``causal_confirm``,
        and that was seen within the last ``line_seed_s``, becomes the coast: its fitted line
        carried on (held as a straight transit where it is one); and the lost chain
        (``causal_keep_lost``) where there was none, where it outweighs it, or where it
        continues it (``_extends``; the larger of the two evidences kept)."""
        tc = self.config.tracking
        t_now = float(self._times[index])
        if tc.causal_line_every_s <= 0 or t_now - self._line_t < tc.causal_line_every_s:
            return
        self._line_t = t_now
        times = self._times[: index + 1]
        i0 = int(np.searchsorted(times, t_now - tc.causal_line_window_s, side="left"))
        lines = find_lines(
            self._tables[i0 : index + 1], times[i0:], tc, -1, self._offset_s, t_now - tc.line_seed_s
        )
        if not lines:
            return
        lines = [replace(rec, frames=rec.frames + i0) for rec in lines]
        scored = score_tracks(lines, self._tables, times, tc, self._weigher)
        recent = [
            tr
            for tr in scored
            if tr.score >= tc.causal_confirm and t_now - tr.times_s[-1] <= tc.line_seed_s
        ]
        if not recent:
            return
        line = max(recent, key=lambda tr: tr.score)
        t, z = seen_times(line.times_s, line.record.lags()), line.positions
        if self._coast is not None and self._coast.t_s >= t[-1]:
            return  # a lost track seen more recently already coasts
        p0, v, tm = constant_velocity_fit(t, z)
        at_end = p0 + v * (t[-1] - tm)
        origin, velocity, hold_s = _extrapolation_ends(
            t, z, at_end[None, :], v[None, :], self._scan_s(index), self.config.smoothing
        )[-1]
        self._coast = _Coast(float(t[-1]), origin, velocity, hold_s, tc.line_tol_m)
        lost = self._lost
        if tc.causal_keep_lost and (
            lost is None
            or line.score > lost.score
            or self._extends(float(line.times_s[0]), line.positions[0])
        ):
            # the line followed is a chain as a lost track's is: its evidence keeps competing
            # (one that continues the lost chain keeps the larger of the two evidences)
            base = lost.score if lost is not None else 0.0
            self._lost = _Lost(max(base, line.score), line.times_s.copy(), z, line.velocity)

    def _coast_estimate(self, c: _Coast, stamp_ns: int, index: int) -> Estimate:
        """The estimate at a frame from a coast: its origin carried on at its velocity, held
        ``hold_s`` and then decaying, and kept clear of the ground (``_clear_of_ground``), as the
        refinement's extrapolation does."""
        sc = self.config.smoothing
        dt = float(self._times[index]) - self._offset_s - c.t_s  # to the stamp's time
        tau_s = decay_tau(c.velocity, sc.extrapolation_tau_s, sc.max_decel_mps2)
        pos, var = extrapolate(
            c.origin, c.velocity, np.zeros((2, 2)), dt, sc.accel_psd, tau_s, c.hold_s
        )
        ground = self.background.ground
        pos = _clear_of_ground(c.origin, pos[None, :], ground, sc.terrain_clearance_m)
        pos = apply_bias(pos, self.config.bias)[0]
        sigma = float(np.hypot(c.sigma_m, np.sqrt(max(var, 0.0))))
        return Estimate(stamp_ns, pos, Source.PREDICTED, 0, sigma)

    def _hold(self, stamp_ns: int, index: int) -> Estimate:
        """No track to follow: the lost track's motion carried on (``_coast_from``, its velocity
        decaying as the refinement's extrapolation does), else the last causal estimate held,
        else the fallback position."""
        c = self._coast
        if c is not None:
            return self._coast_estimate(c, stamp_ns, index)
        if self._causal and self._causal[-1].source != Source.FALLBACK:
            last = self._causal[-1]
            dt = (stamp_ns - last.stamp_ns) / NS_PER_S
            sigma = float(np.hypot(last.sigma_m, self.config.tracking.init_speed_sigma * dt))
            return Estimate(stamp_ns, last.position.copy(), Source.PREDICTED, 0, sigma)
        pos = np.asarray(self.config.tracking.fallback_position, dtype=np.float64)
        return Estimate(stamp_ns, pos, Source.FALLBACK, 0, 1e3)

    # ------------------------------------------------------------------ refine
    def candidates(self) -> Candidates:
        """Every candidate track after the last frame: the tracker's and the line search's, a
        fixed head or tail cut off where another track shows the fixed object (``split_rigid``)."""
        if self._head:  # shorter than ``background.replay_s``: judged again at the end
            self._replay()
        n = len(self._stamps)
        if self._candidates is None or len(self._candidates.tables) != n:
            t_s = self._times[:n].copy()  # observation times (stamp + scan offset)
            tables = list(self._tables)
            for i, table in self._replayed_tables.items():
                tables[i] = table
            records = [
                r.after(self._prefixes[r.track_id]) if r.track_id in self._prefixes else r
                for r in self._tracker.records()
            ] + self._replayed
            if n:  # over the clusters as found (the replay's are hindsight, not sightings)
                records += find_lines(
                    self._tables, t_s, self.config.tracking, self._tracker.next_id, self._offset_s
                )
            records = split_rigid(records, tables, t_s, self.config.tracking)
            stamps = np.asarray(self._stamps, dtype=np.int64)
            self._candidates = Candidates(
                records,
                tables,
                t_s,
                stamps,
                self.background.view(onset=True),
                self.background.ground,
            )
        return self._candidates

    def refine(self, model: LearnedModel | None = None) -> SequenceEstimate:
        """Select the drone's chain of tracks over the whole sequence, smooth, extrapolate;
        with a model (``model``, else the estimator's) score tracks and type the drone with it."""
        causal = tuple(self._causal)
        if not self._stamps:
            return SequenceEstimate((), {}, (), causal)
        model = model if model is not None else self.model
        result = refine_candidates(self.candidates(), self.config, model)
        # a cluster the replay added was never reported (``register_frame`` had returned the
        # frame): the estimate there is DETECTED, but no reported cluster is the drone
        reported = {self._stamps[i]: len(self._tables[i]) for i in self._replayed_tables}
        chosen = {s: c for s, c in result.chosen.items() if c < reported.get(s, c + 1)}
        return replace(result, chosen=chosen, causal=causal)


def refine_candidates(
    cand: Candidates, cfg: CldetConfig, model: LearnedModel | None = None
) -> SequenceEstimate:
    """The refined track of a sequence from its candidates (see the module docstring); without
    the causal estimates, which only the per-frame pass makes."""
    n = len(cand.stamps_ns)
    offset_s = cfg.frames.scan_offset_s
    stamps, t_s = cand.stamps_ns, cand.times_s
    tc = cfg.tracking
    scored = score_tracks(cand.records, cand.tables, t_s, tc, _weigher(model, tc))
    chain = extend_chain(select_chain(scored, tc), scored, tc)
    if not chain:
        pos = np.asarray(tc.fallback_position, dtype=np.float64)
        est = tuple(Estimate(int(s), pos.copy(), Source.FALLBACK, 0, 1e3) for s in stamps)
        ev = TrackEvent(int(stamps[0]), "lost", "no candidate track: fallback position")
        return SequenceEstimate(est, {}, (ev,))

    z = np.full((n, 3), np.nan)
    lag = np.zeros(n)  # each detection's time after its frame's observation time
    sigma = np.full(n, tc.meas_sigma_m)
    n_points = np.zeros(n, dtype=np.int64)
    chosen: dict[int, int] = {}
    raw = np.zeros(n, dtype=bool)
    events: list[TrackEvent] = []
    for k, (tr, i0, i1) in enumerate(chain):
        rec = tr.record
        lags = rec.lags()
        for h in range(i0, i1):
            f, c = int(rec.frames[h]), int(rec.clusters[h])
            z[f] = rec.positions[h]
            lag[f] = lags[h]
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
    # when each detection was seen; frames without one: their observation time
    t_obs = seen_times(t_s, lag)
    sm = rts_smooth(t_obs[seg], z[seg], sigma[seg], cfg.smoothing.accel_psd, tc.init_speed_sigma)
    pos = np.zeros((n, 3))
    var = np.zeros(n)
    # the smoother's states are at the points' time: move them back to the stamps
    pos[seg] = sm.position - sm.velocity * (t_obs[seg] - t_s[seg] + offset_s)[:, None]
    var[seg] = sm.pos_var
    q = cfg.smoothing.accel_psd
    scan_s = float(np.median(np.diff(t_s))) if n > 1 else 0.0  # a scan lasts a frame period
    ends = _extrapolation_ends(t_obs[idx], z[idx], sm.position, sm.velocity, scan_s, cfg.smoothing)
    if cand.view is not None and cfg.smoothing.unseen_check_s > 0:
        tr0, i0, _ = chain[0]
        c0 = int(tr0.record.clusters[i0])
        flags = cand.tables[int(tr0.record.frames[i0])].screened
        came_out = bool(flags[c0]) if flags is not None and c0 >= 0 else False
        # the chain's end position became static while it was followed: it stopped there
        stayed = cfg.smoothing.came_to_rest and bool(
            cand.view.appeared(ends[-1][0][None, :], int(stamps[first]))[0]
        )
        # nothing is foreground during the background's warm-up: no evidence either way
        blind = stamps < stamps[0] + int(round(cfg.background.bin_s * 1e9))
        ends = _stop_unseen(ends, t_s, have, blind, cand.view, came_out, stayed, cfg.smoothing)
    sc = cfg.smoothing
    taus = {
        k: decay_tau(v, sc.extrapolation_tau_s, sc.max_decel_mps2) for k, (_, v, _) in ends.items()
    }
    for f in list(range(first)) + list(range(last + 1, n)):
        k_end = 0 if f < first else -1
        origin, velocity, hold_s = ends[k_end]
        dt = t_s[f] - t_obs[first if f < first else last] - offset_s
        pos[f], var[f] = extrapolate(origin, velocity, sm.cov[k_end], dt, q, taus[k_end], hold_s)
    if cand.ground is not None and sc.ground_stop_m > 0:
        _stop_at_ground(pos, first, last, cand.ground, sc.ground_stop_m)
    if cand.ground is not None:
        for end, rows in ((first, np.arange(first)), (last, np.arange(last + 1, n))):
            pos[rows] = _clear_of_ground(pos[end], pos[rows], cand.ground, sc.terrain_clearance_m)
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
    classes = () if model is None else _classify(model, chain, cand, tc)
    return SequenceEstimate(tuple(estimates), chosen, tuple(events), classes=classes)


def _extrapolation_ends(
    t: NDArray[np.float64],
    z: NDArray[np.float64],
    position: NDArray[np.float64],
    velocity: NDArray[np.float64],
    scan_s: float,
    cfg: SmoothingConfig,
) -> dict[int, tuple[NDArray[np.float64], NDArray[np.float64], float]]:
    """Where the extrapolation beyond the start (key 0) and the end (key -1) of the detections
    ``z`` at times ``t`` starts, its velocity, and how long that holds before it decays: the
    smoother's end state (``position``, ``velocity``), not held; but where the detections
    ending (starting) the track run straight (``straight_min_points`` or more, however short) at
    ``straight_min_speed_mps`` or more (a transit, not a hover), the run's own line: its
    position at the end detection's time and its velocity, fitted to the whole run (the
    smoother's end state rests on the last few detections, each smeared along the path by the
    scan), held ``straight_hold_factor`` times as long as the run lasted (at most
    ``straight_max_hold_s``).
    ``scan_s``: how long a scan collects its points (the smear a fast drone leaves)."""
    ends = {0: (position[0], velocity[0], 0.0), -1: (position[-1], velocity[-1], 0.0)}
    if cfg.straight_rms_m <= 0:
        return ends
    for key, (tt, zz, sign) in {0: (-t[::-1], z[::-1], -1.0), -1: (t, z, 1.0)}.items():
        run = straight_run(tt, zz, cfg.straight_rms_m, scan_s, cfg.straight_min_points)
        if run is not None and float(np.linalg.norm(run.velocity)) >= cfg.straight_min_speed_mps:
            hold_s = min(cfg.straight_hold_factor * run.duration_s, cfg.straight_max_hold_s)
            ends[key] = (run.position, sign * run.velocity, hold_s)
    return ends


def _weigher(model: LearnedModel | None, cfg: TrackingConfig) -> TrackWeigher | None:
    """The learned re-weighing of the hand-set track factors: the packaged prior
    (``tracking.prior_scorer``) times a model's own scorer, either alone, or none."""
    scorers: list[tuple[TrackScorer, float]] = []
    if cfg.prior_scorer:
        prior = load_prior()
        scorers.append((prior.drone_probability, prior.floor))
    if model is not None and model.scorer is not None:
        scorers.append((model.drone_probability, LEARNED_FLOOR))
    return TrackWeigher(tuple(scorers)) if scorers else None


def _stop_unseen(
    ends: dict[int, tuple[NDArray[np.float64], NDArray[np.float64], float]],
    t_s: NDArray[np.float64],
    have: NDArray[np.bool_],
    blind: NDArray[np.bool_],
    view: StaticView,
    came_out: bool,
    stayed: bool,
    cfg: SmoothingConfig,
) -> dict[int, tuple[NDArray[np.float64], NDArray[np.float64], float]]:
    """``ends`` (see ``_extrapolation_ends``), each held still instead where the motion carried
    on contradicts what was not seen: over ``unseen_check_s`` beyond that end (the frames that
    are not ``blind``: during the background's warm-up nothing can be detected) the carried-on
    path lies in open view (``StaticView.open``) where, at the detection rate of the track's
    last (first) ``unseen_check_s``, scaled by range^-2 as returns are, at least one detection
    was likelier than ``unseen_confidence``; and the static scene at that end could hide a
    drone that stayed: after the last detection, the final scene is screened there (a drone
    that stopped and was learned as background, or hid behind something); before the first,
    the scene was screened where the track began (``came_out``: it came out of a hover that
    had been learned). A fast pass leaving the field, a drone turning behind a building, or a
    sparse far one keep their motion; so does one that ended in the open, where a drone that
    stopped would still be seen. ``stayed``: the static surface at the track's end appeared
    there while it was followed, where the sensors had seen through that spot before
    (``StaticView.appeared``): it came to rest there and was learned, and is held there even
    where its carried-on path could have gone unseen (behind the very surface it became)."""
    first, last = (int(i) for i in np.flatnonzero(have)[[0, -1]])
    out = dict(ends)
    for key, end, sign in ((0, first, -1), (-1, last, 1)):
        origin, velocity, hold_s = ends[key]
        if key == -1 and stayed:
            out[key] = (origin, np.zeros(3), 0.0)
            continue
        beyond = np.flatnonzero(
            (sign * (t_s - t_s[end]) > 0) & (sign * (t_s - t_s[end]) <= cfg.unseen_check_s) & ~blind
        )
        within = np.flatnonzero(
            (sign * (t_s[end] - t_s) > 0)
            & (sign * (t_s[end] - t_s) <= cfg.unseen_check_s)
            & (np.arange(len(t_s)) >= first)
            & (np.arange(len(t_s)) <= last)
        )
        if len(beyond) == 0 or len(within) < 3 or not np.any(velocity):
            continue
        rate = min(float(np.mean(have[within])), 0.9)
        if rate <= 0.0:
            continue
        dt = t_s[beyond] - t_s[end]
        tau = decay_tau(velocity, cfg.extrapolation_tau_s, cfg.max_decel_mps2)
        still = np.zeros((2, 2))
        path = np.array([extrapolate(origin, velocity, still, d, 0.0, tau, hold_s)[0] for d in dt])
        r_end = float(np.linalg.norm(origin))
        r = np.maximum(np.linalg.norm(path, axis=1), 1e-3)
        returns = -np.log1p(-rate) * (r_end / r) ** 2  # Poisson mean of a detection's returns
        p_seen = 1.0 - np.exp(-returns[view.open(path)])
        if np.prod(1.0 - p_seen) > 1.0 - cfg.unseen_confidence:
            continue  # the carried-on motion could have gone unseen
        hidden = came_out if key == 0 else bool(view.screened(origin[None, :])[0])
        if hidden:
            out[key] = (origin, np.zeros(3), 0.0)
    return out


def _stop_at_ground(
    pos: NDArray[np.float64], first: int, last: int, ground: GroundModel, margin_m: float
) -> None:
    """In place: the extrapolated positions ``pos`` before row ``first`` and after row ``last``
    (the detections' span), each path followed outwards from its end: where it runs more than
    ``margin_m`` below the ground (``GroundModel.depth_below``; the margin keeps the ground's
    own unevenness and a drone flying low from stopping it), it is held from where it met the
    ground: its last position above the ground before that, or the end's own
    (``smoothing.ground_stop_m``)."""
    for end, rows in ((first, np.arange(first - 1, -1, -1)), (last, np.arange(last + 1, len(pos)))):
        path = np.concatenate([[end], rows])  # from the end row outwards
        depth = ground.depth_below(pos[path])
        under = np.flatnonzero(depth > margin_m)
        if len(under):
            above = np.flatnonzero(depth[: under[0]] <= 0.0)
            k = int(above[-1]) if len(above) else 0
            pos[path[k + 1 :]] = pos[path[k]]


def _clear_of_ground(
    end: NDArray[np.float64], path: NDArray[np.float64], ground: GroundModel, clearance_m: float
) -> NDArray[np.float64]:
    """The positions ``path`` (N,3), carried on beyond a track's detections from its end
    position ``end`` (3,), lifted along the ground's "up" wherever they lie less than the
    clearance above the ground (``GroundModel.depth_below``) that ``end`` has, capped at
    ``clearance_m`` (``smoothing.terrain_clearance_m``): a drone flying on cannot pass through
    the ground, and one seen flying clear of it stays clear. Unchanged before the ground's
    first fit."""
    if not ground.fitted or ground.normal is None or clearance_m <= 0 or not len(path):
        return path
    above = -float(ground.depth_below(end[None, :])[0])
    clear = min(max(above, 0.0), clearance_m)
    lift = np.maximum(ground.depth_below(path) + clear, 0.0)
    return path + lift[:, None] * np.asarray(ground.normal, dtype=np.float64)[None, :]


CLASS_EVERY_S = 1.0
"""A sequence's drone type is re-estimated every this many seconds as its evidence grows."""


def chain_type_features(
    chain: list[tuple[ScoredTrack, int, int]],
    cand: Candidates,
    cfg: TrackingConfig,
    until_s: Sequence[float] = (np.inf,),
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """The chain's tracks over their detections up to each time of ``until_s``: features
    (T, F), each one's weight in the vote (T,: the detections it gave the chain) and the index
    of its time in ``until_s`` (T,)."""
    parts = [(tr, i0, i1, track_detections(tr.record, cand.tables, cfg)) for tr, i0, i1 in chain]
    feats, weights, groups = [], [], []
    for g, t in enumerate(until_s):
        for tr, i0, i1, det in parts:
            upto = min(i1, int(np.searchsorted(tr.times_s, t, side="right")))
            if upto - i0 < 1 or upto < 2:
                continue
            feats.append(track_features(tr.record, det, tr.times_s, upto))
            weights.append(float(upto - i0))
            groups.append(g)
    return (
        np.array(feats).reshape(-1, len(FEATURE_NAMES)),
        np.array(weights, dtype=np.float64),
        np.array(groups, dtype=np.int64),
    )


def _classify(
    model: LearnedModel,
    chain: list[tuple[ScoredTrack, int, int]],
    cand: Candidates,
    cfg: TrackingConfig,
) -> tuple[ClassEstimate, ...]:
    """The drone type every ``CLASS_EVERY_S`` from the chain's evidence so far, and at the end."""
    if model.typer is None:
        return ()
    t_s, stamps = cand.times_s, cand.stamps_ns
    ticks = np.arange(t_s[0], t_s[-1], CLASS_EVERY_S) + CLASS_EVERY_S
    marks = sorted({int(i) for i in np.searchsorted(t_s, ticks)} | {len(t_s) - 1})
    marks = [m for m in marks if m < len(t_s)]
    feats, weights, groups = chain_type_features(chain, cand, cfg, [t_s[f] for f in marks])
    if len(groups) == 0:
        return ()
    proba = model.type_probabilities(feats, weights, groups)
    seen = np.zeros(len(marks), dtype=bool)
    seen[groups] = True
    out = []
    for g in np.flatnonzero(seen):
        p = proba[g]
        out.append(
            ClassEstimate(
                int(stamps[marks[g]]),
                model.class_ids[int(np.argmax(p))],
                tuple(model.class_ids),
                tuple(float(v) for v in p),
            )
        )
    return tuple(out)


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
