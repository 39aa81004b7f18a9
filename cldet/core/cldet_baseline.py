"""The CL-Det method (NTU-ICG, 5th place, UG2+ 2024) as its report describes it, for comparison.

Per Mid-360 frame:

1. remove the environment points;
2. DBSCAN (scikit-learn) with eps 2 m and min_samples 1 over the remaining Mid-360 points;
3. the estimate is the mean of the largest cluster;
4. when no Mid-360 point remains: the mean of the paired (nearest) Avia frame's points (zero
   rows already dropped, nothing else removed);
5. else the mean of all earlier estimates of the sequence;
6. else the training-set mean position (``tracking.fallback_position``, (0.734, -9.739, 33.353)).

What differs from the report, and why: the report drew the environment zones by hand from a
ground-truth heatmap of the training set. Here the environment is learned from the sequence
itself with the same online static background model as ``track`` (``cldet.core.background``,
fed with both LiDARs; nothing is foreground during its warm-up): a point is environment when
it is CORE or MARGIN background. Nothing
else from ``track`` is used (no range filter, no tracking, no smoothing, no bias correction):
only non-finite and exactly-zero rows are dropped. The report's time alignment of the two
LiDARs is the frame pairing done before the estimator.

``baseline.environment: none`` skips step 1: DBSCAN then clusters every valid Mid-360 point,
as the report's own speed (14.9 predictions/s) suggests it nearly did. This is for comparing
costs; the largest cluster is then the ground or a building, so its estimates are poor.

``sigma_m`` (the report has no uncertainty): the RMS distance of the cluster's points from
their mean for steps 3-4, and 10 m for the history and training-mean fallbacks.
"""

from __future__ import annotations

import numpy as np
from sklearn.cluster import DBSCAN

from cldet.config import CldetConfig
from cldet.core.background import FOREGROUND, BackgroundModel
from cldet.core.clustering import summarize_clusters
from cldet.core.estimator import (
    FrameDetections,
    SequenceEstimate,
    TrackEvent,
    check_order,
    fuse_points,
)
from cldet.core.frames import valid_points
from cldet.types import Estimate, LidarFrame, Source

__all__ = ["CLDET_EPS_M", "CLDET_MIN_SAMPLES", "ClDetEstimator"]

CLDET_EPS_M = 2.0
CLDET_MIN_SAMPLES = 1
_FALLBACK_SIGMA_M = 10.0


class ClDetEstimator:
    """The ``cl-det`` method (see the module docstring)."""

    name = "cl-det"

    def __init__(self, config: CldetConfig) -> None:
        # the learned environment uses the same point filter as ``track``
        self.config = config
        self.background = BackgroundModel(config.background)
        self._learned = config.baseline.environment == "learned"
        self._estimates: list[Estimate] = []
        self._chosen: dict[int, int] = {}
        self._events: list[TrackEvent] = []
        self._sum = np.zeros(3)
        self._mode = ""

    def _emit(
        self, stamp_ns: int, pos: np.ndarray, source: Source, n: int, sigma: float, mode: str
    ) -> None:
        self._estimates.append(Estimate(stamp_ns, pos, source, n, sigma))
        self._sum += pos
        if mode != self._mode:
            self._events.append(TrackEvent(stamp_ns, mode, f"cl-det estimate from {mode}"))
            self._mode = mode

    def register_frame(self, frame: LidarFrame) -> FrameDetections:
        """Environment removal, DBSCAN, largest cluster's mean (or the fallbacks)."""
        check_order(self._estimates[-1].stamp_ns if self._estimates else None, frame.stamp_ns)
        mid = valid_points(frame.mid360)
        if self._learned:
            self.background.advance(frame.stamp_ns)
            fg = mid[self.background.classify(mid) == FOREGROUND]
            pts, _ = fuse_points(frame, self.config)
            self.background.update(frame.stamp_ns, pts)
        else:
            fg = mid
        labels = np.full(len(fg), -1, dtype=np.int32)
        clusters: tuple = ()
        if len(fg):
            raw = DBSCAN(eps=CLDET_EPS_M, min_samples=CLDET_MIN_SAMPLES).fit_predict(fg)
            sizes = np.bincount(raw[raw >= 0])
            # rename: 0 = largest (ties: scikit-learn's order)
            rank = np.argsort(-sizes, kind="stable")
            new_id = np.empty_like(rank)
            new_id[rank] = np.arange(len(rank))
            labels = np.where(raw >= 0, new_id[np.maximum(raw, 0)], -1).astype(np.int32)
            clusters = summarize_clusters(fg, labels)
            pts = fg[labels == 0].astype(np.float64)
            mean = pts.mean(axis=0)
            spread = float(np.sqrt(np.mean(np.sum((pts - mean) ** 2, axis=1))))
            self._chosen[frame.stamp_ns] = 0
            self._emit(frame.stamp_ns, mean, Source.DETECTED, len(pts), spread, "largest cluster")
        else:
            avia = valid_points(frame.avia).astype(np.float64)
            if len(avia):
                mean = avia.mean(axis=0)
                spread = float(np.sqrt(np.mean(np.sum((avia - mean) ** 2, axis=1))))
                self._emit(frame.stamp_ns, mean, Source.DETECTED, len(avia), spread, "Avia mean")
            elif self._estimates:
                mean = self._sum / len(self._estimates)
                self._emit(
                    frame.stamp_ns, mean, Source.FALLBACK, 0, _FALLBACK_SIGMA_M, "history mean"
                )
            else:
                mean = np.asarray(self.config.tracking.fallback_position, dtype=np.float64)
                self._emit(
                    frame.stamp_ns, mean, Source.FALLBACK, 0, _FALLBACK_SIGMA_M, "training mean"
                )
        return FrameDetections(frame.stamp_ns, fg, labels, clusters, self._estimates[-1])

    def refine(self) -> SequenceEstimate:
        """The per-frame estimates as they were made (cl-det is causal: nothing is refined)."""
        estimates = tuple(self._estimates)
        return SequenceEstimate(estimates, dict(self._chosen), tuple(self._events), estimates)
