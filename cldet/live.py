"""Live streaming of an annotate run: a Rerun viewer over gRPC, Foxglove over its WebSocket server.

``cldet annotate LOG --live`` streams, frame by frame while the estimator runs, the LiDAR
clouds, the foreground, the clusters and the *causal* estimate (what a live system would show),
then the refined track at the end:

- to Rerun through the review recording's own stream (:class:`cldet.view.RerunView` with a
  gRPC sink beside its file sink: the ``.rrd`` is still written);
- to Foxglove through ``foxglove-sdk``'s WebSocket server (bound to 127.0.0.1 by default), with
  the very messages the annotated log holds: a :class:`cldet.io.mcap_write.LogWriter` writes
  them to the server's channels instead of a file (:class:`FoxgloveBackend`).

:class:`LiveOutput` owns the server across the logs of one command; :class:`FoxgloveView` is
the per-log view. Pacing (``realtime``) and the per-frame latency are the pipeline's, through
:meth:`LiveOutput.pace` and :meth:`LiveOutput.frame_done`.
"""

from __future__ import annotations

import io
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from cldet.config import SensorConfig
from cldet.errors import CldetError
from cldet.io import topics
from cldet.io.mcap_write import LogWriter
from cldet.io.transforms import log_tree
from cldet.result_channels import causal_additions, track_writer, truth_track_writer
from cldet.stamps import NS_PER_S
from cldet.types import LidarFrame

if TYPE_CHECKING:
    from cldet.core.estimator import FrameDetections, SequenceEstimate

DEFAULT_FOXGLOVE_PORT = 8765


class FoxgloveBackend:
    """The ``mcap.writer.Writer`` methods :class:`LogWriter` calls, sent to foxglove-sdk channels.

    Each channel is a raw ``foxglove.Channel`` with the protobuf schema the log would hold, so a
    Foxglove client decodes the live stream exactly as it decodes the annotated log.
    """

    def __init__(self, context: Any) -> None:
        self._context = context
        self._schemas: dict[int, Any] = {}
        self._channels: dict[int, Any] = {}

    def start(self, profile: str = "", library: str = "") -> None:
        """Nothing to start."""

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Keep a schema for the channels that use it."""
        import foxglove

        schema_id = len(self._schemas) + 1
        self._schemas[schema_id] = foxglove.Schema(name=name, encoding=encoding, data=data)
        return schema_id

    def register_channel(
        self,
        topic: str,
        message_encoding: str,
        schema_id: int,
        metadata: dict[str, str] | None = None,
    ) -> int:
        """Open a foxglove-sdk channel (advertised to every connected client)."""
        import foxglove

        channel = foxglove.Channel(
            topic,
            schema=self._schemas.get(schema_id),
            message_encoding=message_encoding,
            context=self._context,
            metadata=dict(metadata or {}),
        )
        channel_id = len(self._channels) + 1
        self._channels[channel_id] = channel
        return channel_id

    def add_message(
        self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0
    ) -> None:
        """Send one serialized message, stamped with its log time (integer ns)."""
        self._channels[channel_id].log(data, log_time=log_time)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A live stream has no metadata records."""

    def finish(self) -> None:
        """Close the channels (clients see them unadvertised)."""
        for channel in self._channels.values():
            channel.close()
        self._channels.clear()


class FoxgloveView:
    """One log streamed to Foxglove: sensor clouds and causal results per frame, then the track.

    Uses the log's topics and frames (``/lidar_360``, ``/livox_avia``, ``/cldet/*``, ``/tf``).
    """

    def __init__(self, context: Any, sensor: SensorConfig, lidar_frame: str) -> None:
        self._writer = LogWriter(io.BytesIO(), backend=FoxgloveBackend(context))
        self._tree = log_tree(lidar_frame, sensor)
        self._frame = lidar_frame
        self._last_ns: int | None = None

    def log_frame(self, frame: LidarFrame, detections: FrameDetections) -> None:
        """The frame's clouds, foreground, clusters, causal estimate (and the frame tree)."""
        w, stamp = self._writer, frame.stamp_ns
        w.write_transforms(topics.TF, stamp, self._tree)  # every frame: late clients get it too
        w.write_cloud(topics.LIDAR_360, stamp, frame.mid360, self._frame)
        w.write_cloud(topics.LIVOX_AVIA, stamp, frame.avia, self._frame)
        for _, write in causal_additions(detections, self._frame):
            write(w)
        self._last_ns = stamp

    def log_result(self, result: SequenceEstimate, detections: Sequence[FrameDetections]) -> None:
        """The refined track, at the last frame's stamp (so a live view shows it at the end)."""
        if result.estimates and self._last_ns is not None:
            positions = np.array([e.position for e in result.estimates], dtype=np.float64)
            track_writer(self._last_ns, positions, self._frame)(self._writer)

    def log_truth(
        self,
        stamps_ns: NDArray[np.int64],
        positions: NDArray[np.float64],
        errors_m: NDArray[np.float64] | None,
        estimated: NDArray[np.float64] | None = None,
    ) -> None:
        """The ground truth's trajectory, at the last frame's stamp."""
        if len(positions) and self._last_ns is not None:
            truth_track_writer(self._last_ns, positions, self._frame)(self._writer)

    def close(self) -> Path | None:
        """Close this log's channels (the server stays up for the next log)."""
        self._writer.finish()
        return None

    def abort(self) -> None:
        """As :meth:`close`."""
        self._writer.finish()


class LiveOutput:
    """Where an annotate run streams to, and how fast: owned by the command, across its logs.

    Args:
        rerun: ``"spawn"`` (start a viewer), a Rerun gRPC URL (``--connect``), or None.
        foxglove_port: serve Foxglove's WebSocket protocol on this port (0: any free one), or
            None for no Foxglove server.
        foxglove_host: the interface to bind; 127.0.0.1 (this machine only) by default.
        realtime: pace the frames at the sensor's rate (their stamps), not as fast as possible.
        on_frame: called after each frame with its stamp (ns) and latency (seconds: from the
            frame in hand to its results sent).

    Raises:
        CldetError: the Foxglove server cannot start (the port is taken, foxglove-sdk missing).
    """

    def __init__(
        self,
        *,
        rerun: str | None = None,
        foxglove_port: int | None = None,
        foxglove_host: str = "127.0.0.1",
        realtime: bool = False,
        on_frame: Callable[[int, float], None] | None = None,
    ) -> None:
        self.rerun = rerun
        self.realtime = realtime
        self.latencies_s: list[float] = []
        self._on_frame = on_frame
        self._pace_origin: tuple[float, int] | None = None
        self._context: Any = None
        self._server: Any = None
        if foxglove_port is not None:
            try:
                import foxglove
            except ImportError as err:
                raise CldetError(
                    "--foxglove needs foxglove-sdk: pip install 'foxglove-sdk>=0.30,<0.31'"
                ) from err
            self._context = foxglove.Context()
            try:
                self._server = foxglove.start_server(
                    name="cldet",
                    host=foxglove_host,
                    port=foxglove_port,
                    context=self._context,
                )
            except Exception as err:  # foxglove raises its own RuntimeError subclasses
                raise CldetError(
                    f"cannot serve Foxglove on {foxglove_host}:{foxglove_port}: {err}"
                ) from err

    @property
    def foxglove_port(self) -> int | None:
        """The port the Foxglove server listens on (None without one)."""
        return None if self._server is None else int(self._server.port)

    def foxglove_view(self, sensor: SensorConfig, lidar_frame: str) -> FoxgloveView | None:
        """A view streaming one log to the Foxglove server (None without one)."""
        if self._context is None:
            return None
        return FoxgloveView(self._context, sensor, lidar_frame)

    def pace(self, stamp_ns: int) -> None:
        """With ``realtime``, wait until ``stamp_ns`` is due (the first frame sets the clock)."""
        if not self.realtime:
            return
        now = time.perf_counter()
        if self._pace_origin is None or stamp_ns < self._pace_origin[1]:
            self._pace_origin = (now, stamp_ns)
            return
        wall0, stamp0 = self._pace_origin
        delay = (stamp_ns - stamp0) / NS_PER_S - (now - wall0)
        if delay > 0:
            time.sleep(delay)

    def frame_done(self, stamp_ns: int, latency_s: float) -> None:
        """Record one frame's latency and tell ``on_frame``."""
        self.latencies_s.append(latency_s)
        if self._on_frame is not None:
            self._on_frame(stamp_ns, latency_s)

    def latency_summary(self) -> str:
        """Median, 95th percentile and maximum per-frame latency, one line."""
        if not self.latencies_s:
            return "no frames streamed"
        ms = np.asarray(self.latencies_s) * 1e3
        return (
            f"per-frame latency over {len(ms)} frames: median {np.median(ms):.1f} ms, "
            f"95th percentile {np.percentile(ms, 95):.1f} ms, max {ms.max():.1f} ms"
        )

    def close(self) -> None:
        """Stop the Foxglove server."""
        if self._server is not None:
            self._server.stop()
            self._server = None
