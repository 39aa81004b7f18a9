"""The Rerun review recording of an annotate run, and a do-nothing view for runs without one.

Entity layout (timeline ``timestamp``, ns; the same name Rerun's own MCAP import uses). Every
position is in the Mid-360's frame (metres, z up):

- ``world``                      static: right-handed, z up; the class colours of the foreground
- ``world/lidar/mid360``         valid Mid-360 points per frame within the configured range (grey)
- ``world/lidar/avia``           valid Avia points per frame within the configured range (blue)
- ``world/foreground``           foreground points, coloured by cluster id; noise grey
- ``world/clusters``             one box per cluster but the drone's (at least 0.2 m a side),
                                 labelled with its point count
- ``world/drone/chosen``         the box of the cluster chosen as the drone in that frame
- ``world/drone/estimate``       the estimate at each frame (colour by source), labelled
- ``world/drone/trajectory``     the smoothed estimated trajectory (static line strip)
- ``world/truth/position``       ground truth at its own stamps (when the log has it), labelled
- ``world/truth/error``          a line from the truth to the estimate at the truth's stamps
- ``world/truth/trajectory``     the ground-truth trajectory (static line strip)
- ``plots/error_m``              3D distance estimate - truth at the truth stamps
- ``drone/type``                 the drone type, with a ``cldet train`` model (``/cldet/class``)
- ``events``                     text log of track events (acquired, lost, re-acquired, predicted)

The blueprint is sent when the recording closes, once what it holds is known: a 3D view whose
camera looks at where the drone flew (not at far outliers), and beside it only the panels that
have something to show (error plot with a ground truth, drone type with a class, events). Each
log gets its own application id, so the viewer keeps a blueprint per log.

Per-frame clouds are buffered and sent as columns every few dozen frames: far cheaper than one
``log`` call per entity per frame (every frame when streaming live).
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from cldet.colours import CHOSEN_RGBA, SOURCE_RGBA, TRACK_RGBA
from cldet.config import SensorConfig
from cldet.io.files import atomic_path
from cldet.types import Cluster, Estimate, LidarFrame

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb

    from cldet.core.estimator import FrameDetections, SequenceEstimate

TIMELINE = "timestamp"
DEFAULT_GRPC_URL = "rerun+http://127.0.0.1:9876/proxy"
_FLUSH_EVERY = 64  # frames buffered before a send_columns batch

# Colours (RGBA) of fixed layers; those of estimates, track and chosen cluster: cldet.colours.
_MID360_COLOUR = (150, 150, 150, 255)
_AVIA_COLOUR = (90, 140, 255, 255)
_NOISE_COLOUR = (120, 120, 120, 255)
_TRUTH_COLOUR = (255, 225, 0, 255)
_ERROR_COLOUR = (255, 60, 60, 255)
_CLUSTER_COLOUR = (200, 200, 60, 255)
_N_CLUSTER_COLOURS = 12
NOISE_CLASS = 255  # class id of noise points (grey, no label)
MIN_BOX_HALF_M = 0.1  # boxes are at least 0.2 m a side: a one-point cluster stays visible
_MIN_VIEW_DISTANCE_M = 6.0


class View(Protocol):
    """What the annotate pipeline tells a review recording."""

    def log_frame(self, frame: LidarFrame, detections: FrameDetections) -> None:
        """One processed frame: its clouds, foreground, clusters and causal estimate."""

    def log_result(self, result: SequenceEstimate, detections: Sequence[FrameDetections]) -> None:
        """The sequence's estimates, trajectory, chosen clusters and track events."""

    def log_truth(
        self,
        stamps_ns: NDArray[np.int64],
        positions: NDArray[np.float64],
        errors_m: NDArray[np.float64] | None,
        estimated: NDArray[np.float64] | None = None,
    ) -> None:
        """The ground truth, the 3D error of the estimates at its stamps and the estimates
        there, (K, 3) (None: no estimate)."""

    def close(self) -> Path | None:
        """Finish the recording; returns its path (None when nothing is written)."""

    def abort(self) -> None:
        """Drop a recording whose run failed (no partial file is left)."""


class NullView:
    """A view that records nothing (``--no-rrd``)."""

    def log_frame(self, frame: LidarFrame, detections: FrameDetections) -> None:
        """Do nothing."""

    def log_result(self, result: SequenceEstimate, detections: Sequence[FrameDetections]) -> None:
        """Do nothing."""

    def log_truth(
        self,
        stamps_ns: NDArray[np.int64],
        positions: NDArray[np.float64],
        errors_m: NDArray[np.float64] | None,
        estimated: NDArray[np.float64] | None = None,
    ) -> None:
        """Do nothing."""

    def close(self) -> Path | None:
        """Nothing was written."""
        return None

    def abort(self) -> None:
        """Nothing to drop."""


class TeeView:
    """Tells several views the same things (the review file and a live stream)."""

    def __init__(self, *views: View) -> None:
        self.views = views

    def log_frame(self, frame: LidarFrame, detections: FrameDetections) -> None:
        """Every view logs the frame."""
        for view in self.views:
            view.log_frame(frame, detections)

    def log_result(self, result: SequenceEstimate, detections: Sequence[FrameDetections]) -> None:
        """Every view logs the result."""
        for view in self.views:
            view.log_result(result, detections)

    def log_truth(
        self,
        stamps_ns: NDArray[np.int64],
        positions: NDArray[np.float64],
        errors_m: NDArray[np.float64] | None,
        estimated: NDArray[np.float64] | None = None,
    ) -> None:
        """Every view logs the truth."""
        for view in self.views:
            view.log_truth(stamps_ns, positions, errors_m, estimated)

    def close(self) -> Path | None:
        """Close every view; the first path any of them wrote."""
        paths = [view.close() for view in self.views]
        return next((p for p in paths if p is not None), None)

    def abort(self) -> None:
        """Abort every view."""
        for view in self.views:
            with contextlib.suppress(Exception):
                view.abort()


def drone_type_text(result: SequenceEstimate) -> str | None:
    """The drone type line of a review: the last (final) ``/cldet/class`` estimate of a run with
    a ``cldet train`` model, with its probability; None without one."""
    if not result.classes:
        return None
    final = result.classes[-1]
    text = f"drone type {final.class_id}"
    probabilities = dict(zip(final.class_ids, final.probabilities, strict=False))
    if final.class_id in probabilities:
        text += f" (p = {probabilities[final.class_id]:.2f})"
    return text


def camera_for(
    positions: NDArray[np.float64] | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(eye, look target) of a 3D view framing where the drone flew (Mid-360 frame, metres).

    The target is the median position of the track; the eye stands back from it towards the
    sensor and 30 degrees up, far enough to see the middle 90% of the track (at least 6 m).
    Without positions: the sensor's surroundings, seen from behind and above.
    """
    if positions is None or len(positions) == 0:
        target = np.zeros(3)
        return np.array([-12.0, -12.0, 9.0]), target
    pts = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    target = np.median(pts, axis=0)
    low, high = np.percentile(pts, [5, 95], axis=0)
    distance = max(2.0 * float(np.linalg.norm(high - low)), _MIN_VIEW_DISTANCE_M)
    back = -target[:2]
    norm = float(np.linalg.norm(back))
    back = back / norm if norm > 1e-6 else np.array([-1.0, 0.0])
    direction = np.array([back[0] * np.cos(np.pi / 6), back[1] * np.cos(np.pi / 6), 0.5])
    return target + distance * direction, target


def _time_column(stamps_ns: NDArray[np.int64] | Sequence[int]) -> rr.TimeColumn:
    import rerun as rr

    return rr.TimeColumn(
        TIMELINE, timestamp=np.asarray(stamps_ns, dtype=np.int64).astype("datetime64[ns]")
    )


def _within(points: NDArray[np.float32], max_range_m: float) -> NDArray[np.float32]:
    """The rows of (N, 3) ``points`` within ``max_range_m`` of the sensor."""
    if not len(points) or not np.isfinite(max_range_m):
        return points
    keep = np.einsum("ij,ij->i", points, points) <= max_range_m * max_range_m
    return points if keep.all() else points[keep]


def min_half_sizes(lower: NDArray[np.float64], upper: NDArray[np.float64]) -> NDArray[np.float64]:
    """Half sizes of a box from ``lower`` to ``upper``, at least :data:`MIN_BOX_HALF_M`."""
    half = (np.asarray(upper, np.float64) - np.asarray(lower, np.float64)) / 2.0
    return np.maximum(half, MIN_BOX_HALF_M)


class _CloudBuffer:
    """Per-frame point clouds collected for one entity and sent as one column batch."""

    def __init__(self) -> None:
        self.stamps: list[int] = []
        self.points: list[NDArray[np.float32]] = []
        self.class_ids: list[NDArray[np.int32]] = []

    def add(
        self, stamp_ns: int, points: NDArray[np.float32], class_ids: NDArray[np.int32] | None = None
    ) -> None:
        self.stamps.append(stamp_ns)
        self.points.append(points)
        if class_ids is not None:
            self.class_ids.append(class_ids)

    def send(self, rec: rr.RecordingStream, path: str) -> None:
        """Send the buffered frames as one column batch (colours come from static styling)."""
        import rerun as rr

        if not self.stamps:
            return
        lengths = [len(p) for p in self.points]
        positions = np.concatenate(self.points)
        if self.class_ids:
            columns = rr.Points3D.columns(
                positions=positions, class_ids=np.concatenate(self.class_ids)
            )
        else:
            columns = rr.Points3D.columns(positions=positions)
        rec.send_columns(
            path, indexes=[_time_column(self.stamps)], columns=columns.partition(lengths)
        )
        self.stamps.clear()
        self.points.clear()
        self.class_ids.clear()


class RerunView:
    """The review recording: a ``.rrd`` written atomically, and/or a live stream to a viewer.

    Args:
        path: the ``.rrd`` (written to a temporary file beside it, renamed on close); None
            writes no file (a live stream only).
        recording_name: shown in the viewer.
        application_id: one per log (see :func:`cldet.pipeline.review_application_id`), so the
            viewer keeps a blueprint per log.
        recording_id: None: a fresh id.
        sensor: the sensor's height draws the ground grid.
        max_range_m: points farther than this are not logged (far outliers).
        live: also stream to a Rerun viewer: ``"spawn"`` starts one, otherwise a gRPC URL such
            as :data:`DEFAULT_GRPC_URL`; frames are then sent as they come.
    """

    def __init__(
        self,
        path: Path | None,
        *,
        recording_name: str,
        application_id: str = "cldet",
        recording_id: str | None = None,
        sensor: SensorConfig | None = None,
        max_range_m: float = float("inf"),
        live: str | None = None,
    ) -> None:
        import rerun as rr

        self.path = path
        self._sensor = sensor or SensorConfig()
        self._max_range_m = max_range_m
        self._stack = contextlib.ExitStack()
        self._tmp: Path | None = None
        if path is not None:
            self._tmp = self._stack.enter_context(atomic_path(path, overwrite=True))
        self._rec = rr.RecordingStream(application_id, recording_id=recording_id)
        sinks: list[Any] = []
        if live is not None:
            url = live
            if live == "spawn":
                rr.spawn(connect=False)
                url = DEFAULT_GRPC_URL
            sinks.append(rr.GrpcSink(url))
        if self._tmp is not None:
            sinks.append(rr.FileSink(self._tmp))
        self._rec.set_sinks(*sinks)
        self._live = live is not None
        self._flush_every = 1 if self._live else _FLUSH_EVERY
        self._rec.send_recording_name(recording_name)
        self._mid360 = _CloudBuffer()
        self._avia = _CloudBuffer()
        self._foreground = _CloudBuffer()
        self._boxes: list[tuple[int, NDArray[np.float64], NDArray[np.float64], list[str]]] = []
        self._causal: list[tuple[int, Estimate]] = []
        self._track: NDArray[np.float64] | None = None
        self._has_truth_errors = False
        self._drone_type: str | None = None
        self._has_events = False
        self._closed = False
        self._log_static()
        if self._live:  # the live viewer gets a layout at once; the final one at close
            self._rec.send_blueprint(self._blueprint(), make_active=True, make_default=True)

    def _log_static(self) -> None:
        import rerun as rr

        rec = self._rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        palette = _cluster_palette()
        infos = [rr.AnnotationInfo(id=i, color=palette[i]) for i in range(_N_CLUSTER_COLOURS)]
        infos.append(rr.AnnotationInfo(id=NOISE_CLASS, color=_NOISE_COLOUR[:3]))
        rec.log("world", rr.AnnotationContext(infos), static=True)
        rec.log(
            "world/lidar/mid360",
            rr.Points3D.from_fields(radii=-1.5, colors=_MID360_COLOUR),
            static=True,
        )
        rec.log(
            "world/lidar/avia",
            rr.Points3D.from_fields(radii=-2.0, colors=_AVIA_COLOUR),
            static=True,
        )
        rec.log("world/foreground", rr.Points3D.from_fields(radii=-3.0), static=True)

    def log_frame(self, frame: LidarFrame, detections: FrameDetections) -> None:
        """Buffer one frame's clouds, foreground (by cluster id), cluster boxes, causal estimate."""
        stamp = frame.stamp_ns
        self._mid360.add(stamp, _within(frame.mid360, self._max_range_m))
        self._avia.add(stamp, _within(frame.avia, self._max_range_m))
        labels = np.asarray(detections.labels, dtype=np.int32)
        self._foreground.add(
            stamp,
            detections.foreground,
            np.where(labels < 0, NOISE_CLASS, labels % _N_CLUSTER_COLOURS).astype(np.int32),
        )
        if self._live:  # live: every cluster now (the file: in log_result, but the drone's)
            self._add_boxes(stamp, detections.clusters)
            if detections.estimate is not None:
                self._causal.append((stamp, detections.estimate))
        if len(self._mid360.stamps) >= self._flush_every:
            self._flush()

    def _add_boxes(self, stamp_ns: int, clusters: Sequence[Cluster]) -> None:
        if not clusters:
            return
        centres = np.array([c.centroid for c in clusters], dtype=np.float64)
        halves = np.array([min_half_sizes(c.lower, c.upper) for c in clusters], dtype=np.float64)
        self._boxes.append((stamp_ns, centres, halves, [_points(c.n_points) for c in clusters]))

    def _flush(self) -> None:
        import rerun as rr

        self._mid360.send(self._rec, "world/lidar/mid360")
        self._avia.send(self._rec, "world/lidar/avia")
        self._foreground.send(self._rec, "world/foreground")
        if self._boxes:
            stamps = [b[0] for b in self._boxes]
            lengths = [len(b[1]) for b in self._boxes]
            columns = rr.Boxes3D.columns(
                centers=np.concatenate([b[1] for b in self._boxes]),
                half_sizes=np.concatenate([b[2] for b in self._boxes]),
                labels=[t for b in self._boxes for t in b[3]],
                colors=np.tile(np.array(_CLUSTER_COLOUR, np.uint8), (sum(lengths), 1)),
            )
            self._rec.send_columns(
                "world/clusters", indexes=[_time_column(stamps)], columns=columns.partition(lengths)
            )
            self._boxes.clear()
        if self._causal:  # live only: the causal estimate as it is made
            self._send_estimates("world/drone/estimate", [e for _, e in self._causal])
            self._causal.clear()

    def _send_estimates(self, path: str, estimates: Sequence[Estimate]) -> None:
        import rerun as rr

        stamps = np.array([e.stamp_ns for e in estimates], dtype=np.int64)
        positions = np.array([e.position for e in estimates], dtype=np.float64)
        colours = np.array([SOURCE_RGBA[e.source] for e in estimates], dtype=np.uint8)
        labels = [
            f"drone: {e.source.name.lower()}"
            + (f", {_points(e.n_points)}" if e.n_points else "")
            + f", ±{e.sigma_m:.2f} m"
            for e in estimates
        ]
        self._rec.send_columns(
            path,
            indexes=[_time_column(stamps)],
            columns=rr.Points3D.columns(
                positions=positions,
                colors=colours,
                radii=np.full(len(stamps), 0.2, np.float32),
                labels=labels,
            ),
        )

    def log_result(self, result: SequenceEstimate, detections: Sequence[FrameDetections]) -> None:
        """Send the estimates (coloured by source), the trajectory, chosen boxes, the event log
        and the drone type (when the results carry one)."""
        import rerun as rr

        self._flush()
        rec = self._rec
        estimates: Sequence[Estimate] = result.estimates
        if estimates:
            self._send_estimates("world/drone/estimate", estimates)
            positions = np.array([e.position for e in estimates], dtype=np.float64)
            self._track = positions
            rec.log(
                "world/drone/trajectory",
                rr.LineStrips3D([positions], colors=[TRACK_RGBA], radii=[0.04]),
                static=True,
            )
        chosen: list[tuple[int, Cluster]] = []
        for det in detections:  # one pass: ``detections`` may live on disk
            chosen_id = result.chosen.get(det.stamp_ns)
            if chosen_id is not None and 0 <= chosen_id < len(det.clusters):
                chosen.append((det.stamp_ns, det.clusters[chosen_id]))
            if not self._live:  # the boxes of every frame, but the drone's (it has its own)
                self._add_boxes(
                    det.stamp_ns, [c for c in det.clusters if c.cluster_id != chosen_id]
                )
        self._flush()
        if chosen:
            rec.send_columns(
                "world/drone/chosen",
                indexes=[_time_column([s for s, _ in chosen])],
                columns=rr.Boxes3D.columns(
                    centers=np.array([c.centroid for _, c in chosen]),
                    half_sizes=np.array([min_half_sizes(c.lower, c.upper) for _, c in chosen])
                    + 0.05,
                    colors=np.tile(np.array(CHOSEN_RGBA, np.uint8), (len(chosen), 1)),
                ),
            )
        if result.events:
            self._has_events = True
            rec.send_columns(
                "events",
                indexes=[_time_column([e.stamp_ns for e in result.events])],
                columns=rr.TextLog.columns(
                    text=[f"{e.kind}: {e.text}" for e in result.events],
                    level=["WARN" if e.kind == "lost" else "INFO" for e in result.events],
                ),
            )
        text = drone_type_text(result)
        if text is not None:
            self._drone_type = text
            rec.log("drone/type", rr.TextDocument(text), static=True)

    def log_truth(
        self,
        stamps_ns: NDArray[np.int64],
        positions: NDArray[np.float64],
        errors_m: NDArray[np.float64] | None,
        estimated: NDArray[np.float64] | None = None,
    ) -> None:
        """Send the ground truth (labelled), its error lines and the error over time."""
        import rerun as rr

        if len(stamps_ns) == 0:
            return
        rec = self._rec
        n = len(positions)
        rec.send_columns(
            "world/truth/position",
            indexes=[_time_column(stamps_ns)],
            columns=rr.Points3D.columns(
                positions=positions,
                colors=np.tile(np.asarray(_TRUTH_COLOUR, np.uint8), (n, 1)),
                radii=np.full(n, 0.2, np.float32),
                labels=["truth"] * n,
            ),
        )
        rec.log(
            "world/truth/trajectory",
            rr.LineStrips3D([positions], colors=[_TRUTH_COLOUR], radii=[0.03]),
            static=True,
        )
        if estimated is not None and len(estimated) == n:
            strips = np.stack([positions, np.asarray(estimated, np.float64)], axis=1)  # (K, 2, 3)
            rec.send_columns(
                "world/truth/error",
                indexes=[_time_column(stamps_ns)],
                columns=rr.LineStrips3D.columns(
                    strips=list(strips),
                    colors=np.tile(np.asarray(_ERROR_COLOUR, np.uint8), (n, 1)),
                    radii=np.full(n, 0.03, np.float32),
                ),
            )
        if errors_m is not None:
            self._has_truth_errors = True
            rec.log(
                "plots/error_m",
                rr.SeriesLines(names="3D error (m)", colors=_ERROR_COLOUR),
                static=True,
            )
            rec.send_columns(
                "plots/error_m",
                indexes=[_time_column(stamps_ns)],
                columns=rr.Scalars.columns(scalars=errors_m),
            )

    def _blueprint(self) -> rrb.Blueprint:
        """A 3D view looking at the track, and only the side panels that have something."""
        import rerun as rr
        import rerun.blueprint as rrb

        eye, target = camera_for(self._track)
        scene = rrb.Spatial3DView(
            name="scene",
            origin="world",
            eye_controls=rrb.EyeControls3D(
                position=eye.tolist(), look_target=target.tolist(), eye_up=[0.0, 0.0, 1.0]
            ),
            line_grid=rrb.LineGrid3D(
                visible=True,
                spacing=1.0,
                plane=rr.components.Plane3D.XY.with_distance(-self._sensor.height_m),
            ),
        )
        side: list[Any] = []
        if self._drone_type is not None:
            side.append(rrb.TextDocumentView(name="drone type", origin="drone/type"))
        if self._has_truth_errors:
            side.append(rrb.TimeSeriesView(name="position error (m)", origin="plots"))
        if self._has_events:
            side.append(rrb.TextLogView(name="track events", origin="events"))
        if not side:
            return rrb.Blueprint(scene, collapse_panels=True)
        return rrb.Blueprint(
            rrb.Horizontal(scene, rrb.Vertical(*side), column_shares=[3, 1]),
            collapse_panels=True,
        )

    def close(self) -> Path | None:
        """Flush everything, send the blueprint, close the file and rename it into place."""
        if not self._closed:
            self._flush()
            self._rec.send_blueprint(self._blueprint(), make_active=True, make_default=True)
            self._rec.flush()
            self._rec.disconnect()
            self._closed = True
            self._stack.close()  # fsync, the umask's mode, rename (removed on failure)
        return self.path

    def abort(self) -> None:
        """Close the stream and delete the temporary file."""
        if not self._closed:
            self._closed = True
            try:
                self._rec.disconnect()
            finally:
                error = RuntimeError("review recording aborted")
                self._stack.__exit__(type(error), error, None)  # removes the temporary file


def _points(n: int) -> str:
    return f"{n} pt" if n == 1 else f"{n} pts"


def _cluster_palette() -> list[tuple[int, int, int]]:
    """Distinct colours for cluster ids (noise has its own grey class)."""
    base = [
        (230, 25, 75), (60, 180, 75), (255, 225, 25), (0, 130, 200), (245, 130, 48), (145, 30, 180),
        (70, 240, 240), (240, 50, 230), (210, 245, 60), (250, 190, 212), (0, 128, 128), (220, 190, 255),
    ]  # fmt: skip
    return base[:_N_CLUSTER_COLOURS]
