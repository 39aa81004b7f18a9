"""Helpers of the exploratory notebooks (``notebooks/``): statistics, clustering studies, errors.

The notebooks reproduce the CL-Det report's exploratory work (ground-truth heatmaps and
histograms, frames with and without environment points, K-Means with the elbow method, a
DBSCAN parameter sweep) and compare ``track`` with ``cl-det``. Whatever grew beyond a few lines
there lives here, tested. Plotting stays in the notebooks: this module needs numpy, scipy and
scikit-learn only, and reads data through ``converters.mmaud`` and the estimator core.

Times are integer nanoseconds (``*_ns``), lengths metres (``*_m``), angles degrees (``*_deg``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment
from sklearn.cluster import KMeans

from cldet.config import CldetConfig
from cldet.core.background import FOREGROUND, BackgroundModel
from cldet.core.clustering import cluster_points, summarize_clusters
from cldet.core.estimator import fuse_points
from cldet.core.frames import pair_frames, valid_points
from cldet.core.trajectory import evaluate_trajectory, rms, trajectory_errors
from cldet.results import normalise_sequence, read_truth
from cldet.stamps import NS_PER_S
from cldet.types import Estimate, LidarFrame, Source
from converters.mmaud import SequenceRef, iter_clouds, iter_ground_truth, iter_positions

__all__ = [
    "DbscanSweep",
    "ErrorSeries",
    "FrameStats",
    "KMeansStability",
    "Truth",
    "TruthHistograms",
    "dbscan_sweep",
    "elbow_k",
    "elevation_coverage",
    "elevation_deg",
    "error_by_source",
    "estimate_errors",
    "frame_statistics",
    "kmeans_elbow",
    "kmeans_stability",
    "learn_background",
    "load_truth",
    "sequence_frames",
    "source_runs",
    "split_environment",
    "truth_at",
    "truth_histograms",
]


# --------------------------------------------------------------------------- data access


def sequence_frames(
    seq: SequenceRef, max_gap_ns: int = 50_000_000
) -> Callable[[], Iterator[LidarFrame]]:
    """A re-iterable source of a challenge sequence's paired Mid-360/Avia frames.

    Each call of the returned function streams the sequence from disk again (the estimator
    reads a sequence twice), pairing every Mid-360 frame with its nearest Avia frame
    (:func:`cldet.core.frames.pair_frames`); a sequence without ``livox_avia`` gives frames with
    an empty Avia cloud.

    Args:
        seq: a sequence found by :func:`converters.mmaud.find_sequences`; needs ``lidar_360``.
        max_gap_ns: largest |Avia - Mid-360| stamp difference paired, ns.

    Returns:
        A function returning a fresh iterator of :class:`LidarFrame` in stamp order.
    """

    def frames() -> Iterator[LidarFrame]:
        avia = iter_clouds(seq, "livox_avia") if "livox_avia" in seq.modalities else iter(())
        return pair_frames(iter_clouds(seq, "lidar_360"), avia, max_gap_ns)

    return frames


@dataclass(frozen=True)
class Truth:
    """The drone's positions over a sequence, and what they are."""

    kind: str  # "ground truth" or "reference estimate" (another method's output, not truth)
    stamps_ns: NDArray[np.int64]  # (K,) ascending
    positions: NDArray[np.float64]  # (K, 3) metres, Mid-360 frame


def load_truth(seq: SequenceRef, root: Path | None = None) -> Truth | None:
    """The best positions known for a sequence: ground truth, else a reference estimate.

    Looked up in this order: the sequence's ``ground_truth/`` folder (train); the split's
    truth CSV ``ROOT/<split>_truth.csv`` (written by ``cldet simulate`` for val and test); a
    reference track ``ROOT/reference/<seq>/`` (the real sample ships the 1st-place team's
    estimate there: kind ``"reference estimate"``).

    Args:
        seq: the sequence.
        root: the dataset root (default: two levels above the sequence folder).

    Returns:
        A :class:`Truth`, or None when nothing is found (or the CSV has no row of the sequence).

    Raises:
        DatasetError, ResultsError: a truth file exists but is malformed.
    """
    root = Path(root) if root is not None else seq.path.parent.parent
    if "ground_truth" in seq.modalities:
        samples = list(iter_ground_truth(seq))
        if samples:
            return _truth(
                "ground truth", [s.stamp_ns for s in samples], [s.position for s in samples]
            )
    csv = root / f"{seq.split}_truth.csv"
    if csv.is_file():
        rows = [r for r in read_truth(csv).rows if normalise_sequence(r.sequence) == seq.name]
        if rows:
            return _truth("ground truth", [r.stamp_ns for r in rows], [r.position for r in rows])
    for name in (seq.name, seq.path.name):
        folder = root / "reference" / name
        if folder.is_dir():
            samples = list(iter_positions(folder))
            if samples:
                return _truth(
                    "reference estimate",
                    [s.stamp_ns for s in samples],
                    [s.position for s in samples],
                )
    return None


def _truth(kind: str, stamps: Sequence[int], positions: Sequence[ArrayLike]) -> Truth:
    s = np.asarray(stamps, dtype=np.int64)
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    order = np.argsort(s, kind="stable")
    return Truth(kind=kind, stamps_ns=s[order], positions=p[order])


def truth_at(truth: Truth, stamps_ns: ArrayLike) -> NDArray[np.float64]:
    """The truth's positions at the given stamps (linear inside, its own motion outside).

    Args:
        truth: the positions to evaluate.
        stamps_ns: (N,) integer ns.

    Returns:
        (N, 3) metres (:func:`cldet.core.trajectory.evaluate_trajectory`).
    """
    query = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    return evaluate_trajectory(truth.stamps_ns, truth.positions, query)


# --------------------------------------------------------------------------- what the sensors see


@dataclass(frozen=True)
class FrameStats:
    """Valid points per paired frame of a sequence."""

    stamps_ns: NDArray[np.int64]  # (N,) Mid-360 stamps
    mid360_points: NDArray[np.int64]  # (N,) valid Mid-360 points
    avia_points: NDArray[np.int64]  # (N,) valid points of the paired Avia frame (0: none paired)
    avia_paired: NDArray[np.bool_]  # (N,) an Avia frame was paired

    @property
    def avia_empty_fraction(self) -> float:
        """Fraction of frames whose Avia cloud is empty (unpaired or all-zero)."""
        return float(np.mean(self.avia_points == 0)) if len(self.avia_points) else 0.0


def frame_statistics(frames: Iterable[LidarFrame]) -> FrameStats:
    """Count the valid points of each frame's two LiDARs (finite and not (0,0,0)).

    Args:
        frames: paired frames in stamp order.

    Returns:
        A :class:`FrameStats`.
    """
    stamps: list[int] = []
    mid: list[int] = []
    avia: list[int] = []
    paired: list[bool] = []
    for frame in frames:
        stamps.append(frame.stamp_ns)
        mid.append(len(valid_points(frame.mid360)))
        avia.append(len(valid_points(frame.avia)))
        paired.append(frame.avia_stamp_ns is not None)
    return FrameStats(
        stamps_ns=np.asarray(stamps, dtype=np.int64),
        mid360_points=np.asarray(mid, dtype=np.int64),
        avia_points=np.asarray(avia, dtype=np.int64),
        avia_paired=np.asarray(paired, dtype=np.bool_),
    )


def elevation_deg(points: ArrayLike) -> NDArray[np.float64]:
    """Elevation of each point (N,3) seen from the Mid-360 origin, degrees (-90..90, z up)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return np.degrees(np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1])))


def elevation_coverage(
    frames: Iterable[LidarFrame], edges_deg: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mean valid points per frame in each elevation band, per sensor.

    Args:
        frames: paired frames.
        edges_deg: (B+1,) ascending elevation band edges, degrees.

    Returns:
        (Mid-360 points per frame per band (B,), Avia points per frame per band (B,)); zeros
        when there is no frame.
    """
    edges = np.asarray(edges_deg, dtype=np.float64)
    mid = np.zeros(len(edges) - 1)
    avia = np.zeros(len(edges) - 1)
    n = 0
    for frame in frames:
        mid += np.histogram(elevation_deg(valid_points(frame.mid360)), bins=edges)[0]
        avia += np.histogram(elevation_deg(valid_points(frame.avia)), bins=edges)[0]
        n += 1
    return (mid / n, avia / n) if n else (mid, avia)


@dataclass(frozen=True)
class TruthHistograms:
    """Per-axis histograms and the x-y heatmap of drone positions."""

    axis_edges: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]  # x, y, z
    axis_counts: tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]
    xy_counts: NDArray[np.int64]  # (len(x_edges)-1, len(y_edges)-1), x along axis 0
    x_edges: NDArray[np.float64]  # metres
    y_edges: NDArray[np.float64]  # metres
    mean: NDArray[np.float64]  # (3,) metres
    std: NDArray[np.float64]  # (3,) metres


def truth_histograms(
    positions: ArrayLike, axis_bin_m: float = 1.0, xy_cell_m: float = 1.0
) -> TruthHistograms:
    """Histograms of drone positions (N,3): each axis in bins of ``axis_bin_m``, x-y in cells.

    Bin edges are multiples of the bin size covering every position.

    Raises:
        ValueError: no position, a non-finite position or a non-positive bin size.
    """
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        raise ValueError("no position to histogram")
    if not np.all(np.isfinite(p)):
        raise ValueError("positions must be finite")
    if axis_bin_m <= 0 or xy_cell_m <= 0:
        raise ValueError(f"bin sizes must be > 0, got {axis_bin_m} and {xy_cell_m}")
    edges = tuple(_edges(p[:, a], axis_bin_m) for a in range(3))
    counts = tuple(np.histogram(p[:, a], bins=edges[a])[0].astype(np.int64) for a in range(3))
    x_edges, y_edges = _edges(p[:, 0], xy_cell_m), _edges(p[:, 1], xy_cell_m)
    xy = np.histogram2d(p[:, 0], p[:, 1], bins=(x_edges, y_edges))[0].astype(np.int64)
    return TruthHistograms(
        axis_edges=(edges[0], edges[1], edges[2]),
        axis_counts=(counts[0], counts[1], counts[2]),
        xy_counts=xy,
        x_edges=x_edges,
        y_edges=y_edges,
        mean=p.mean(axis=0),
        std=p.std(axis=0),
    )


def _edges(values: NDArray[np.float64], step: float) -> NDArray[np.float64]:
    lo = np.floor(values.min() / step)
    hi = np.floor(values.max() / step) + 1
    return np.arange(lo, hi + 0.5) * step


# --------------------------------------------------------------------------- environment points


def learn_background(
    frames: Iterable[LidarFrame], config: CldetConfig | None = None
) -> BackgroundModel:
    """Learn the static background (online, as the estimator does) from a sequence's frames.

    Both LiDARs' valid points within the configured range band are counted, as the estimator
    does (:func:`cldet.core.estimator.fuse_points`). The model then holds the static range of
    the last window of ``background.window_bins`` bins.

    Args:
        frames: every frame of the sequence, in stamp order.
        config: the estimator configuration (defaults when None).

    Returns:
        The model; :func:`split_environment` classifies a frame's points with it.
    """
    cfg = config or CldetConfig()
    model = BackgroundModel(cfg.background)
    last_ns = None
    for frame in frames:
        points, _ = fuse_points(frame, cfg)
        model.update(frame.stamp_ns, points)
        last_ns = frame.stamp_ns
    if last_ns is not None:  # finish the last bin so that it counts
        model.advance(last_ns + int(round(cfg.background.bin_s * 1e9)))
    return model


def split_environment(
    frame: LidarFrame, model: BackgroundModel, config: CldetConfig | None = None
) -> tuple[NDArray[np.float32], NDArray[np.bool_], int]:
    """A frame's fused points and which of them are foreground (not environment).

    Args:
        frame: one paired frame.
        model: the sequence's background (:func:`learn_background`).
        config: the estimator configuration (defaults when None).

    Returns:
        (points (N,3) metres, Mid-360 first; foreground mask (N,); number of Mid-360 points).
    """
    cfg = config or CldetConfig()
    points, n_mid = fuse_points(frame, cfg)
    return points, model.classify(points) == FOREGROUND, n_mid


# --------------------------------------------------------------------------- K-Means


def kmeans_elbow(
    points: ArrayLike,
    ks: Sequence[int],
    *,
    init: str = "k-means++",
    seed: int = 0,
    n_init: int = 4,
) -> NDArray[np.float64]:
    """K-Means inertia (sum of squared distances to the nearest centre, m^2) for each K.

    Args:
        points: (N,3) metres, N >= max(ks).
        ks: the numbers of clusters to try.
        init: "k-means++" or "random".
        seed: random state.
        n_init: restarts per K (the best inertia is kept).

    Returns:
        (len(ks),) inertias, m^2.

    Raises:
        ValueError: fewer points than the largest K.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(ks) and len(p) < max(ks):
        raise ValueError(f"{len(p)} points cannot form {max(ks)} clusters")
    return np.array(
        [
            KMeans(n_clusters=int(k), init=init, n_init=n_init, random_state=seed).fit(p).inertia_
            for k in ks
        ],
        dtype=np.float64,
    )


def elbow_k(ks: Sequence[int], inertias: ArrayLike) -> int:
    """The elbow of an inertia curve: the K farthest below the chord from the first to the last.

    Both axes are scaled to 0..1 first (the "kneedle" rule), so units do not matter.

    Raises:
        ValueError: fewer than 3 values, or mismatched lengths.
    """
    k = np.asarray(ks, dtype=np.float64)
    y = np.asarray(inertias, dtype=np.float64)
    if len(k) < 3 or len(k) != len(y):
        raise ValueError(f"need >= 3 (K, inertia) pairs of equal length, got {len(k)} and {len(y)}")
    kn = (k - k[0]) / (k[-1] - k[0])
    span = y[0] - y[-1]
    yn = (y - y[-1]) / span if span > 0 else np.zeros_like(y)
    # the chord runs from (0, 1) to (1, 0): distance below it ~ 1 - kn - yn
    return int(k[int(np.argmax(1.0 - kn - yn))])


@dataclass(frozen=True)
class KMeansStability:
    """K-Means run once per seed (one initialisation each): how much the result moves."""

    init: str
    k: int
    seeds: NDArray[np.int64]  # (S,)
    inertias: NDArray[np.float64]  # (S,) m^2
    centres: NDArray[np.float64]  # (S, k, 3) metres, matched to the best run's centres
    centre_shift_m: NDArray[np.float64]  # (S,) mean distance of matched centres to the best run's

    @property
    def inertia_spread(self) -> float:
        """Relative spread of the inertia over seeds: (max - min) / min."""
        lo = float(self.inertias.min())
        return float((self.inertias.max() - lo) / lo) if lo > 0 else 0.0


def kmeans_stability(
    points: ArrayLike, k: int, seeds: Sequence[int], init: str = "k-means++"
) -> KMeansStability:
    """Run K-Means with one initialisation per seed and compare the runs.

    Centres of each run are matched one-to-one to those of the lowest-inertia run (Hungarian
    assignment on distance), so ``centre_shift_m`` is 0 for runs that found the same solution.

    Args:
        points: (N,3) metres, N >= k.
        k: number of clusters.
        seeds: random states, one run each.
        init: "k-means++" or "random".

    Raises:
        ValueError: fewer points than ``k`` or no seed.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) < k:
        raise ValueError(f"{len(p)} points cannot form {k} clusters")
    if not len(seeds):
        raise ValueError("need at least one seed")
    fits = [KMeans(n_clusters=k, init=init, n_init=1, random_state=int(s)).fit(p) for s in seeds]
    inertias = np.array([f.inertia_ for f in fits], dtype=np.float64)
    best = fits[int(np.argmin(inertias))].cluster_centers_
    centres = np.empty((len(fits), k, 3))
    shift = np.empty(len(fits))
    for i, fit in enumerate(fits):
        c = fit.cluster_centers_
        d = np.linalg.norm(best[:, None, :] - c[None, :, :], axis=2)
        rows, cols = linear_sum_assignment(d)
        centres[i, rows] = c[cols]
        shift[i] = float(d[rows, cols].mean())
    return KMeansStability(
        init=init,
        k=k,
        seeds=np.asarray(seeds, dtype=np.int64),
        inertias=inertias,
        centres=centres,
        centre_shift_m=shift,
    )


# --------------------------------------------------------------------------- DBSCAN sweep


@dataclass(frozen=True)
class DbscanSweep:
    """Per-frame position error of DBSCAN clusters over a grid of (eps, min_samples).

    Two picks per frame: the cluster nearest the truth (an oracle: the best any selection rule
    could do) and the largest cluster (CL-Det's rule). A frame where no cluster forms has a
    NaN error (a miss).
    """

    eps_m: NDArray[np.float64]  # (E,)
    min_samples: NDArray[np.int64]  # (M,)
    nearest_error_m: NDArray[np.float64]  # (E, M, F) metres, NaN: no cluster
    largest_error_m: NDArray[np.float64]  # (E, M, F) metres, NaN: no cluster
    n_clusters: NDArray[np.int64]  # (E, M, F)

    def median_error(self, pick: str = "largest") -> NDArray[np.float64]:
        """(E, M) median error over the frames with a cluster, metres (NaN: no cluster at all)."""
        err = self._errors(pick)
        out = np.full(err.shape[:2], np.nan)
        found = np.isfinite(err).any(axis=2)
        out[found] = np.nanmedian(err[found], axis=1)
        return out

    def miss_rate(self) -> NDArray[np.float64]:
        """(E, M) fraction of frames where no cluster formed."""
        return np.mean(self.n_clusters == 0, axis=2)

    def hit_rate(self, pick: str = "largest", within_m: float = 1.0) -> NDArray[np.float64]:
        """(E, M) fraction of frames whose picked cluster lies within ``within_m`` of the truth.

        A frame without any cluster is not a hit, so this accounts for misses as well.
        """
        err = self._errors(pick)
        with np.errstate(invalid="ignore"):
            return np.mean(np.nan_to_num(err, nan=np.inf) <= within_m, axis=2)

    def best(self, pick: str = "largest", within_m: float = 1.0) -> tuple[float, int, float, float]:
        """The setting with the highest hit rate (ties: the lower median error, then smaller eps).

        Returns:
            (eps metres, min_samples, its hit rate, its median error metres).
        """
        hit = self.hit_rate(pick, within_m)
        med = np.nan_to_num(self.median_error(pick), nan=np.inf)
        best_hit = hit.max()
        candidates = np.argwhere(hit >= best_hit - 1e-12)  # row-major: smaller eps first
        i, j = min(candidates, key=lambda ij: (med[ij[0], ij[1]], ij[0], ij[1]))
        return float(self.eps_m[i]), int(self.min_samples[j]), float(hit[i, j]), float(med[i, j])

    def _errors(self, pick: str) -> NDArray[np.float64]:
        if pick == "largest":
            return self.largest_error_m
        if pick == "nearest":
            return self.nearest_error_m
        raise ValueError(f"unknown pick {pick!r}: expected 'largest' or 'nearest'")


def dbscan_sweep(
    foregrounds: Sequence[ArrayLike],
    truth: ArrayLike,
    eps_m: Sequence[float],
    min_samples: Sequence[int],
) -> DbscanSweep:
    """Cluster each frame's foreground with every (eps, min_samples) and measure the error.

    Clustering is the estimator's exact DBSCAN (:func:`cldet.core.clustering.cluster_points`);
    a cluster's position is its centroid.

    Args:
        foregrounds: F arrays (N_f, 3) of foreground points, metres (N_f may be 0).
        truth: (F, 3) the drone's position in each frame, metres.
        eps_m: neighbourhood radii to try, metres.
        min_samples: core-point thresholds to try.

    Returns:
        A :class:`DbscanSweep`.

    Raises:
        ValueError: ``truth`` does not have one row per frame.
    """
    t = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
    if len(t) != len(foregrounds):
        raise ValueError(f"need one truth row per frame: {len(foregrounds)} frames, {len(t)} rows")
    eps = np.asarray(eps_m, dtype=np.float64)
    ms = np.asarray(min_samples, dtype=np.int64)
    shape = (len(eps), len(ms), len(t))
    nearest = np.full(shape, np.nan)
    largest = np.full(shape, np.nan)
    count = np.zeros(shape, dtype=np.int64)
    for f, fg in enumerate(foregrounds):
        pts = np.asarray(fg, dtype=np.float64).reshape(-1, 3)
        if len(pts) == 0:
            continue
        for i, e in enumerate(eps):
            for j, m in enumerate(ms):
                labels = cluster_points(pts, float(e), int(m))
                clusters = summarize_clusters(pts, labels)
                count[i, j, f] = len(clusters)
                if not clusters:
                    continue
                d = np.linalg.norm(np.array([c.centroid for c in clusters]) - t[f], axis=1)
                nearest[i, j, f] = d.min()
                largest[i, j, f] = d[0]  # cluster 0 is the largest
    return DbscanSweep(
        eps_m=eps,
        min_samples=ms,
        nearest_error_m=nearest,
        largest_error_m=largest,
        n_clusters=count,
    )


# --------------------------------------------------------------------------- estimate errors


@dataclass(frozen=True)
class ErrorSeries:
    """Per-frame error of a method's estimates against the truth."""

    method: str
    stamps_ns: NDArray[np.int64]  # (N,) estimate stamps
    t_s: NDArray[np.float64]  # (N,) seconds since the first estimate
    error_m: NDArray[np.float64]  # (N,) 3D distance to the truth at the estimate's stamp
    source: NDArray[np.int64]  # (N,) cldet.types.Source values

    @property
    def rms_m(self) -> float:
        """RMS 3D error, metres (NaN when empty)."""
        return rms(self.error_m)


def estimate_errors(method: str, estimates: Sequence[Estimate], truth: Truth) -> ErrorSeries:
    """Error of every estimate: distance to the truth interpolated at its stamp.

    Args:
        method: a label (e.g. the configuration's ``method``).
        estimates: one sequence's estimates in stamp order.
        truth: the sequence's truth.

    Returns:
        An :class:`ErrorSeries`.
    """
    stamps = np.array([e.stamp_ns for e in estimates], dtype=np.int64)
    pos = np.array([e.position for e in estimates], dtype=np.float64).reshape(-1, 3)
    err = trajectory_errors(stamps, pos, truth.stamps_ns, truth.positions)
    t0 = stamps[0] if len(stamps) else 0
    return ErrorSeries(
        method=method,
        stamps_ns=stamps,
        t_s=(stamps - t0).astype(np.float64) / NS_PER_S,
        error_m=err,
        source=np.array([int(e.source) for e in estimates], dtype=np.int64),
    )


def error_by_source(series: ErrorSeries) -> dict[str, tuple[int, float]]:
    """Frames and RMS error (metres) per estimate source, for the sources present.

    Returns:
        ``{source name in lower case: (frames, RMS error m)}`` in :class:`Source` order.
    """
    out: dict[str, tuple[int, float]] = {}
    for source in Source:
        sel = series.source == int(source)
        if sel.any():
            out[source.name.lower()] = (int(sel.sum()), rms(series.error_m[sel]))
    return out


def source_runs(sources: ArrayLike) -> list[tuple[int, int, int]]:
    """Runs of equal values: ``(start, stop, value)`` with ``stop`` exclusive, in order."""
    s = np.asarray(sources).reshape(-1)
    if len(s) == 0:
        return []
    cuts = np.flatnonzero(s[1:] != s[:-1]) + 1
    starts = np.concatenate([[0], cuts])
    stops = np.concatenate([cuts, [len(s)]])
    return [(int(a), int(b), int(s[a])) for a, b in zip(starts, stops, strict=True)]
