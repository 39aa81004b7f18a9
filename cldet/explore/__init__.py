"""Helpers of the exploratory notebooks (``notebooks/``): statistics, clustering studies, errors.

The notebooks reproduce the CL-Det report's exploratory work (ground-truth heatmaps and
histograms, frames with and without environment points, K-Means with the elbow method, a
DBSCAN parameter sweep) and compare ``track`` with ``cl-det``. Whatever grew beyond a few lines
there lives here, tested. Plotting stays in the notebooks: this module needs numpy, scipy and
scikit-learn only, and reads data through ``converters.mmaud`` and the estimator core.

One module a job: :mod:`~cldet.explore.data` (a sequence's frames and truth),
:mod:`~cldet.explore.sensors` (points per frame, coverage, positions, environment points),
:mod:`~cldet.explore.clustering` (K-Means, the DBSCAN sweep), :mod:`~cldet.explore.error_series`
(a method's errors); everything is importable from ``cldet.explore`` as before.

Times are integer nanoseconds (``*_ns``), lengths metres (``*_m``), angles degrees (``*_deg``).
"""

from __future__ import annotations

from cldet.explore.clustering import (
    DbscanSweep,
    KMeansStability,
    dbscan_sweep,
    elbow_k,
    kmeans_elbow,
    kmeans_stability,
)
from cldet.explore.data import (
    Truth,
    load_truth,
    sequence_frames,
    truth_at,
)
from cldet.explore.error_series import (
    ErrorSeries,
    error_by_source,
    estimate_errors,
    source_runs,
)
from cldet.explore.sensors import (
    FrameStats,
    TruthHistograms,
    elevation_coverage,
    elevation_deg,
    frame_statistics,
    learn_background,
    split_environment,
    truth_histograms,
)

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
