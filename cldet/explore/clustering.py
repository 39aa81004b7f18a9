"""Clustering studies: K-Means with the elbow method and its stability, a DBSCAN parameter sweep."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment
from sklearn.cluster import KMeans

from cldet.core.clustering import cluster_points, summarize_clusters


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
