"""``annotate``: read a log's LiDAR channels, run the estimator, write results back, record a review.

The flow for one log (times are integer ns throughout):

1. one pass streams the paired Mid-360/Avia frames through the estimator's per-frame verb
   (``register_frame``: background, clusters, tracks, the causal estimate) and the review view;
2. ``refine`` selects and smooths the drone's track over what was stored per frame;
4. the log is rewritten with the ``/cldet/*`` result channels (every source message copied byte
   for byte, earlier results replaced), atomically, and the ``.rrd`` renamed into place.

Nothing holds more than one frame's raw points; what the results need of each frame (its
foreground and clusters) waits in a temporary file (:class:`cldet.io.spool.Spool`), and the
estimator keeps per frame only what ``refine`` needs, so memory grows slowly with the length.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Iterator, Sequence
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from cldet import __version__
from cldet.config import CldetConfig, FramesConfig, SensorConfig, config_to_dict
from cldet.core.estimator import FrameDetections
from cldet.core.frames import pair_frames
from cldet.core.methods import make_estimator
from cldet.core.model import LearnedModel
from cldet.core.trajectory import rms, trajectory_errors
from cldet.errors import CldetError, FrameOrderError
from cldet.executors import iter_outcomes, runs_here
from cldet.io import topics
from cldet.io.files import check_output, file_size, lock_file
from cldet.io.mcap_append import is_replaced_channel
from cldet.io.mcap_read import LogReader, open_log
from cldet.io.mcap_write import LogWriter
from cldet.io.rewrite import Addition, rewrite_log
from cldet.io.ros import FrameTransform
from cldet.io.sources import (
    SensorTopics,
    iter_log_clouds,
    reader_clouds,
    reader_positions,
    select_topics,
)
from cldet.io.spool import Spool
from cldet.io.transforms import log_tree
from cldet.live import LiveOutput
from cldet.progress import NullProgress, Progress
from cldet.result_channels import result_additions
from cldet.signals import check_terminated
from cldet.types import Cloud, Estimate, LidarFrame, PositionSample, Source
from cldet.view import NullView, RerunView, TeeView, View

METADATA_ANNOTATE = topics.METADATA_CONFIG


@dataclass(frozen=True)
class AnnotateReport:
    """The outcome of annotating one log."""

    log: Path
    output: Path
    rrd: Path | None
    sequence: str
    frames: int
    sources: dict[str, int]  # estimates per source name
    seconds: float
    rms_error_m: float | None  # against the log's ground truth, when it has one

    @property
    def predictions_per_s(self) -> float:
        """Estimates produced per second of wall time, end to end."""
        return self.frames / self.seconds if self.seconds > 0 else float("inf")

    def describe(self) -> str:
        """One line for the terminal."""
        parts = [
            f"{self.sequence}: {self.frames} frames in {self.seconds:.1f} s ({self.predictions_per_s:.0f}/s)"
        ]
        parts.append(", ".join(f"{n} {k}" for k, n in self.sources.items() if n))
        if self.rms_error_m is not None:
            parts.append(f"RMS error {self.rms_error_m:.3f} m vs ground truth")
        parts.append(f"-> {self.output}")
        if self.rrd is not None:
            parts.append(f"review: rerun {self.rrd}")
        return "; ".join(parts)


def _avia_extrinsic(cfg: FramesConfig) -> NDArray[np.float64] | None:
    """The configured Avia-to-LiDAR transform (4x4), None when it is the identity."""
    if not any(cfg.avia_xyz_m) and not any(cfg.avia_rpy_deg):
        return None
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_euler("xyz", cfg.avia_rpy_deg, degrees=True).as_matrix()
    matrix[:3, 3] = cfg.avia_xyz_m
    return matrix


def read_frames(
    log: Path,
    sensors: SensorTopics,
    cfg: FramesConfig,
    lidar_frame: list[str] | None = None,
    truth: list[PositionSample] | None = None,
) -> Iterator[LidarFrame]:
    """The LiDAR's frames paired with the Avia's, streamed in one pass over the log.

    The topics are read through one reader, in step, so each chunk is decompressed once.
    ``lidar_frame`` receives the LiDAR's frame id from its first cloud; ``truth``, when given,
    receives the positions of ``sensors.truth`` (read in step with the frames, complete when
    the frames are).
    """
    if lidar_frame is None:
        lidar_frame = []
    extrinsic = _avia_extrinsic(cfg)
    with open_log(log) as reader:

        def lidar() -> Iterator[Cloud]:
            for cloud in reader_clouds(reader, sensors.lidar):
                if not lidar_frame:
                    lidar_frame.append(cloud.frame_id)
                yield Cloud(stamp_ns=cloud.stamp_ns, points=cloud.points, times=cloud.times)

        def avia(topic: str) -> Iterator[Cloud]:
            # into the LiDAR's frame through the log's /tf_static when it connects them, else by
            # the configured extrinsic; pair_frames asks for the first LiDAR cloud before the
            # first Avia cloud
            into = lambda: lidar_frame[0] if lidar_frame else None  # noqa: E731
            for cloud in reader_clouds(reader, topic, target_frame=into, fallback=extrinsic):
                yield Cloud(stamp_ns=cloud.stamp_ns, points=cloud.points, times=cloud.times)

        positions = (
            reader_positions(reader, sensors.truth)
            if truth is not None and sensors.truth
            else iter(())
        )
        sink = truth if truth is not None else []  # empty when no truth is asked for
        pending = next(positions, None)
        for frame in pair_frames(lidar(), avia(sensors.avia) if sensors.avia else iter(())):
            yield frame
            while pending is not None and pending.stamp_ns <= frame.stamp_ns:
                sink.append(pending)
                pending = next(positions, None)
        if pending is not None:
            sink.append(pending)
            sink.extend(positions)


def annotate_log(
    log: Path,
    *,
    config: CldetConfig | None = None,
    output: Path | None = None,
    rrd: Path | None = None,
    write_rrd: bool = True,
    progress: Progress | None = None,
    lidar: str | None = None,
    avia: str | None = None,
    truth: str | None = None,
    model: LearnedModel | None = None,
    live: LiveOutput | None = None,
) -> AnnotateReport:
    """Estimate the drone's position at every Mid-360 frame of ``log`` and write the results back.

    Args:
        log: an MCAP log: written by ``cldet convert`` (``/lidar_360``, with ``/livox_avia`` and
            ``/ground_truth`` when present) or recorded with ROS (point clouds as
            ``sensor_msgs/msg/PointCloud2`` or Livox ``CustomMsg``, see
            :mod:`cldet.io.sources`). Never damaged: results go to a temporary file renamed over
            ``output`` only when complete.
        config: the estimator configuration (defaults when None).
        output: where the annotated log goes; default ``log`` itself (rewritten in place).
        rrd: the Rerun review recording; default ``output`` with suffix ``.rrd``.
        write_rrd: False skips the recording.
        progress: receives one unit per frame.
        lidar: the LiDAR's point-cloud topic (default: ``/lidar_360``, else the log's only
            point-cloud topic).
        avia: the Avia's point-cloud topic, fused with the LiDAR's (default: ``/livox_avia``
            with ``/lidar_360``, else none).
        truth: a ground-truth position topic for the reported error (default:
            ``/ground_truth`` when present).
        model: a model from ``cldet train`` (``track`` only): its scan-time offset and bias
            replace the configuration's, its scorer picks the drone's tracks and its classifier
            writes ``/cldet/class``.
        live: stream each frame as it is processed (and the refined track at the end) to a
            Rerun viewer and/or a Foxglove server (:mod:`cldet.live`), paced at the sensor's
            rate when it says so; the outputs are written as without it.

    Returns:
        An :class:`AnnotateReport`.

    Raises:
        LogError: the log cannot be read, a topic is missing or of another type, no (or more
            than one) topic could be the LiDAR; CorruptMessageError: a message is malformed.
        OutputError: an output cannot be written there (checked before any work).
    """
    started = time.perf_counter()
    config = config or CldetConfig()
    if model is not None:
        config = model.configure(config)
    progress = progress or NullProgress()
    log = Path(log)
    output = Path(output) if output is not None else log
    check_output(output, "annotated log")  # up front: fail before any work
    if write_rrd:
        check_output(Path(rrd) if rrd is not None else output.with_suffix(".rrd"), "recording")
    with open_log(log) as reader:
        found = reader.list_topics()
        source_meta = reader.metadata().get(topics.METADATA_SOURCE, {})
        sensors = select_topics(reader, lidar, avia, truth)
        tree, tf_taken = _existing_tree(reader)
        first_ns = reader.time_range()[0]
    n_frames = found[sensors.lidar]
    sequence = source_meta.get("sequence", log.stem)
    split = source_meta.get("split", "")

    view: View = NullView()
    live_rerun = live.rerun if live is not None else None
    if write_rrd or live_rerun is not None:
        rrd_path = Path(rrd) if rrd is not None else output.with_suffix(".rrd")
        view = RerunView(
            rrd_path if write_rrd else None,
            recording_name=f"cldet {split + '/' if split else ''}{sequence}",
            application_id=review_application_id(log, split, sequence),
            sensor=config.sensor,
            max_range_m=config.frames.max_range_m,
            live=live_rerun,
        )
    foxglove_view = (
        live.foxglove_view(config.sensor, _lidar_frame_id(log, sensors.lidar))
        if live is not None
        else None
    )
    if foxglove_view is not None:
        view = TeeView(view, foxglove_view)
    # every frame's foreground and clusters, on disk until the results are written: memory
    # does not grow with the sequence's length
    detections: Spool[FrameDetections] = Spool()
    stamps: list[int] = []  # each detection's stamp, kept in memory (8 bytes a frame)
    try:
        estimator = make_estimator(config, model)
        progress.start(n_frames, f"{sequence}: tracking")
        lidar_frame: list[str] = []
        truths: list[PositionSample] = []  # read in the same pass as the frames
        try:
            for frame in read_frames(log, sensors, config.frames, lidar_frame, truths):
                check_terminated()  # SIGTERM, should a C callback have swallowed its exception
                if live is not None:
                    live.pace(frame.stamp_ns)
                in_hand = time.perf_counter()
                found_here = estimator.register_frame(frame)
                detections.append(found_here)
                stamps.append(found_here.stamp_ns)
                view.log_frame(frame, found_here)
                if live is not None:
                    live.frame_done(frame.stamp_ns, time.perf_counter() - in_hand)
                progress.advance()
        except FrameOrderError as err:
            raise FrameOrderError(f"{log}: {err}") from err
        result = estimator.refine()
        view.log_result(result, detections)
        rms_m: float | None = None
        truth_xyz: NDArray[np.float64] | None = None
        if truths:
            truth_ns = np.array([t.stamp_ns for t in truths], dtype=np.int64)
            truth_xyz = np.array([t.position for t in truths], dtype=np.float64)
            errors = _truth_errors(result.estimates, truth_ns, truth_xyz)
            view.log_truth(truth_ns, truth_xyz, errors, _estimates_at(result.estimates, truth_ns))
            rms_m = None if errors is None else rms(errors)
        frame_id = lidar_frame[0] if lidar_frame else topics.FRAME_MID360
        additions = result_additions(
            result, detections, frame_id=frame_id, truth=truth_xyz, stamps=stamps
        )
        if tree is None:  # a log without a frame tree gets one (replaced by the next run)
            additions.append((first_ns, _tree_writer(tf_taken, frame_id, config.sensor, first_ns)))
        metadata = {
            METADATA_ANNOTATE: {
                "method": config.method,
                "config": json.dumps(config_to_dict(config), sort_keys=True),
                "cldet_version": __version__,
                "sequence": sequence,
                "frames": str(len(detections)),
                "lidar": sensors.lidar,
                "avia": sensors.avia or "",
                "truth": sensors.truth or "",
                "model": "" if model is None else json.dumps(model.describe_source()),
            }
        }
        rewrite_log(
            log,
            output,
            additions,
            metadata=metadata,
            replace_metadata=(METADATA_ANNOTATE,),
        )
        rrd_written = view.close()
    except BaseException:
        view.abort()
        raise
    finally:
        detections.close()
    sources = {s.name.lower(): 0 for s in Source}
    for estimate in result.estimates:
        sources[estimate.source.name.lower()] += 1
    return AnnotateReport(
        log=log,
        output=output,
        rrd=rrd_written,
        sequence=sequence,
        frames=len(detections),
        sources=sources,
        seconds=time.perf_counter() - started,
        rms_error_m=rms_m,
    )


def _truth_errors(
    estimates: Sequence[Estimate], truth_ns: np.ndarray, truth_xyz: np.ndarray
) -> np.ndarray | None:
    """(K,) 3D distance, metres, of the estimated trajectory to the truth at its K stamps."""
    if not estimates:
        return None
    stamps = np.array([e.stamp_ns for e in estimates], dtype=np.int64)
    positions = np.array([e.position for e in estimates], dtype=np.float64)
    return trajectory_errors(truth_ns, truth_xyz, stamps, positions)


def review_application_id(log: Path, split: str, sequence: str) -> str:
    """The Rerun application id of a log's review recording: one per log, so that the viewer
    keeps a blueprint per log (not one shared by every ``seq0001`` of every split)."""
    digest = hashlib.sha1(str(Path(log).resolve()).encode()).hexdigest()[:8]
    return "-".join(p for p in ("cldet", split, sequence, digest) if p)


def _estimates_at(
    estimates: Sequence[Estimate], stamps_ns: NDArray[np.int64]
) -> NDArray[np.float64] | None:
    """(K, 3) the estimated trajectory at ``stamps_ns`` (None without estimates)."""
    from cldet.core.trajectory import evaluate_trajectory

    if not estimates:
        return None
    stamps = np.array([e.stamp_ns for e in estimates], dtype=np.int64)
    positions = np.array([e.position for e in estimates], dtype=np.float64)
    return np.asarray(evaluate_trajectory(stamps, positions, stamps_ns), dtype=np.float64)


def _lidar_frame_id(log: Path, topic: str) -> str:
    """The frame id of the LiDAR's first cloud (the Mid-360's when the topic is empty)."""
    for cloud in iter_log_clouds(log, topic):
        return cloud.frame_id or topics.FRAME_MID360
    return topics.FRAME_MID360


def _existing_tree(reader: LogReader) -> tuple[list[FrameTransform] | None, bool]:
    """The log's own static frame tree (``foxglove.FrameTransforms`` on channels that are not
    results of an earlier run; None without one), and whether its ``/tf`` topic is taken by
    such a channel (e.g. ROS transforms)."""
    kinds = reader.topic_types()
    wanted = [t for t, kind in kinds.items() if kind == topics.SCHEMA_FRAME_TRANSFORMS]
    if topics.TF in kinds and topics.TF not in wanted:
        wanted.append(topics.TF)
    out: list[FrameTransform] = []
    tf_taken = False
    tf_seen = False
    for _, channel, message in reader.iter_messages(wanted) if wanted else ():
        if is_replaced_channel(channel, "/cldet/"):
            tf_seen = tf_seen or channel.topic == topics.TF
            continue
        if channel.topic == topics.TF:
            tf_taken = tf_seen = True
        if kinds.get(channel.topic) == topics.SCHEMA_FRAME_TRANSFORMS:
            for t in FrameTransforms.FromString(message.data).transforms:
                out.append(FrameTransform(t.parent_frame_id, t.child_frame_id, np.eye(4)))
    if topics.TF in kinds and not tf_seen:
        tf_taken = True  # a /tf channel without messages: leave it alone
    return out or None, tf_taken


def _tree_writer(tf_taken: bool, lidar_frame: str, sensor: SensorConfig, stamp_ns: int) -> Addition:
    """Writes the frame tree of a log that has none, on ``/tf`` (``/cldet/tf`` when the log's
    ``/tf`` is taken, e.g. by ROS transforms), marked as a result."""
    topic = "/cldet/tf" if tf_taken else topics.TF
    tree = log_tree(lidar_frame, sensor)

    def write(writer: LogWriter) -> None:
        writer.write_transforms(
            topic, stamp_ns, tree, channel_metadata={topics.RESULT_CHANNEL_KEY: "annotate"}
        )

    return write


def annotate_log_locked(
    log: Path,
    *,
    config: CldetConfig | None = None,
    output: Path | None = None,
    rrd: Path | None = None,
    write_rrd: bool = True,
    force: bool = False,
    progress: Progress | None = None,
    lidar: str | None = None,
    avia: str | None = None,
    truth: str | None = None,
    model: LearnedModel | None = None,
    live: LiveOutput | None = None,
) -> AnnotateReport:
    """:func:`annotate_log` while holding an exclusive lock on the log (a second run refuses).

    Args:
        force: rewrite an output that is read-only (its mode is kept); otherwise refused.
        others: as :func:`annotate_log`.

    Raises:
        OutputError: another process is annotating the log; the output is read-only and
            ``force`` is false; as :func:`annotate_log`.
    """
    check_output(output if output is not None else log, "annotated log", force=force)
    with lock_file(log, "log"):
        return annotate_log(
            log,
            config=config,
            output=output,
            rrd=rrd,
            write_rrd=write_rrd,
            progress=progress,
            lidar=lidar,
            avia=avia,
            truth=truth,
            model=model,
            live=live,
        )


@dataclass(frozen=True)
class _AnnotateJob:
    """One log of :func:`annotate_logs`, as a worker receives it."""

    log: Path
    output: Path
    config: CldetConfig | None
    write_rrd: bool
    force: bool
    lidar: str | None
    avia: str | None
    truth: str | None
    model: LearnedModel | None
    per_frame: bool  # report progress per frame (one log at a time, in this process)


def _annotate_job(job: _AnnotateJob, progress: Progress) -> AnnotateReport:
    """:func:`annotate_log_locked` on one job (runs in a worker process or a Ray task)."""
    return annotate_log_locked(
        job.log,
        config=job.config,
        output=job.output,
        write_rrd=job.write_rrd,
        force=job.force,
        progress=progress if job.per_frame else None,
        lidar=job.lidar,
        avia=job.avia,
        truth=job.truth,
        model=job.model,
    )


def annotate_logs(
    logs: Sequence[Path],
    *,
    config: CldetConfig | None = None,
    outputs: Sequence[Path] | None = None,
    write_rrd: bool = True,
    workers: int | None = 1,
    force: bool = False,
    progress: Progress | None = None,
    lidar: str | None = None,
    avia: str | None = None,
    truth: str | None = None,
    model: LearnedModel | None = None,
    executor: str = "local",
    ray_address: str | None = None,
) -> tuple[list[AnnotateReport], list[tuple[Path, str]]]:
    """Annotate several logs, in parallel when ``workers > 1`` or on Ray.

    One failing log is reported and the others still run. Each log is locked while it is
    annotated (:func:`annotate_log_locked`). On Ctrl-C or SIGTERM the workers (or Ray tasks) are
    stopped and remove their temporary files; a local worker stops by itself when this process
    dies. Both executors write the same outputs, byte for byte.

    Args:
        logs: the MCAP logs.
        config: the estimator configuration (defaults when None).
        outputs: one output path per log (default: each log rewritten in place).
        write_rrd: write a ``.rrd`` beside each output.
        workers: logs annotated at once (None: every CPU, here or of the Ray cluster); 1 with
            the ``local`` executor runs in this process (with per-frame progress).
        force: rewrite read-only logs (their mode is kept).
        progress: one unit per frame (one log at a time, in this process) or per log.
        lidar, avia, truth: the topics to read in every log (as :func:`annotate_log`).
        model: a model from ``cldet train`` (as :func:`annotate_log`).
        executor: ``local`` (worker processes here) or ``ray`` (a Ray task per log; see
            :mod:`cldet.executors`).
        ray_address: with ``ray``, the cluster to join (default: a local Ray for the run).

    Returns:
        (reports of the logs done, in the order given; (log, error message) of those that
        failed with a :class:`CldetError`, in the order given).

    Raises:
        ExecutorError: an unknown executor, Ray missing or unreachable, a worker process died.
        Any other error of one log (an ``OSError``, a bug) is raised here, with the worker's
        traceback as its cause, and the logs still running are stopped.
    """
    if outputs is not None and len(outputs) != len(logs):
        raise CldetError(f"{len(outputs)} output paths for {len(logs)} logs")
    targets = list(outputs) if outputs is not None else [Path(log) for log in logs]
    progress = progress or NullProgress()
    per_frame = runs_here(len(logs), workers, executor)
    jobs = [
        _AnnotateJob(
            Path(log), Path(target), config, write_rrd, force, lidar, avia, truth, model, per_frame
        )
        for log, target in zip(logs, targets, strict=True)
    ]
    done: dict[int, AnnotateReport] = {}
    failed: dict[int, str] = {}
    if not per_frame:
        progress.start(len(logs), "annotating")
    outcomes = iter_outcomes(
        _annotate_job,
        jobs,
        workers=workers,
        executor=executor,
        ray_address=ray_address,
        progress=progress,
        costs=[file_size(job.log) for job in jobs],  # the longest logs first
    )
    with closing(outcomes):
        for outcome in outcomes:
            if outcome.result is not None:
                done[outcome.index] = outcome.result
            elif isinstance(outcome.error, CldetError):
                failed[outcome.index] = str(outcome.error)
            else:  # a crash (a bug, a full disk): raised here, the other logs are stopped
                outcome.raise_error()
            if not per_frame:
                progress.advance()
    failures = [(Path(logs[i]), failed[i]) for i in sorted(failed)]
    return [done[i] for i in sorted(done)], failures
