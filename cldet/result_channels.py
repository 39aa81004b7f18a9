"""The ``/cldet/*`` messages of an annotate run, as writes through a :class:`LogWriter`.

The same writes go into the annotated log (:func:`result_additions`, by
:func:`cldet.pipeline.annotate_log`) and to a live Foxglove stream (:func:`causal_additions`,
:func:`track_writer`, by :mod:`cldet.live`), so a live view shows what the log will hold.
Foxglove draws every channel; Rerun's MCAP import draws the point clouds among them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from cldet.colours import CHOSEN_RGBA, SOURCE_RGBA, TRACK_RGBA
from cldet.core.estimator import FrameDetections, SequenceEstimate
from cldet.io import topics
from cldet.io.mcap_write import LogWriter
from cldet.io.rewrite import Addition
from cldet.types import ClassEstimate, Estimate

__all__ = ["causal_additions", "result_additions", "track_writer", "truth_track_writer"]

_TRUTH_RGBA = (255, 255, 255, 255)
_CLUSTER_RGBA = (255, 150, 0, 255)


def result_additions(
    result: SequenceEstimate,
    detections: Sequence[FrameDetections],
    *,
    frame_id: str = topics.FRAME_MID360,
    truth: NDArray[np.float64] | None = None,
    stamps: Sequence[int] | None = None,
) -> list[tuple[int, Addition]]:
    """The ``/cldet/*`` messages of one annotate run, as ``(log_time_ns, write)`` pairs.

    ``stamps``: each of ``detections``' ``stamp_ns``, where the caller kept them (``detections``
    may live on disk: each is then read once, when its messages are written, not also here).

    All in ``frame_id`` (the LiDAR's frame). Foxglove draws every one of them; Rerun's MCAP
    import draws the point clouds (``/cldet/drone``, ``/cldet/track``, ``/cldet/truth_track``,
    ``/cldet/centroids``, ``/cldet/foreground``), not the poses or the scene update.

    - ``/cldet/estimate`` (cldet.Estimate) and ``/cldet/pose`` (foxglove.PoseInFrame)
      per estimate of the refined track;
    - ``/cldet/causal`` (cldet.Estimate): the causal estimate of each frame, as it was made
      from that frame and the ones before (what a live run shows);
    - ``/cldet/class`` (cldet.ClassEstimate), with a model: the drone type and every class's
      probability from the chosen track's evidence up to each second, the last one final;
    - ``/cldet/trajectory`` (foxglove.PosesInFrame): the whole smoothed trajectory, once, at the
      first frame's stamp, so a viewer shows it for the whole playback;
    - ``/cldet/clusters`` (foxglove.SceneUpdate) per frame: a box and label per cluster, the
      chosen one as a separate green ``drone`` entity;
    - ``/cldet/foreground`` (foxglove.PointCloud x, y, z, cluster_id) per frame;
    - ``/cldet/drone`` (the estimate, coloured by source) and ``/cldet/centroids`` (cluster
      centres, the chosen one green) per frame, ``/cldet/track`` (the refined track, magenta)
      and ``/cldet/truth_track`` (``truth``, (K, 3) metres, white) once at the first stamp:
      coloured point clouds, which Rerun draws too.
    """
    additions: list[tuple[int, Addition]] = []
    for est in result.estimates:
        additions.append((est.stamp_ns, _estimate_writer(est, frame_id)))
    for est in result.causal:
        additions.append((est.stamp_ns, _causal_writer(est)))
    for cls in result.classes:
        additions.append((cls.stamp_ns, _class_writer(cls)))
    if result.estimates:
        first = result.estimates[0].stamp_ns
        positions = np.array([e.position for e in result.estimates], dtype=np.float64)
        additions.append((first, track_writer(first, positions, frame_id)))
        if truth is not None and len(truth):
            truth_xyz = np.asarray(truth, dtype=np.float64)
            additions.append((first, truth_track_writer(first, truth_xyz, frame_id)))
    if stamps is None:
        stamps = [det.stamp_ns for det in detections]
    for i, stamp_ns in enumerate(stamps):
        # the writer reads its frame when called: ``detections`` may live on disk
        chosen_id = result.chosen.get(stamp_ns)
        additions.append((stamp_ns, _frame_clusters_writer(detections, i, chosen_id, frame_id)))
    return additions


def track_writer(stamp_ns: int, positions: NDArray[np.float64], frame_id: str) -> Addition:
    """Writes the refined track: ``/cldet/trajectory`` (poses) and ``/cldet/track`` (cloud)."""

    def write(writer: LogWriter) -> None:
        writer.write_poses(topics.TRAJECTORY, stamp_ns, positions, frame_id)
        writer.write_colored_cloud(topics.TRACK, stamp_ns, positions, TRACK_RGBA, frame_id)

    return write


def truth_track_writer(stamp_ns: int, positions: NDArray[np.float64], frame_id: str) -> Addition:
    """Writes the ground truth's trajectory once: ``/cldet/truth_track`` (a white cloud)."""

    def write(writer: LogWriter) -> None:
        writer.write_colored_cloud(topics.TRUTH_TRACK, stamp_ns, positions, _TRUTH_RGBA, frame_id)

    return write


def _estimate_writer(est: Estimate, frame_id: str) -> Addition:
    def write(writer: LogWriter) -> None:
        writer.write_estimate(topics.ESTIMATE, est.stamp_ns, est)
        writer.write_pose(topics.POSE, est.stamp_ns, est.position, frame_id)
        writer.write_colored_cloud(
            topics.DRONE, est.stamp_ns, est.position[None, :], SOURCE_RGBA[est.source], frame_id
        )

    return write


def _class_writer(estimate: ClassEstimate) -> Addition:
    def write(writer: LogWriter) -> None:
        writer.write_class_estimate(topics.CLASS_ESTIMATE, estimate)

    return write


def causal_additions(det: FrameDetections, frame_id: str) -> list[tuple[int, Addition]]:
    """What a live view shows of one frame as it is processed: its foreground, cluster centres
    and boxes, and the causal estimate (``/cldet/causal``, ``/cldet/drone``, ``/cldet/pose``)."""
    additions = [(det.stamp_ns, _clusters_writer(det, None, frame_id))]
    est = det.estimate
    if est is not None:

        def write(writer: LogWriter) -> None:
            writer.write_estimate(topics.CAUSAL, est.stamp_ns, est)
            writer.write_pose(topics.POSE, est.stamp_ns, est.position, frame_id)
            writer.write_colored_cloud(
                topics.DRONE,
                est.stamp_ns,
                est.position[None, :],
                SOURCE_RGBA[est.source],
                frame_id,
            )

        additions.append((det.stamp_ns, write))
    return additions


def _causal_writer(est: Estimate) -> Addition:
    def write(writer: LogWriter) -> None:
        writer.write_estimate(topics.CAUSAL, est.stamp_ns, est)

    return write


def _frame_clusters_writer(
    detections: Sequence[FrameDetections], index: int, chosen_id: int | None, frame_id: str
) -> Addition:
    def write(writer: LogWriter) -> None:
        _clusters_writer(detections[index], chosen_id, frame_id)(writer)

    return write


def _clusters_writer(det: FrameDetections, chosen_id: int | None, frame_id: str) -> Addition:
    def write(writer: LogWriter) -> None:
        cloud = np.column_stack([det.foreground, det.labels.astype(np.float32)])
        writer.write_cloud(
            topics.FOREGROUND,
            det.stamp_ns,
            cloud,
            frame_id,
            fields=("x", "y", "z", "cluster_id"),
        )
        others = [c for c in det.clusters if c.cluster_id != chosen_id]
        writer.write_scene_update(topics.CLUSTERS, det.stamp_ns, others, frame_id)
        chosen = [c for c in det.clusters if c.cluster_id == chosen_id]
        centres = np.array([c.centroid for c in others + chosen], dtype=np.float64).reshape(-1, 3)
        colours = np.array([_CLUSTER_RGBA] * len(others) + [CHOSEN_RGBA] * len(chosen), np.uint8)
        writer.write_colored_cloud(
            topics.CENTROIDS, det.stamp_ns, centres, colours.reshape(-1, 4), frame_id
        )
        writer.write_scene_update(
            topics.CLUSTERS,
            det.stamp_ns,
            chosen,
            frame_id,
            labels=[f"drone ({c.n_points} pts)" for c in chosen],
            color=(0.1, 0.9, 0.2, 0.8),
            entity_id="drone",
        )

    return write
