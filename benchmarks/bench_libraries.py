"""Benchmark: cldet's hand-written code against the library that does the same, on one core.

Prints two tables, each with the library as the reference (the results must be identical):

- clustering: ``cldet.core.clustering.cluster_points`` (exact DBSCAN on a grid, numba) against
  ``scipy.spatial.cKDTree.query_pairs`` + ``scipy.sparse.csgraph.connected_components``, on
  foreground-like clouds (a few drone-sized blobs, clutter and speckle) of 300 to 20,000 points,
  eps 1 m, ``min_samples`` 1 (the estimator's setting) and 3; the partitions are compared;
- reading: ``cldet.io.mcap_read.LogReader.iter_clouds`` (its own chunk parser and protobuf
  walker) against ``mcap.reader.make_reader(...).iter_messages`` + ``PointCloud.FromString``, on
  a log written by ``LogWriter`` with two LiDAR channels and a pose channel; the decoded points
  and stamps are compared.

    python benchmarks/bench_libraries.py               # the full sizes
    python benchmarks/bench_libraries.py --quick       # smaller, for a smoke test

Times are the median of ``--repeat`` runs after a warm-up (numba compiled, files in the page
cache); the first-call time (numba's compile or cache load) is printed apart.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray


def _median_s(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


# --------------------------------------------------------------------------- clustering
def foreground_cloud(n: int, seed: int) -> NDArray[np.float64]:
    """(n, 3) metres: 10 % in drone-sized blobs, 60 % in clutter patches, 30 % lone speckle."""
    rng = np.random.default_rng(seed)
    n_blob, n_clutter = n // 10, (6 * n) // 10
    n_speckle = n - n_blob - n_clutter
    blob_ids = rng.integers(0, 8, n_blob)
    blobs = rng.uniform(-40, 40, (8, 3))[blob_ids] + rng.normal(0, 0.2, (n_blob, 3))
    centres = rng.uniform(-50, 50, (max(n_clutter // 150, 1), 3))
    clutter = centres[rng.integers(0, len(centres), n_clutter)] + rng.normal(0, 1.5, (n_clutter, 3))
    speckle = rng.uniform(-60, 60, (n_speckle, 3))
    return np.concatenate([blobs, clutter, speckle])


def scipy_dbscan(points: NDArray[np.float64], eps: float, min_samples: int) -> NDArray[np.int64]:
    """DBSCAN labels from the libraries: pairs within eps, core points, components, borders.

    Clusters are named by first appearance (compare partitions, not names); border points take
    the cluster of their nearest core point, as ``cluster_points`` does.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = len(points)
    pairs = cKDTree(points).query_pairs(eps, output_type="ndarray")
    core = np.ones(n, dtype=bool)
    if min_samples > 1:
        counts = 1 + np.bincount(pairs.ravel(), minlength=n)
        core = counts >= min_samples
    both = core[pairs[:, 0]] & core[pairs[:, 1]]
    a, b = pairs[both, 0], pairs[both, 1]
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    labels = labels.astype(np.int64)
    labels[~core] = -1
    if min_samples > 1:
        border = core[pairs[:, 0]] ^ core[pairs[:, 1]]
        i, j = pairs[border, 0], pairs[border, 1]
        core_end = np.where(core[i], i, j)
        other = np.where(core[i], j, i)
        d = np.linalg.norm(points[core_end] - points[other], axis=1)
        order = np.lexsort((d, other))  # per border point, its nearest core point first
        first = np.ones(len(order), dtype=bool)
        first[1:] = other[order][1:] != other[order][:-1]
        pick = order[first]
        labels[other[pick]] = labels[core_end[pick]]
    return labels


def partition(labels: NDArray[np.integer]) -> set[frozenset[int]]:
    """The clusters as sets of point indices (noise excluded)."""
    out: dict[int, list[int]] = {}
    for i, c in enumerate(labels.tolist()):
        if c >= 0:
            out.setdefault(c, []).append(i)
    return {frozenset(v) for v in out.values()}


def bench_clustering(sizes: list[int], repeat: int) -> None:
    from cldet.core.clustering import cluster_points

    t0 = time.perf_counter()
    cluster_points(foreground_cloud(100, 0), 1.0, 1)
    cluster_points(foreground_cloud(100, 0), 1.0, 3)
    first = time.perf_counter() - t0
    print(
        f"\nclustering (eps 1 m); numba first calls (compile or cache load): {first * 1e3:.0f} ms"
    )
    print(f"{'points':>7} {'min_samples':>11} {'numba ms':>9} {'scipy ms':>9} {'same':>5}")
    for n in sizes:
        pts = foreground_cloud(n, n)
        for ms in (1, 3):
            ours = cluster_points(pts, 1.0, ms)
            ref = scipy_dbscan(pts, 1.0, ms)
            same = partition(ours) == partition(ref)
            t_ours = _median_s(lambda pts=pts, ms=ms: cluster_points(pts, 1.0, ms), repeat)
            t_ref = _median_s(lambda pts=pts, ms=ms: scipy_dbscan(pts, 1.0, ms), repeat)
            print(f"{n:>7} {ms:>11} {t_ours * 1e3:>9.2f} {t_ref * 1e3:>9.2f} {str(same):>5}")


# --------------------------------------------------------------------------- reading
def write_log(path: Path, frames: int, points: int) -> None:
    """A log like a converted sequence: Mid-360 and Avia clouds at 10 Hz, a pose per frame."""
    from cldet.io import LogWriter
    from cldet.io import topics as tp

    rng = np.random.default_rng(1)
    with open(path, "wb") as f, LogWriter(f) as writer:
        for i in range(frames):
            stamp = 1_713_163_000 * 10**9 + i * 100_000_000
            mid = rng.normal(0, 20, (points, 3)).astype(np.float32)
            avia = rng.normal(0, 20, (points // 2, 3)).astype(np.float32)
            writer.write_cloud(tp.LIDAR_360, stamp, mid, tp.FRAME_MID360)
            writer.write_cloud(tp.LIVOX_AVIA, stamp + 14_000_000, avia, tp.FRAME_MID360)
            writer.write_pose(tp.GROUND_TRUTH, stamp, rng.normal(0, 10, 3), tp.FRAME_MID360)
        writer.write_metadata(tp.METADATA_SOURCE, {"sequence": "seq0001", "split": "val"})


def library_clouds(path: Path, topic: str) -> list[tuple[int, NDArray[np.float32]]]:
    """(stamp, (N,3) float32) per message, through mcap's reader and protobuf."""
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
    from mcap.reader import make_reader

    out = []
    with open(path, "rb") as f:
        for _schema, _channel, message in make_reader(f).iter_messages(topics=[topic]):
            cloud = PointCloud.FromString(message.data)
            stride = cloud.point_stride
            raw = np.frombuffer(cloud.data, dtype=np.uint8).reshape(-1, stride)
            offsets = {field.name: field.offset for field in cloud.fields}
            xyz = np.stack(
                [raw[:, offsets[a] : offsets[a] + 4].copy().view(np.float32)[:, 0] for a in "xyz"],
                axis=1,
            )
            out.append((message.log_time, xyz))
    return out


def ours_clouds(path: Path, topic: str) -> list[tuple[int, NDArray[np.float32]]]:
    from cldet.io import open_log

    with open_log(path) as log:
        return [(c.stamp_ns, c.points) for c in log.iter_clouds(topic)]


def bench_reading(frames: int, points: int, repeat: int) -> None:
    from cldet.io import topics as tp

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "seq0001.mcap"
        write_log(path, frames, points)
        size_mb = path.stat().st_size / 1e6
        print(
            f"\nreading a log of {frames} frames ({points} + {points // 2} points), {size_mb:.0f} MB"
        )
        print(f"{'topic':>20} {'cldet ms':>9} {'mcap ms':>9} {'same':>5}")
        for topic in (tp.LIDAR_360, tp.LIVOX_AVIA):
            ours = ours_clouds(path, topic)
            ref = library_clouds(path, topic)
            same = len(ours) == len(ref) and all(
                a[0] == b[0] and np.array_equal(a[1], b[1]) for a, b in zip(ours, ref, strict=True)
            )
            t_ours = _median_s(lambda topic=topic: ours_clouds(path, topic), repeat)
            t_ref = _median_s(lambda topic=topic: library_clouds(path, topic), repeat)
            print(f"{topic:>20} {t_ours * 1e3:>9.1f} {t_ref * 1e3:>9.1f} {str(same):>5}")


def main() -> None:
    """Run both benchmarks and print the tables."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="smaller sizes (a smoke test)")
    parser.add_argument("--repeat", type=int, default=7, help="timed runs per figure (median)")
    args = parser.parse_args()
    from machine import cpu_model  # benchmarks/machine.py (the script's folder is on the path)

    print(f"{cpu_model()}, {os.cpu_count()} cores (one used), numpy {np.__version__}")
    sizes = [300, 3000] if args.quick else [300, 3000, 20000]
    bench_clustering(sizes, args.repeat)
    if args.quick:
        bench_reading(frames=20, points=2000, repeat=args.repeat)
    else:
        bench_reading(frames=300, points=20000, repeat=args.repeat)


if __name__ == "__main__":
    main()
