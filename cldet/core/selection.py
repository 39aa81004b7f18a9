"""Which candidate track is the drone: whole-sequence evidence, then a chain through gaps.

Each candidate track (``cldet.core.tracking``) is scored over the whole sequence; one frame's
largest cluster never decides. The score is a sum over the track's detections (persistence),
each detection weighted by per-detection evidence and the track's factors:

* size: a detection whose cluster box is larger than ``max_size_m`` (1.2 m; the largest
  drones are ~0.8 m) weighs 0.1 (a person, a car, a branch);
* height: a detection weighs 1 when its lowest point is at least ``min_height_m`` (2 m) above
  the local ground (``cldet.core.ground``: a fitted plane and height map, so a tilted sensor,
  a slope or a rooftop change nothing), falling linearly to 0.1 at 1 m lower: whatever the
  LiDAR sees of a walking person lies below ~2 m, while the drone flies higher nearly all the
  time (but may come down to a person's height). The estimator sets the height to 0 for a
  cluster that may continue below what is seen: one cut by the bottom of the Mid-360's field of
  view, or whose continuation one cell below is hidden by the ground's background margin (a
  person far out shows only head and shoulders). Unknown height (no ground fitted) weighs 1;
* raw: a detection from the raw-point gate (no cluster) weighs ``raw_weight`` (0.5);
* cross-section: a LiDAR puts a fixed number of points per steradian on a surface per scan, so
  points / density * range^2 is the area that returned them; below ``min_cross_section_m2``
  (0.02 m^2, a small drone edge-on) a detection weighs that fraction, down to 0.1: a lone
  return 3 m away comes from a rain drop, dust or a leaf (a drone there returns a dozen);
* speed: factor 0.1 when the track's 90th-percentile filtered speed exceeds ``max_speed``
  (30 m/s: DJI drones cruise at 15-23 m/s, so speed alone never makes a drone a bird);
* static: factor ``static_factor`` (0.6) when 90 % of its detections lie within ``static_spread_m`` (0.5 m) of
  their median (sparse returns from different parts of one object scatter its centroid), or
  when they scatter less than 2 m but a least-squares constant-velocity fit moves them less
  than ``static_spread_m`` over the track's span (a swaying or flickering clump far away):
  static clutter, or a drone hovering the whole time (kept when nothing else is there, but a
  real mover wins). This holds at every elevation: nothing assumes an open sky;
* fixed: factor ``fixed_factor`` (0.01) instead when, over at least 2 s, the running mean of
  5 detections (about half a second) stays within ``fixed_spread_m`` (2.5 cm, 90 %) of its
  median: a multirotor holding position still wanders by centimetres to decimetres (its
  position controller, the wind), so a mean position fixed to a few centimetres is rigid
  structure (a sign, a lamp head) that the background keeps as foreground because it floats.
  The mean averages the sampling noise away only for objects with many points: a sparse or far
  object never looks fixed. A larger rigid object's centroid also jitters with which of its
  parts each scan hits (``sampling_jitter``: its largest edge / sqrt(12 points), 4 cm for a
  balcony corner 0.7 m across with 20 returns): the spread allowed grows to
  ``fixed_sampling_factor`` (1) times that. At 1 the rule catches about three in four rigid
  objects (its 90th percentile sits near the theory's); on the development worlds every drone
  track of 2 s or more wandered at least 1.27 times its jitter, and 1.5 broke three hovers.
  The factor is far below the static one because this is near certainty, not a likelihood: at 0.1 such a track of 80 detections still outweighed a drone
  hovering low beside a bush (0.1 for its height times 0.6 for static per detection).
  A track's fixed head or tail is cut off first (``split_rigid``) where another track shows a
  fixed object at the same place: two tracks that swapped a drone and a sign it passed;
* motion consistency: a detection whose NIS exceeds 7.81 (the 95 % point of chi^2, 3 dof)
  weighs exp(-(NIS - 7.81) / 7.81): smooth motion keeps its weight, erratic speckle or a
  bird's jinks lose it;
* crowding: a detection with k other clusters of its frame within ``crowd_radius_m`` (3 m,
  as far as the tracker's default hard gate), each with a point count within a factor of two
  of its own, weighs 1 / (1 + k): among
  rain, speckle or flickering foliage any track finds some return to continue on by chance,
  so such a detection says little about one object persisting (a drone alone in the sky keeps
  its full weight; single rain returns do not crowd a drone's dense cluster, nor does a wall's
  or a person's far larger one);
* sensors: factor 1 + 0.5 f, f = fraction of detections seen by both LiDARs in one cluster.

A track's first detection does not count (anything can start a track: persistence is what
the following detections show); tracks of a single detection are not candidates. The drone's record is often several tracks
(long unseen stretches, a detection stolen by clutter). A chain is the sequence of tracks
maximising the summed scores, where track A links to a later-starting track B if the jump
from A's last detection before B starts to B's first is at most ``link_speed * gap + 1 m``
within ``link_max_gap_s``, the jump taken from where A was there or from where A's motion
then (``link_velocity_s``) carries it, whichever is nearer (``link_jump``: a pass at 20 m/s is
no slower across a gap than while it is seen); A then counts only up to B's start, and
each link costs 2 detections' worth. A track that followed the drone out of sight may coast on
onto single returns that its gate happens to catch, leading away until the drone reappears
farther from the tail's end than any speed allows: the link may then leave A at its latest
detection from which the jump is possible, dropping the rest, but only when the dropped tail
is weak (its returns per detection average at most ``link_tail_ratio`` of the kept part's). A
steady track of something else keeps its returns to the end and cannot be cut to feed a drone
track. This is a dynamic programme over tracks sorted by start. The chain's first track may in
turn have begun on something else: a track started on lone returns (rain near the sensor,
speckle) that its gate then led onto the drone. Its detections before the first whose
cross-section (``cross_section``: returns scaled by range^2, so a far drone's few returns count
as much as a near one's many) reaches ``chain_head_ratio`` of the median over the track are
dropped: the chain begins where the object it follows is first seen whole.

The chosen chain is then carried on at both ends (``extend_chain``) by tracks too weak to be
worth a link that touch it: a detection at most ``extend_gap_s`` (0.5 s) before its first or
after its last, within the link's reach, bringing at least ``extend_min_evidence`` (half a
full-weight detection). The evidence has said which object is the drone; a drone that hovered
before flying off was judged static, and its track, worth less than a link, is still where that
object was: better than extrapolating the chain's motion back through it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from cldet.config import TrackingConfig
from cldet.core.features import TrackDetections, track_detections, track_features
from cldet.core.stats import column_medians, median, percentile
from cldet.core.tracking import (
    MIN_TRACK_HITS,
    ClusterTable,
    TrackRecord,
    constant_velocity_fit,
    windowed_velocity,
)

__all__ = [
    "ScoredTrack",
    "TrackScorer",
    "TrackWeigher",
    "detection_weights",
    "extend_chain",
    "fixed_spread",
    "link_jump",
    "link_reach",
    "rigid_now",
    "sampling_jitter",
    "score_tracks",
    "select_chain",
    "split_rigid",
]

LEARNED_FLOOR = 0.3
"""A learned scorer re-weighs a track's hand-set factors by ``LEARNED_FLOOR + (1 -
LEARNED_FLOOR) p``: at most ~3x, never to nothing. Its probability is calibrated on the logs it
was trained on; on another site's it is over-confident, and letting it veto tracks outright
(floor 0) raised the failure rate on 60 randomised development worlds (29 against 24 of 60, a
model trained on 24 sequences of the default simulator) where 0.3 did not (24 of 60, lower MSE)."""
_LINK_COST = 2.0
_NIS95 = 7.81  # 95 % point of chi^2 with 3 degrees of freedom
_JITTER_M = 2.0  # a track scattered less than this that goes nowhere is static clutter
FIXED_JUDGE_S = 2.0  # a track must be seen this long before it is judged rigidly fixed
FIXED_MEAN_HITS = 5  # "fixed" looks at the running mean of this many detections


@dataclass(frozen=True)
class ScoredTrack:
    """A candidate track with its per-detection contributions to the score."""

    record: TrackRecord
    times_s: NDArray[np.float64]  # (H,) detection times, s
    positions: NDArray[np.float64]  # (H,3) cluster centroids, metres
    # (H,3) its motion at each detection, m/s (``windowed_velocity`` over ``link_velocity_s``)
    velocity: NDArray[np.float64]
    contribution: NDArray[np.float64]  # (H,) each detection's weight in the score
    score: float
    cross: NDArray[np.float64] | None = None  # (H,) cross-section, m^2 (``cross_section``)


def _net_motion(t: NDArray[np.float64], pos: NDArray[np.float64]) -> float:
    """How far a least-squares constant-velocity fit moves over the track's time span, metres."""
    _, velocity, _ = constant_velocity_fit(t, pos)
    return float(np.linalg.norm(velocity)) * float(t[-1] - t[0])


def sampling_jitter(
    extent: NDArray[np.float64], n_points: NDArray[np.int64]
) -> NDArray[np.float64]:
    """How much sampling alone moves a rigid object's centroid from scan to scan, metres, per
    detection: its largest edge / sqrt(12 n), the standard deviation of the mean of n points
    spread uniformly along that edge (each scan hits other parts of the object). For the running
    mean of ``FIXED_MEAN_HITS`` detections, the 90th percentile of its 3-D distance to the median
    (about 2.2-2.5 / sqrt(5) per-axis deviations) is about this figure."""
    return np.asarray(extent / np.sqrt(12.0 * np.maximum(n_points, 1)), dtype=np.float64)


def fixed_spread(cfg: TrackingConfig, jitter_m: float) -> float:
    """How still a rigidly fixed track's running mean stays: ``fixed_spread_m``, or
    ``fixed_sampling_factor`` times the detections' sampling jitter where that is more (0: off)."""
    if cfg.fixed_spread_m <= 0:
        return 0.0
    return max(cfg.fixed_spread_m, cfg.fixed_sampling_factor * jitter_m)


def _is_fixed(t: NDArray[np.float64], pos: NDArray[np.float64], spread_m: float) -> bool:
    """Whether the running mean of ``FIXED_MEAN_HITS`` detections stays (90 %) within
    ``spread_m`` of its median over at least ``FIXED_JUDGE_S``: rigid structure, not a drone."""
    if spread_m <= 0 or len(t) < 2 * FIXED_MEAN_HITS or t[-1] - t[0] < FIXED_JUDGE_S:
        return False
    c = np.cumsum(np.vstack([np.zeros((1, 3)), pos]), axis=0)
    mean = (c[FIXED_MEAN_HITS:] - c[:-FIXED_MEAN_HITS]) / FIXED_MEAN_HITS
    dist = np.linalg.norm(mean - column_medians(mean), axis=1)
    return percentile(dist, 90) < spread_m


def detection_weights(
    extent: NDArray[np.float64],
    height: NDArray[np.float64],
    raw: NDArray[np.bool_],
    nis: NDArray[np.float64],
    cross: NDArray[np.float64],
    cfg: TrackingConfig,
    crowd: NDArray[np.int64] | None = None,
) -> NDArray[np.float64]:
    """Per-detection evidence: size, height above the local ground, raw gate, motion
    consistency, cross-section.

    Args: (H,) cluster box extent (m), lowest point's height above the local ground (m, NaN
    unknown), from the raw gate, normalised innovation squared (NaN at a track's birth), the
    cross-section that returned the points (m^2, ``cross_section``).
    """
    # (np.minimum / np.maximum rather than np.clip, np.where rather than np.nan_to_num: the
    # same values at a fraction of the call overhead, on the few detections of a frame)
    per_det = np.where(extent <= cfg.max_size_m, 1.0, 0.1)
    # a lone return near the sensor comes from something far smaller than any drone (a rain
    # drop, a leaf, dust): a drone at 3 m returns a dozen points
    per_det *= np.minimum(np.maximum(cross / cfg.min_cross_section_m2, 0.1), 1.0)
    lo_h, hi_h = cfg.min_height_m - 1.0, cfg.min_height_m
    finite = np.isfinite(height)
    height_w = np.minimum(
        np.maximum((np.where(finite, height, 0.0) - lo_h) / (hi_h - lo_h), 0.1), 1.0
    )
    per_det *= np.where(finite, height_w, 1.0)
    per_det *= np.where(raw, cfg.raw_weight, 1.0)
    # motion consistency: a detection far outside the constant-velocity prediction
    # (NIS above the 95 % point of chi^2 with 3 dof) is down-weighted smoothly
    nis0 = np.where(np.isnan(nis), 0.0, nis)
    per_det = per_det * np.exp(-np.maximum(nis0 - _NIS95, 0.0) / _NIS95)
    if crowd is not None:
        # k other clusters within reach: any track continues on one of them by chance
        per_det = per_det / (1.0 + crowd)
    return per_det


TrackScorer = Callable[[NDArray[np.float64]], NDArray[np.float64]]
"""A learned scorer: track features (T, len(FEATURE_NAMES)) -> probability of the drone (T,)."""


@dataclass(frozen=True)
class TrackWeigher:
    """Learned re-weighings of the hand-set track factors.

    Each ``(scorer, floor)`` weighs a track by ``floor + (1 - floor) p``, ``p`` its
    probability that the track is the drone: within bounds, never to nothing. Several multiply
    (the packaged prior and a user's model: what each learned counts).
    """

    scorers: tuple[tuple[TrackScorer, float], ...]

    @property
    def floor(self) -> float:
        """The least factor it can give a track."""
        return float(np.prod([floor for _, floor in self.scorers]))

    def __call__(self, features: NDArray[np.float64]) -> NDArray[np.float64]:
        """(T,) factors of the tracks with features (T, len(FEATURE_NAMES))."""
        factors = np.ones(len(features))
        for scorer, floor in self.scorers:
            factors *= floor + (1.0 - floor) * np.asarray(scorer(features), dtype=np.float64)
        return factors


def score_tracks(
    records: list[TrackRecord],
    tables: list[ClusterTable],
    times_s: NDArray[np.float64],
    cfg: TrackingConfig,
    weigher: TrackWeigher | None = None,
) -> list[ScoredTrack]:
    """Score every candidate track of two detections or more (see the module docstring).

    With a ``weigher`` the hand-set track factors (speed, static, fixed, sensors) are
    re-weighed by what was learned: the physics stays the prior, what was learned from
    labelled logs (or simulated worlds: ``cldet.core.prior``) re-weighs it within bounds.
    """
    kept: list[tuple[TrackRecord, TrackDetections, NDArray[np.float64]]] = []
    for rec in records:
        if len(rec.frames) < MIN_TRACK_HITS:
            continue
        det = track_detections(rec, tables, cfg)
        per_det = detection_weights(
            det.extent, det.height, rec.raw, rec.nis, det.cross, cfg, det.crowd
        )
        kept.append((rec, det, per_det))
    factors = np.array([_hand_factor(r, d, times_s, cfg) for r, d, _ in kept])
    if weigher is not None and kept:
        feats = np.array([track_features(r, d, times_s[r.frames]) for r, d, _ in kept])
        factors = factors * weigher(feats)
    out = []
    for (rec, det, per_det), factor in zip(kept, factors, strict=True):
        contribution = per_det * float(factor)
        contribution[0] = 0.0  # a track's first detection is no evidence of persistence
        out.append(
            ScoredTrack(
                record=rec,
                times_s=times_s[rec.frames],
                positions=rec.positions,
                velocity=windowed_velocity(times_s[rec.frames], rec.positions, cfg.link_velocity_s),
                contribution=contribution,
                score=float(contribution.sum()),
                cross=det.cross,
            )
        )
    return out


def _hand_factor(
    rec: TrackRecord, det: TrackDetections, times_s: NDArray[np.float64], cfg: TrackingConfig
) -> float:
    """The hand-set track factors: speed, fixed or static, sensors (see the module docstring)."""
    h = len(rec.frames)
    pos = rec.positions
    factor = 1.0
    speeds = rec.speed[2:] if h > 3 else rec.speed[1:]
    if len(speeds) and percentile(speeds, 90) > cfg.max_speed:
        factor *= 0.1
    centre = column_medians(pos)
    spread = percentile(np.linalg.norm(pos - centre, axis=1), 90)
    jitter = median(sampling_jitter(det.extent, rec.n_points))
    if _is_fixed(times_s[rec.frames], pos, fixed_spread(cfg, jitter)):
        factor *= cfg.fixed_factor
    elif spread < cfg.static_spread_m or (
        spread < _JITTER_M and _net_motion(times_s[rec.frames], pos) < cfg.static_spread_m
    ):
        factor *= cfg.static_factor
    return factor * (1.0 + 0.5 * float(np.mean(det.both)))


def rigid_now(
    t: NDArray[np.float64],
    pos: NDArray[np.float64],
    jitter_m: float,
    cfg: TrackingConfig,
    head_s: float,
) -> bool:
    """Whether a track's detections ``pos`` (H,3) at times ``t`` (H,) after its first
    ``head_s`` are rigidly fixed as the refinement judges (``_is_fixed`` over at least
    ``FIXED_JUDGE_S``, the spread grown to the sampling jitter ``jitter_m``): a track's first
    detections are its least sure (its gate is widest at birth: it may have begun on clutter
    beside the object), and what is rigid from then on is structure. All the rest is judged,
    not a recent window: a hovering drone wanders by decimetres over seconds, yet can keep
    still to centimetres for one or two."""
    after = t >= t[0] + head_s
    return _is_fixed(t[after], pos[after], fixed_spread(cfg, jitter_m))


def _detection_tolerance(cfg: TrackingConfig, jitter: NDArray[np.float64]) -> float:
    """How far one detection of a rigidly fixed object may lie from its median: twice a single
    detection's spread, ``sqrt(FIXED_MEAN_HITS)`` times that of the running mean
    (``fixed_spread``, with the detections' sampling ``jitter``)."""
    return 2.0 * float(np.sqrt(FIXED_MEAN_HITS)) * fixed_spread(cfg, median(jitter))


def _fixed_end(
    t: NDArray[np.float64],
    pos: NDArray[np.float64],
    jitter: NDArray[np.float64],
    cfg: TrackingConfig,
) -> int:
    """Where the rigidly fixed run ending a track's detections (times ``t`` (H,), positions
    ``pos`` (H,3), sampling jitter ``jitter`` (H,)) begins: the first index of the longest
    suffix that ``_is_fixed`` judges fixed (``len(t)``: none)."""
    h = len(t)
    k = int(np.searchsorted(t, t[-1] - FIXED_JUDGE_S, side="right")) - 1
    k = min(k, h - 2 * FIXED_MEAN_HITS)
    if k < 1:
        return h

    def fixed(i: int) -> bool:
        return _is_fixed(t[i:], pos[i:], fixed_spread(cfg, median(jitter[i:])))

    if not fixed(k):
        return h
    while k > 0 and fixed(k - 1):
        k -= 1
    # the rule allows a tenth of the running means astray, so the run may have taken in the
    # last detections before it: it begins at the first detection on the fixed object
    centre = column_medians(pos[k:])
    tol = _detection_tolerance(cfg, jitter[k:])
    while k < h - 1 and np.linalg.norm(pos[k] - centre) > tol:
        k += 1
    return k


def split_rigid(
    records: list[TrackRecord],
    tables: list[ClusterTable],
    times_s: NDArray[np.float64],
    cfg: TrackingConfig,
) -> list[TrackRecord]:
    """The records with a rigidly fixed head or tail cut off as a record of its own where that
    part sits on a rigidly fixed object that another track shows (``tracking.split_rigid``).

    A track's gate that followed the drone past a sign (or that was born on a sign and then
    pulled away by the drone passing it) holds two objects, and as a whole it is neither fixed
    nor all the drone. Where its first or last detections, over ``FIXED_JUDGE_S`` or more, are
    fixed as ``_is_fixed`` judges a whole track, and a fixed run of another track (the whole of
    it, or its head or tail judged so) has its median position within a single detection's
    spread of theirs, the object there is structure seen on its own: that part is cut off and
    scored alone (fixed), and the rest links as a track of its own. A drone that flies in and hovers still, or hovers and then
    leaves, sits where no fixed track was, and is not cut. The new records take ids above
    every id in ``records``; the rest are returned as they were."""
    if not cfg.split_rigid or cfg.fixed_spread_m <= 0:
        return records
    # per track, its fixed runs: (where it begins, where it ends, median position, tolerance)
    runs: dict[int, list[tuple[int, int, NDArray[np.float64], float]]] = {}
    for rec in records:
        t = times_s[rec.frames]
        h = len(t)
        if h < 2 * FIXED_MEAN_HITS or t[-1] - t[0] < FIXED_JUDGE_S:
            continue
        extent = np.array(
            [
                0.0 if c < 0 else tables[f].extent[c]
                for f, c in zip(rec.frames, rec.clusters, strict=True)
            ]
        )
        jitter = sampling_jitter(extent, rec.n_points)
        tail = _fixed_end(t, rec.positions, jitter, cfg)
        if tail == 0:  # fixed as a whole
            ends = [(0, h)]
        else:
            head = h - _fixed_end(-t[::-1], rec.positions[::-1], jitter[::-1], cfg)
            ends = [(a, b) for a, b in ((0, head), (tail, h)) if b > a]
        for a, b in ends:
            tol = _detection_tolerance(cfg, jitter[a:b])
            runs.setdefault(rec.track_id, []).append(
                (a, b, column_medians(rec.positions[a:b]), tol)
            )

    def elsewhere(track_id: int, centre: NDArray[np.float64], tol: float) -> bool:
        return any(
            np.linalg.norm(at - centre) <= max(tol, other)
            for tid, own in runs.items()
            if tid != track_id
            for _, _, at, other in own
        )

    cuts: dict[int, list[int]] = {}
    for rec in records:
        h = len(rec.frames)
        own = [
            (a, b)
            for a, b, at, tol in runs.get(rec.track_id, ())
            if elsewhere(rec.track_id, at, tol)
        ]
        bounds = sorted({0, h} | {a for a, _ in own} | {b for _, b in own})
        if len(bounds) > 2 and all(b - a < h for a, b in own):
            cuts[rec.track_id] = bounds
    next_id = max((r.track_id for r in records), default=-1) + 1
    out: list[TrackRecord] = []
    for rec in records:
        at_cuts = cuts.get(rec.track_id)
        if at_cuts is None:
            out.append(rec)
            continue
        for k, (a, b) in enumerate(zip(at_cuts[:-1], at_cuts[1:], strict=True)):
            part = rec.part(a, b)
            nis = part.nis.copy()
            nis[0] = np.nan  # each part is born again
            out.append(replace(part, track_id=rec.track_id if k == 0 else next_id, nis=nis))
            next_id += k > 0
    return out


def link_reach(
    gap_s: NDArray[np.float64] | float, cfg: TrackingConfig
) -> NDArray[np.float64] | float:
    """How far a track may start from where another's detection ``gap_s`` earlier puts it
    (``link_jump``) and still link to it: ``link_speed`` times the gap, plus 1 m."""
    return cfg.link_speed * gap_s + 1.0


def link_jump(
    times_s: NDArray[np.float64],
    positions: NDArray[np.float64],
    velocity: NDArray[np.float64],
    t0: float,
    p0: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Per detection of a track (``times_s``, ``positions``, its ``velocity`` there), how far a
    track starting at ``t0`` at ``p0`` lies from it: from where it was, or from where its motion
    carries it by ``t0``, whichever is nearer. A drone that stopped or turned back is near the
    first; one that flew on unseen (a pass at 20 m/s is no slower across a gap than while it is
    seen), near the second; one moving the other way at speed, near neither."""
    dt = (t0 - times_s)[:, None]
    rest = np.linalg.norm(positions - p0, axis=1)
    carried = np.linalg.norm(positions + velocity * dt - p0, axis=1)
    return np.asarray(np.minimum(rest, carried), dtype=np.float64)


def _link_cut(ta: ScoredTrack, t0: float, p0: NDArray[np.float64], cfg: TrackingConfig) -> int:
    """How many of track ``ta``'s first hits a link to a track starting at time ``t0`` and
    position ``p0`` keeps (0: no link; see the module docstring): all its hits before ``t0``
    when the jump from the last of them is possible, else, when ``link_tail_ratio`` allows,
    up to the latest hit from which it is, if the hits dropped are a weak tail."""
    hi = int(np.searchsorted(ta.times_s, t0, side="left"))  # hits strictly before t0
    lo = int(np.searchsorted(ta.times_s, t0 - cfg.link_max_gap_s, side="left"))
    if hi <= lo:
        return 0
    if cfg.link_tail_ratio <= 0:
        lo = hi - 1
    gap = t0 - ta.times_s[lo:hi]
    jump = link_jump(ta.times_s[lo:hi], ta.positions[lo:hi], ta.velocity[lo:hi], t0, p0)
    ok = np.flatnonzero(jump <= link_reach(gap, cfg))
    if not len(ok):
        return 0
    cut = lo + int(ok[-1]) + 1
    n = ta.record.n_points
    if cut < hi and np.mean(n[cut:hi]) > cfg.link_tail_ratio * np.mean(n[:cut]):
        return 0
    return cut


def select_chain(
    tracks: list[ScoredTrack], cfg: TrackingConfig
) -> list[tuple[ScoredTrack, int, int]]:
    """The best chain of tracks: a list of (track, first hit index, end hit index exclusive).

    Empty when there is no candidate track.
    """
    if not tracks:
        return []
    # a track worth less than a link can only win alone: keep the best one of those
    strong = [t for t in tracks if t.score >= _LINK_COST]
    if not strong:
        strong = [max(tracks, key=lambda t: (t.score, -t.record.track_id))]
    tracks = strong
    order = sorted(
        range(len(tracks)), key=lambda i: (tracks[i].times_s[0], tracks[i].record.track_id)
    )
    trs = [tracks[i] for i in order]
    starts = np.array([t.times_s[0] for t in trs])
    ends = np.array([t.times_s[-1] for t in trs])
    cum = [np.concatenate([[0.0], np.cumsum(t.contribution)]) for t in trs]
    best_in = np.zeros(len(trs))
    parent = np.full(len(trs), -1)
    parent_cut = np.zeros(len(trs), dtype=np.int64)  # hits of the parent kept
    for b, tb in enumerate(trs):
        t0, p0 = starts[b], tb.positions[0]
        for a in range(b):
            if starts[a] >= t0 or ends[a] < t0 - cfg.link_max_gap_s:
                continue
            cut = _link_cut(trs[a], t0, p0, cfg)
            if cut == 0:
                continue
            value = best_in[a] + cum[a][cut] - _LINK_COST
            if value > best_in[b]:
                best_in[b] = value
                parent[b] = a
                parent_cut[b] = cut
    total = best_in + np.array([c[-1] for c in cum])
    b = int(np.argmax(total))
    chain: list[tuple[ScoredTrack, int, int]] = []
    end = len(trs[b].times_s)
    while b >= 0:
        chain.append((trs[b], 0, end))
        end = int(parent_cut[b])
        b = int(parent[b])
    chain.reverse()
    first, _, end = chain[0]
    chain[0] = (first, _weak_head(first, end, cfg), end)
    return chain


def _weak_head(tr: ScoredTrack, end: int, cfg: TrackingConfig) -> int:
    """How many of the chain's first track's first hits to drop (see the module docstring):
    those before its first detection whose cross-section reaches ``chain_head_ratio`` of the
    median of its hits up to ``end`` (0: none; at least ``MIN_TRACK_HITS`` are kept)."""
    if cfg.chain_head_ratio <= 0 or tr.cross is None:
        return 0
    cross = tr.cross[:end]
    h = int(np.argmax(cross >= cfg.chain_head_ratio * np.median(cross)))
    return h if end - h >= MIN_TRACK_HITS else 0


def extend_chain(
    chain: list[tuple[ScoredTrack, int, int]], tracks: list[ScoredTrack], cfg: TrackingConfig
) -> list[tuple[ScoredTrack, int, int]]:
    """The chain carried on at both ends by tracks that touch it (``extend_gap_s``).

    The chain is chosen by evidence; a track too weak to be worth a link (a drone hovering at
    the start is judged static, its detections weigh little) may still be where the chosen
    object was before the chain begins or after it ends. Before the chain's first detection:
    the track, other than the chain's, whose detections before it end at most ``extend_gap_s``
    earlier within ``link_reach`` of it, its hits up to then prepended; after the last: the
    track whose first detection after it comes at most ``extend_gap_s`` later within reach of
    the chain's last detection, its hits from then appended. Both are the refinement's link
    (``_link_cut`` with ``link_max_gap_s`` set to ``extend_gap_s``). Among several, the one with
    the most evidence in the part taken, some and at least ``extend_min_evidence``
    (near-weightless returns that clutter makes by chance next to anything do not count);
    repeated while one is found."""
    if not chain or cfg.extend_gap_s <= 0:
        return chain
    near = cfg.model_copy(update={"link_max_gap_s": cfg.extend_gap_s})
    floor = max(cfg.extend_min_evidence, 1e-9)
    out = list(chain)
    used = {id(tr) for tr, _, _ in out}
    while True:  # before the first detection
        tr0, i0, _ = out[0]
        t0, p0 = float(tr0.times_s[i0]), tr0.positions[i0]
        best: tuple[float, ScoredTrack, int] | None = None
        for tr in tracks:
            if id(tr) in used or tr.times_s[0] >= t0:
                continue
            cut = _link_cut(tr, t0, p0, near)
            value = float(np.sum(tr.contribution[:cut]))
            if cut >= MIN_TRACK_HITS and value >= floor and (best is None or value > best[0]):
                best = (value, tr, cut)
        if best is None:
            break
        out.insert(0, (best[1], 0, best[2]))
        used.add(id(best[1]))
    while True:  # after the last detection
        tr1, _, i1 = out[-1]  # the chain's last track, to its end
        t1 = float(tr1.times_s[i1 - 1])
        best = None
        for tr in tracks:
            if id(tr) in used or tr.times_s[-1] <= t1:
                continue
            j = int(np.searchsorted(tr.times_s, t1, side="right"))
            if len(tr.times_s) - j < MIN_TRACK_HITS:
                continue
            # linked from the chain's last detection itself (no tail of it dropped)
            if _link_cut(tr1, float(tr.times_s[j]), tr.positions[j], near) != i1:
                continue
            value = float(np.sum(tr.contribution[j:]))
            if value >= floor and (best is None or value > best[0]):
                best = (value, tr, j)
        if best is None:
            break
        out.append((best[1], best[2], len(best[1].times_s)))
        used.add(id(best[1]))
    return out
