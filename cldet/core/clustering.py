"""Exact DBSCAN of one frame's foreground points on a uniform grid (numba), and cluster summaries.

With ``min_samples = 1`` DBSCAN is the connected components of the graph "within ``eps``"
(single linkage): a far drone gives 1-3 points and must still form a cluster. The grid has
cells of edge ``eps``, so every neighbour of a point lies in its own or one of the 26
adjacent cells; points are sorted by cell and each cell's neighbours are found by binary
search, then joined with a union-find. The result is exact (distances <= eps, as
scikit-learn's DBSCAN) and independent of the point order up to the naming of the clusters.

For ``min_samples > 1``, core points (>= ``min_samples`` points within ``eps``, itself
included) are joined as above; a border point takes the cluster of its nearest core point
(scikit-learn takes the first one it meets, which depends on the order); the rest is noise (-1).

Cluster ids are numbered by decreasing size (ties: by smallest x, then y, then z of their
centroid), so the numbering does not depend on the input order either.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from cldet.types import Cluster

__all__ = ["cluster_points", "summarize_clusters"]


@numba.njit(cache=True)
def _find(parent: NDArray[np.int64], i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@numba.njit(cache=True)
def _dist2(points: NDArray[np.float64], i: int, j: int) -> float:
    """Squared distance between points i and j."""
    dd = 0.0
    for d in range(3):
        t = points[i, d] - points[j, d]
        dd += t * t
    return dd


@numba.njit(cache=True)
def _sorted_grid(
    points: NDArray[np.float64], h: float, pad: int
) -> tuple[
    NDArray[np.int64],
    NDArray[np.int64],
    NDArray[np.int64],
    NDArray[np.int64],
    NDArray[np.int64],
    NDArray[np.int64],
]:
    """Points binned in cubic cells of edge ``h``, sorted by cell key.

    Returns ``(lo, span, order, ukeys, starts, ccell)``: the grid origin and size per axis (with
    ``pad`` empty cells on each side, so neighbour keys never wrap), the point order by key, the
    occupied cells' keys, their point ranges ``order[starts[c]:starts[c + 1]]`` and their integer
    coordinates.
    """
    n = points.shape[0]
    cells = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        for d in range(3):
            cells[i, d] = np.int64(np.floor(points[i, d] / h))
    lo = np.empty(3, dtype=np.int64)
    span = np.empty(3, dtype=np.int64)
    for d in range(3):
        lo[d] = cells[:, d].min() - pad
        span[d] = cells[:, d].max() - lo[d] + pad + 1
    keys = np.empty(n, dtype=np.int64)
    for i in range(n):
        keys[i] = ((cells[i, 0] - lo[0]) * span[1] + (cells[i, 1] - lo[1])) * span[2] + (
            cells[i, 2] - lo[2]
        )
    order = np.argsort(keys)
    skeys = keys[order]
    n_cells = 1
    for s in range(1, n):
        if skeys[s] != skeys[s - 1]:
            n_cells += 1
    ukeys = np.empty(n_cells, dtype=np.int64)
    starts = np.empty(n_cells + 1, dtype=np.int64)
    ccell = np.empty((n_cells, 3), dtype=np.int64)
    c = 0
    ukeys[0] = skeys[0]
    starts[0] = 0
    ccell[0] = cells[order[0]]
    for s in range(1, n):
        if skeys[s] != skeys[s - 1]:
            c += 1
            ukeys[c] = skeys[s]
            starts[c] = s
            ccell[c] = cells[order[s]]
    starts[n_cells] = n
    return lo, span, order, ukeys, starts, ccell


@numba.njit(cache=True)
def _neighbour_pairs(
    points: NDArray[np.float64], eps: float
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """All pairs (i < j) within ``eps`` (inclusive) and their squared distances, on a grid."""
    n = points.shape[0]
    _, span, order, ukeys, starts, _ = _sorted_grid(points, eps, 1)
    n_cells = len(ukeys)
    eps2 = eps * eps
    cap = 4 * n + 16
    pairs = np.empty((cap, 2), dtype=np.int64)
    dist2 = np.empty(cap, dtype=np.float64)
    m = 0
    for ci in range(n_cells):
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    off = (dx * span[1] + dy) * span[2] + dz
                    if off < 0:
                        continue  # half shell: each cell pair once
                    key = ukeys[ci] + off
                    cj = ci
                    if off > 0:
                        cj = np.searchsorted(ukeys, key)
                        if cj >= n_cells or ukeys[cj] != key:
                            continue
                    for a in range(starts[ci], starts[ci + 1]):
                        i = order[a]
                        b0 = a + 1 if cj == ci else starts[cj]
                        for b in range(b0, starts[cj + 1]):
                            j = order[b]
                            dd = _dist2(points, i, j)
                            if dd <= eps2:
                                if m == cap:
                                    cap *= 2
                                    bigger = np.empty((cap, 2), dtype=np.int64)
                                    bigger[:m] = pairs[:m]
                                    pairs = bigger
                                    bigger_d = np.empty(cap, dtype=np.float64)
                                    bigger_d[:m] = dist2[:m]
                                    dist2 = bigger_d
                                pairs[m, 0] = min(i, j)
                                pairs[m, 1] = max(i, j)
                                dist2[m] = dd
                                m += 1
    return pairs[:m], dist2[:m]


@numba.njit(cache=True)
def _dbscan_roots(
    n: int, pairs: NDArray[np.int64], dist2: NDArray[np.float64], min_samples: int
) -> NDArray[np.int64]:
    """Component root per point (-1 for noise) from the eps-pairs; roots are point indices."""
    core = np.ones(n, dtype=np.bool_)
    if min_samples > 1:
        counts = np.ones(n, dtype=np.int64)  # itself
        for p in range(pairs.shape[0]):
            counts[pairs[p, 0]] += 1
            counts[pairs[p, 1]] += 1
        for i in range(n):
            core[i] = counts[i] >= min_samples
    parent = np.arange(n)
    for p in range(pairs.shape[0]):
        i, j = pairs[p, 0], pairs[p, 1]
        if core[i] and core[j]:
            ri = _find(parent, i)
            rj = _find(parent, j)
            if ri != rj:
                parent[max(ri, rj)] = min(ri, rj)
    root = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        if core[i]:
            root[i] = _find(parent, i)
    if min_samples > 1:  # border point -> cluster of its nearest core point
        best = np.full(n, np.inf)
        for p in range(pairs.shape[0]):
            i, j = pairs[p, 0], pairs[p, 1]
            if core[i] and not core[j] and dist2[p] < best[j]:
                best[j] = dist2[p]
                root[j] = root[i]
            elif core[j] and not core[i] and dist2[p] < best[i]:
                best[i] = dist2[p]
                root[i] = root[j]
    return root


@numba.njit(cache=True)
def _lower_bound(a: NDArray[np.int64], n: int, key: int) -> int:
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) >> 1
        if a[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo


@numba.njit(cache=True)
def _compact(
    root: NDArray[np.int64], points: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Labels 0..K-1 by first appearance (roots < 0 stay -1), sizes (K,), centroids (K,3)."""
    n = root.shape[0]
    m = 0
    for i in range(n):
        m = max(m, root[i] + 1)
    remap = np.full(m, -1, dtype=np.int64)
    labels = np.full(n, -1, dtype=np.int64)
    k = 0
    for i in range(n):
        r = root[i]
        if r < 0:
            continue
        if remap[r] < 0:
            remap[r] = k
            k += 1
        labels[i] = remap[r]
    sizes = np.zeros(k, dtype=np.int64)
    cent = np.zeros((k, 3))
    for i in range(n):
        c = labels[i]
        if c >= 0:
            sizes[c] += 1
            for d in range(3):
                cent[c, d] += points[i, d]
    for c in range(k):
        for d in range(3):
            cent[c, d] /= sizes[c]
    return labels, sizes, cent


@numba.njit(cache=True)
def _grid_components(points: NDArray[np.float64], eps: float) -> NDArray[np.int64]:
    """Connected components of the graph "within eps" (DBSCAN with min_samples 1).

    Cells of edge eps/sqrt(3): two points in one cell are always within eps, so a cell is
    joined as a whole; two cells at most 2 apart on every axis are joined when any pair of their
    points is within eps (early exit). Returns a component root (a cell index) per point.
    """
    n = points.shape[0]
    h = eps / np.sqrt(3.0) * (1.0 - 1e-12)
    lo, span, order, ukeys, starts, ccell = _sorted_grid(points, h, 3)
    n_cells = len(ukeys)
    eps2 = eps * eps
    parent = np.arange(n_cells)
    for ci in range(n_cells):
        for dx in range(-2, 3):
            for dy in range(-2, 3):
                key_lo = (
                    (ccell[ci, 0] + dx - lo[0]) * span[1] + (ccell[ci, 1] + dy - lo[1])
                ) * span[2] + (ccell[ci, 2] - 2 - lo[2])
                cj = _lower_bound(ukeys, n_cells, key_lo)
                while cj < n_cells and ukeys[cj] <= key_lo + 4:
                    if cj > ci:
                        dz = ccell[cj, 2] - ccell[ci, 2]
                        gap = 0.0
                        if dx * dx > 1:
                            gap += (abs(dx) - 1) ** 2
                        if dy * dy > 1:
                            gap += (abs(dy) - 1) ** 2
                        if dz * dz > 1:
                            gap += (abs(dz) - 1) ** 2
                        if gap * h * h <= eps2:
                            ri = _find(parent, ci)
                            rj = _find(parent, cj)
                            if ri != rj:
                                linked = False
                                for a in range(starts[ci], starts[ci + 1]):
                                    i = order[a]
                                    for b in range(starts[cj], starts[cj + 1]):
                                        j = order[b]
                                        if _dist2(points, i, j) <= eps2:
                                            linked = True
                                            break
                                    if linked:
                                        break
                                if linked:
                                    parent[max(ri, rj)] = min(ri, rj)
                    cj += 1
    root = np.empty(n, dtype=np.int64)
    for c in range(n_cells):
        r = _find(parent, c)
        for a in range(starts[c], starts[c + 1]):
            root[order[a]] = r
    return root


def cluster_points(
    points: NDArray[np.floating], eps_m: float, min_samples: int = 1
) -> NDArray[np.int32]:
    """Exact DBSCAN labels of ``points`` (N,3) metres: (N,) int32, clusters 0..K-1, noise -1.

    Cluster 0 is the largest. Neighbours are points within ``eps_m`` (inclusive).
    """
    if eps_m <= 0:
        raise ValueError(f"eps_m must be > 0, got {eps_m}")
    if min_samples < 1:
        raise ValueError(f"min_samples must be >= 1, got {min_samples}")
    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=np.int32)
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if min_samples == 1:
        root = _grid_components(pts, float(eps_m))
    else:
        pairs, dist2 = _neighbour_pairs(pts, float(eps_m))
        root = _dbscan_roots(n, pairs, dist2, int(min_samples))
    lab, sizes, cent = _compact(root, pts)
    k = len(sizes)
    if k == 0:
        return np.full(n, -1, dtype=np.int32)
    # rank: size descending, then centroid x, y, z ascending (order independent)
    rank_order = np.lexsort((cent[:, 2], cent[:, 1], cent[:, 0], -sizes))
    new_id = np.empty(k + 1, dtype=np.int32)
    new_id[rank_order] = np.arange(k, dtype=np.int32)
    new_id[k] = -1
    labels = new_id[np.where(lab >= 0, lab, k)]
    return labels


def summarize_clusters(
    points: NDArray[np.floating], labels: NDArray[np.integer], n_mid360: int | None = None
) -> tuple[Cluster, ...]:
    """One Cluster per label 0..K-1 (noise ignored): centroid, box, point counts per sensor,
    the Mid-360 points' vertical spread.

    Args:
        points: (N,3) metres.
        labels: (N,) cluster ids from ``cluster_points``.
        n_mid360: the first ``n_mid360`` points come from the Mid-360, the rest from the Avia
            (None: all from the Mid-360).
    """
    if len(points) == 0 or labels.max(initial=-1) < 0:
        return ()
    n_mid = len(points) if n_mid360 is None else n_mid360
    pts = np.asarray(points, dtype=np.float64)
    valid = labels >= 0
    lab = labels[valid].astype(np.int64)
    p = pts[valid]
    is_mid = (np.arange(len(points)) < n_mid)[valid]
    k = int(lab.max()) + 1
    order = np.argsort(lab, kind="stable")
    lab_s, p_s = lab[order], p[order]
    starts = np.searchsorted(lab_s, np.arange(k))
    sizes = np.bincount(lab, minlength=k)
    n_mid_c = np.bincount(lab, weights=is_mid, minlength=k).astype(np.int64)
    lower = np.minimum.reduceat(p_s, starts, axis=0)
    upper = np.maximum.reduceat(p_s, starts, axis=0)
    cent = np.add.reduceat(p_s, starts, axis=0) / sizes[:, None]
    # the Mid-360 points' vertical spread about their own mean, per cluster (about the centroid
    # first, so that the sums of squares lose nothing to the points' height)
    z = np.where(is_mid[order], p_s[:, 2] - cent[lab_s, 2], 0.0)
    sum_z = np.add.reduceat(z, starts)
    z_ss = np.maximum(np.add.reduceat(z * z, starts) - sum_z**2 / np.maximum(n_mid_c, 1), 0.0)
    z_ss_list = z_ss.tolist()
    return tuple(
        Cluster(
            cluster_id=c,
            centroid=cent[c],
            lower=lower[c],
            upper=upper[c],
            n_points=int(sizes[c]),
            n_mid360=int(n_mid_c[c]),
            n_avia=int(sizes[c] - n_mid_c[c]),
            mid360_z_ss=z_ss_list[c],
        )
        for c in range(k)
    )
