"""The Rerun review recording of an annotate run, and a do-nothing view for runs without one.

Entity layout (timeline ``timestamp``, ns; the same name Rerun's own MCAP import uses):

- ``world``                      static: right-handed, z up (the Mid-360 frame)
- ``world/lidar/mid360``         valid Mid-360 points per frame (grey)
- ``world/lidar/avia``           valid Avia points per frame (blue)
- ``world/foreground``           foreground points, coloured by cluster id (class ids)
- ``world/clusters``             one box per cluster, labelled with its id and point count
- ``world/drone/chosen``         the box of the cluster chosen as the drone in that frame
- ``world/drone/estimate``       the estimate at each frame (colour by source)
- ``world/drone/trajectory``     the smoothed estimated trajectory (static line strip)
- ``world/truth/position``       ground truth at its own stamps (when the log has it)
- ``world/truth/trajectory``     the ground-truth trajectory (static line strip)
- ``plots/error_m``              3D distance estimate - truth at the truth stamps
- ``events``                     text log of track events (acquired, lost, re-acquired, predicted)

Per-frame clouds are buffered and sent as columns every few dozen frames: far cheaper than one
``log`` call per entity per frame. Only valid points are logged (the zero rows never reach here).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import NDArray

from cldet.io.files import commit, remove_stale_temporaries, resolve_link, temporary_path
from cldet.types import Estimate, LidarFrame, Source

if TYPE_CHECKING:
    import rerun as rr

    from cldet.core.estimator import FrameDetections, SequenceEstimate

TIMELINE = "timestamp"
_FLUSH_EVERY = 64  # frames buffered before a send_columns batch

# Colours (RGBA): sources of estimates, and fixed layers.
_SOURCE_COLOURS = {
    Source.DETECTED: (40, 220, 60, 255),
    Source.PREDICTED: (255, 170, 0, 255),
    Source.SMOOTHED: (80, 200, 255, 255),
    Source.FALLBACK: (255, 40, 40, 255),
}
_MID360_COLOUR = (190, 190, 190, 255)
_AVIA_COLOUR = (90, 140, 255, 255)
_TRUTH_COLOUR = (255, 255, 255, 255)
_TRACK_COLOUR = (255, 60, 200, 255)
_N_CLUSTER_COLOURS = 12


class View(Protocol):
    """What the annotate pipeline tells a review recording."""

    def log_frame(self, frame: LidarFrame, detections: FrameDetections) -> None:
        """One processed frame: its clouds, foreground and clusters."""

    def log_result(self, result: SequenceEstimate, detections: Sequence[FrameDetections]) -> None:
        """The sequence's estimates, trajectory, chosen clusters and track events."""

    def log_truth(
        self,
        stamps_ns: NDArray[np.int64],
        positions: NDArray[np.float64],
        errors_m: NDArray[np.float64] | None,
    ) -> None:
        """The ground truth and the 3D error of the estimates at its stamps (None: no estimate)."""

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
    ) -> None:
        """Do nothing."""

    def close(self) -> Path | None:
        """Nothing was written."""
        return None

    def abort(self) -> None:
        """Nothing to drop."""


def _time_column(stamps_ns: NDArray[np.int64] | Sequence[int]) -> rr.TimeColumn:
    import rerun as rr

    return rr.TimeColumn(
        TIMELINE, timestamp=np.asarray(stamps_ns, dtype=np.int64).astype("datetime64[ns]")
    )


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
    """Writes the review recording to a temporary ``.rrd`` beside ``path``, renamed on close."""

    def __init__(self, path: Path, *, recording_name: str, recording_id: str | None = None) -> None:
        import rerun as rr
        import rerun.blueprint as rrb

        self.path = path
        target = resolve_link(path)  # a link is kept: the file it points to is replaced
        remove_stale_temporaries(target.parent)
        self._target = target
        self._tmp = temporary_path(target)
        self._rec = rr.RecordingStream("cldet", recording_id=recording_id)  # None: a fresh id
        blueprint = rrb.Blueprint(
            rrb.Horizontal(
                rrb.Spatial3DView(name="scene", origin="world"),
                rrb.Vertical(
                    rrb.TimeSeriesView(name="position error (m)", origin="plots"),
                    rrb.TextLogView(name="track events", origin="events"),
                    row_shares=[2, 1],
                ),
                column_shares=[3, 1],
            ),
            collapse_panels=True,
        )
        self._rec.save(self._tmp, default_blueprint=blueprint)
        self._rec.send_recording_name(recording_name)
        self._mid360 = _CloudBuffer()
        self._avia = _CloudBuffer()
        self._foreground = _CloudBuffer()
        self._boxes: list[tuple[int, NDArray[np.float64], NDArray[np.float64], list[str]]] = []
        self._closed = False
        self._log_static()

    def _log_static(self) -> None:
        import rerun as rr

        rec = self._rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        palette = _cluster_palette()
        rec.log(
            "world",
            rr.AnnotationContext(
                [
                    rr.AnnotationInfo(id=i, label=f"cluster {i}", color=palette[i])
                    for i in range(_N_CLUSTER_COLOURS)
                ]
            ),
            static=True,
        )
        rec.log(
            "world/lidar/mid360",
            rr.Points3D.from_fields(radii=-1.2, colors=_MID360_COLOUR),
            static=True,
        )
        rec.log(
            "world/lidar/avia",
            rr.Points3D.from_fields(radii=-2.0, colors=_AVIA_COLOUR),
            static=True,
        )
        rec.log("world/foreground", rr.Points3D.from_fields(radii=-3.0), static=True)
        rec.log(
            "plots/error_m", rr.SeriesLines(names="3D error (m)", colors=_TRACK_COLOUR), static=True
        )

    def log_frame(self, frame: LidarFrame, detections: FrameDetections) -> None:
        """Buffer one frame's clouds, foreground (by cluster id) and cluster boxes."""
        stamp = frame.stamp_ns
        self._mid360.add(stamp, frame.mid360)
        self._avia.add(stamp, frame.avia)
        labels = np.asarray(detections.labels, dtype=np.int32)
        self._foreground.add(
            stamp, detections.foreground, np.where(labels < 0, 0, labels % _N_CLUSTER_COLOURS)
        )
        if detections.clusters:
            centres = np.array([c.centroid for c in detections.clusters], dtype=np.float64)
            halves = np.array(
                [(c.upper - c.lower) / 2 + 0.05 for c in detections.clusters], dtype=np.float64
            )
            labels_txt = [f"{c.cluster_id}: {c.n_points} pts" for c in detections.clusters]
            self._boxes.append((stamp, centres, halves, labels_txt))
        if len(self._mid360.stamps) >= _FLUSH_EVERY:
            self._flush()

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
                colors=np.tile(np.array([200, 200, 60, 255], np.uint8), (sum(lengths), 1)),
            )
            self._rec.send_columns(
                "world/clusters", indexes=[_time_column(stamps)], columns=columns.partition(lengths)
            )
            self._boxes.clear()

    def log_result(self, result: SequenceEstimate, detections: Sequence[FrameDetections]) -> None:
        """Send the estimates (coloured by source), the trajectory, chosen boxes and the event log."""
        import rerun as rr

        self._flush()
        rec = self._rec
        estimates: Sequence[Estimate] = result.estimates
        if estimates:
            stamps = np.array([e.stamp_ns for e in estimates], dtype=np.int64)
            positions = np.array([e.position for e in estimates], dtype=np.float64)
            colours = np.array([_SOURCE_COLOURS[e.source] for e in estimates], dtype=np.uint8)
            labels = [
                f"{e.source.name.lower()} ({e.n_points} pts, ±{e.sigma_m:.2f} m)" for e in estimates
            ]
            rec.send_columns(
                "world/drone/estimate",
                indexes=[_time_column(stamps)],
                columns=rr.Points3D.columns(
                    positions=positions,
                    colors=colours,
                    radii=np.full(len(stamps), 0.15, np.float32),
                    labels=labels,
                ),
            )
            rec.log(
                "world/drone/trajectory",
                rr.LineStrips3D([positions], colors=[_TRACK_COLOUR], radii=[0.03]),
                static=True,
            )
        by_stamp = {d.stamp_ns: d for d in detections}
        chosen = [
            (s, by_stamp[s].clusters[cid])
            for s, cid in sorted(result.chosen.items())
            if s in by_stamp and 0 <= cid < len(by_stamp[s].clusters)
        ]
        if chosen:
            rec.send_columns(
                "world/drone/chosen",
                indexes=[_time_column([s for s, _ in chosen])],
                columns=rr.Boxes3D.columns(
                    centers=np.array([c.centroid for _, c in chosen]),
                    half_sizes=np.array([(c.upper - c.lower) / 2 + 0.15 for _, c in chosen]),
                    colors=np.tile(np.array([40, 220, 60, 255], np.uint8), (len(chosen), 1)),
                    labels=["drone"] * len(chosen),
                ),
            )
        if result.events:
            rec.send_columns(
                "events",
                indexes=[_time_column([e.stamp_ns for e in result.events])],
                columns=rr.TextLog.columns(
                    text=[f"{e.kind}: {e.text}" for e in result.events],
                    level=["WARN" if e.kind == "lost" else "INFO" for e in result.events],
                ),
            )

    def log_truth(
        self,
        stamps_ns: NDArray[np.int64],
        positions: NDArray[np.float64],
        errors_m: NDArray[np.float64] | None,
    ) -> None:
        """Send the ground truth and the 3D error of the estimates at its stamps."""
        import rerun as rr

        if len(stamps_ns) == 0:
            return
        rec = self._rec
        rec.send_columns(
            "world/truth/position",
            indexes=[_time_column(stamps_ns)],
            columns=rr.Points3D.columns(
                positions=positions,
                colors=np.tile(np.asarray(_TRUTH_COLOUR, np.uint8), (len(positions), 1)),
                radii=np.full(len(positions), 0.1, np.float32),
            ),
        )
        rec.log(
            "world/truth/trajectory",
            rr.LineStrips3D([positions], colors=[_TRUTH_COLOUR], radii=[0.02]),
            static=True,
        )
        if errors_m is not None:
            rec.send_columns(
                "plots/error_m",
                indexes=[_time_column(stamps_ns)],
                columns=rr.Scalars.columns(scalars=errors_m),
            )

    def close(self) -> Path:
        """Flush everything, close the file and rename it into place."""
        if not self._closed:
            self._flush()
            self._rec.flush()
            self._rec.disconnect()
            self._closed = True
            try:
                commit(self._tmp, self._target)  # fsync, the umask's mode, rename
            except BaseException:
                self._tmp.unlink(missing_ok=True)
                raise
        return self.path

    def abort(self) -> None:
        """Close the stream and delete the temporary file."""
        if not self._closed:
            self._closed = True
            try:
                self._rec.disconnect()
            finally:
                self._tmp.unlink(missing_ok=True)


def _cluster_palette() -> list[tuple[int, int, int]]:
    """Distinct colours for cluster ids (id 0 is also used for noise points)."""
    base = [
        (230, 25, 75), (60, 180, 75), (255, 225, 25), (0, 130, 200), (245, 130, 48), (145, 30, 180),
        (70, 240, 240), (240, 50, 230), (210, 245, 60), (250, 190, 212), (0, 128, 128), (220, 190, 255),
    ]  # fmt: skip
    return base[:_N_CLUSTER_COLOURS]
