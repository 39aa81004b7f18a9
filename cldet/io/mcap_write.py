"""Writing cldet's MCAP logs: a :class:`LogWriter` around an open binary stream.

Messages are protobuf with Foxglove's well-known schemas (plus cldet's own types from
:mod:`cldet.io.schemas`), so Foxglove and Rerun display them natively. Every ``stamp_ns`` is
integer nanoseconds since the Unix epoch and is written, exactly, as the message's log time, its
publish time and its own ``timestamp`` field.

:func:`atomic_output` (from :mod:`cldet.io.files`) gives the matching file discipline: write into a
temporary file in the target folder, rename it into place only once complete, remove it on any
failure.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Mapping, Sequence
from enum import Enum
from types import TracebackType
from typing import IO, Any

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.CubePrimitive_pb2 import CubePrimitive
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.TextPrimitive_pb2 import TextPrimitive
from google.protobuf.message import Message
from google.protobuf.timestamp_pb2 import Timestamp
from mcap.records import Attachment, Channel, Schema
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from numpy.typing import ArrayLike

from cldet import __version__
from cldet.errors import LogError
from cldet.io import topics
from cldet.io.mcap_append import AppendPlan, AppendWriter
from cldet.io.ros import FrameTransform
from cldet.io.schemas import ClassEstimateMessage, ClassLabel, file_descriptor_set
from cldet.io.schemas import Estimate as EstimateMessage
from cldet.stamps import NS_PER_S
from cldet.types import ClassEstimate, Cluster, Estimate

__all__ = ["Compression", "LogWriter", "png_size"]

DEFAULT_CHUNK_SIZE = 1 << 20  # bytes of uncompressed messages per chunk: ~20 Mid-360 frames

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_XYZ = ("x", "y", "z")


class Compression(str, Enum):
    """Chunk compression of a log: zstd (smallest), lz4 (faster), none (fastest, largest)."""

    zstd = "zstd"
    lz4 = "lz4"
    none = "none"


_MCAP_COMPRESSION = {
    Compression.zstd: CompressionType.ZSTD,
    Compression.lz4: CompressionType.LZ4,
    Compression.none: CompressionType.NONE,
}


def _varint(value: int) -> bytes:
    """Protobuf base-128 varint of a non-negative integer."""
    out = bytearray()
    while value > 0x7F:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _timestamp(stamp_ns: int) -> Timestamp:
    seconds, nanos = divmod(stamp_ns, NS_PER_S)
    return Timestamp(seconds=seconds, nanos=nanos)


def _identity_pose(pose: Pose) -> None:
    # A zero position is absent on the wire unless marked present; Rerun's importer needs it.
    pose.position.SetInParent()
    pose.orientation.w = 1.0


def png_size(png: bytes) -> tuple[int, int]:
    """Width and height of a PNG image, read from its IHDR header (the image is not decoded).

    Raises:
        ValueError: ``png`` does not start with a PNG signature and an IHDR chunk.
    """
    if len(png) < 24 or png[:8] != _PNG_SIGNATURE or png[12:16] != b"IHDR":
        raise ValueError("not a PNG image (no PNG signature and IHDR header)")
    width, height = struct.unpack(">II", png[16:24])
    return int(width), int(height)


class _CloudLayout:
    """The constant part of a PointCloud message for one frame id and one set of float32 fields.

    A PointCloud is serialized as ``timestamp | frame_id, pose, point_stride, fields | data`` (the
    field order protobuf itself uses), with the middle part serialized once here, so writing a
    cloud costs one copy of its points and no per-point Python work.
    """

    def __init__(self, frame_id: str, fields: tuple[str, ...]) -> None:
        template = PointCloud(frame_id=frame_id, point_stride=4 * len(fields))
        _identity_pose(template.pose)
        for i, name in enumerate(fields):
            template.fields.add(name=name, offset=4 * i, type=PackedElementField.FLOAT32)
        self.middle = template.SerializeToString()
        self.n_fields = len(fields)

    def serialize(self, stamp_ns: int, data: memoryview | bytes) -> bytes:
        head = PointCloud(timestamp=_timestamp(stamp_ns)).SerializeToString()
        if len(data) == 0:
            return head + self.middle
        return b"".join((head, self.middle, b"\x32", _varint(len(data)), data))  # field 6: data


class LogWriter:
    """Writes protobuf messages into an MCAP log on an open, writable binary stream.

    A context manager: on a clean exit the log is finished (indexes, summary, footer) and the
    stream flushed; after an exception nothing more is written, since such a file is to be
    discarded (see :func:`cldet.io.files.atomic_output`). The stream is never closed: whoever opened it owns it.

    Args:
        stream: an open binary stream (a file opened ``"wb"``, a ``BytesIO``), at its start.
        compression: chunk compression, ``"zstd"``, ``"lz4"`` or ``"none"``.
        chunk_size: uncompressed bytes gathered per chunk; a chunk is what a reader must
            decompress to reach any message in it, so keep it modest.
        profile: the MCAP header's profile string (empty for protobuf logs).
        continues: continue an existing log instead of starting one: ``stream`` already holds
            the log's first ``continues.cut`` bytes (see :mod:`cldet.io.mcap_append`); new
            records follow them, then a summary covering the old records and the new.
        backend: send the records to this object instead of an MCAP file on ``stream`` (it
            offers the methods of ``mcap.writer.Writer`` this class calls: ``start``,
            ``register_schema``, ``register_channel``, ``add_message``, ``add_metadata``,
            ``finish``), e.g. a live WebSocket server (:mod:`cldet.live`).

    Every ``write_*`` method takes ``stamp_ns``, integer nanoseconds since the Unix epoch, used
    exactly as log time, publish time and the message's ``timestamp``.
    """

    def __init__(
        self,
        stream: IO[bytes],
        *,
        compression: Compression | str = Compression.zstd,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        profile: str = "",
        continues: AppendPlan | None = None,
        backend: Any = None,
    ) -> None:
        try:
            self.compression = Compression(compression)
        except ValueError as err:
            raise LogError(
                f"unknown compression {compression!r}: expected one of "
                + ", ".join(c.value for c in Compression)
            ) from err
        self._stream: IO[bytes] = stream
        self._buffer: io.BufferedWriter | None = None
        if isinstance(stream, io.RawIOBase):  # buffer raw streams ourselves, flushed in finish()
            self._buffer = io.BufferedWriter(stream)
            self._stream = self._buffer
        self._mcap: Any
        if backend is not None:
            self._mcap = backend
        elif continues is None:
            self._mcap = McapWriter(
                self._stream,
                chunk_size=chunk_size,
                compression=_MCAP_COMPRESSION[self.compression],
            )
        else:
            self._mcap = AppendWriter(self._stream, continues, chunk_size=chunk_size)
        self._mcap.start(profile=profile, library=f"cldet/{__version__}")
        self._schemas: dict[str, int] = {}  # schema name -> id
        self._channels: dict[str, tuple[int, str]] = {}  # topic -> (channel id, schema name)
        self._layouts: dict[tuple[str, tuple[str, ...]], _CloudLayout] = {}
        self._counts: dict[str, int] = {}
        self._finished = False

    # --- context manager ---------------------------------------------------------------------
    def __enter__(self) -> LogWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.finish()

    def finish(self) -> None:
        """Write the summary and footer and flush the stream (idempotent; never closes it)."""
        if self._finished:
            return
        self._finished = True
        self._mcap.finish()
        self._stream.flush()
        if self._buffer is not None:
            self._buffer.detach()  # leave the caller's raw stream open

    @property
    def counts(self) -> dict[str, int]:
        """Messages written so far, per topic."""
        return dict(self._counts)

    # --- channels ----------------------------------------------------------------------------
    def _schema_id(self, name: str, data: bytes, encoding: str = topics.SCHEMA_ENCODING) -> int:
        schema_id = self._schemas.get(name)
        if schema_id is None:
            schema_id = self._mcap.register_schema(name=name, encoding=encoding, data=data)
            self._schemas[name] = schema_id
        return schema_id

    def _channel(
        self, topic: str, message_class: Any, metadata: Mapping[str, str] | None = None
    ) -> int:
        name: str = message_class.DESCRIPTOR.full_name
        found = self._channels.get(topic)
        if found is not None:
            channel_id, existing = found
            if existing != name:
                raise LogError(f"topic {topic} carries {existing}, cannot write a {name} to it")
            return channel_id
        schema_id = self._schema_id(name, file_descriptor_set(message_class))
        channel_id = self._mcap.register_channel(
            topic=topic,
            message_encoding=topics.MESSAGE_ENCODING,
            schema_id=schema_id,
            metadata=dict(metadata or {}),
        )
        self._channels[topic] = (channel_id, name)
        return channel_id

    def _add(self, channel_id: int, topic: str, stamp_ns: int, data: bytes) -> None:
        if self._finished:
            raise LogError(f"cannot write to {topic}: the log is already finished")
        stamp = int(stamp_ns)
        if stamp < 0:
            raise ValueError(f"stamp_ns must be non-negative nanoseconds, got {stamp_ns}")
        self._mcap.add_message(channel_id=channel_id, log_time=stamp, data=data, publish_time=stamp)
        self._counts[topic] = self._counts.get(topic, 0) + 1

    def write_message(
        self,
        topic: str,
        stamp_ns: int,
        message: Message,
        *,
        channel_metadata: Mapping[str, str] | None = None,
    ) -> None:
        """Write any protobuf message; its type's ``FileDescriptorSet`` becomes the schema.

        ``channel_metadata`` goes into the channel record when this call creates the channel.
        """
        channel_id = self._channel(topic, type(message), channel_metadata)
        self._add(channel_id, topic, stamp_ns, message.SerializeToString())

    def write_raw(
        self, schema: Schema | None, channel: Channel, log_time: int, publish_time: int, data: bytes
    ) -> None:
        """Copy one message of another MCAP log byte for byte (schema and channel included).

        For rewriting a log with added channels: pass what ``mcap.reader`` yields. Times are
        kept as they are; the topic must not also be written through the typed methods.
        """
        found = self._channels.get(channel.topic)
        name = schema.name if schema is not None else ""
        if found is None:
            schema_id = (
                0 if schema is None else self._schema_id(schema.name, schema.data, schema.encoding)
            )
            channel_id = self._mcap.register_channel(
                topic=channel.topic,
                message_encoding=channel.message_encoding,
                schema_id=schema_id,
                metadata=dict(channel.metadata),
            )
            self._channels[channel.topic] = (channel_id, name)
        else:
            channel_id, existing = found
            if existing != name:
                raise LogError(
                    f"topic {channel.topic} carries {existing}, cannot copy a {name} to it"
                )
        if self._finished:
            raise LogError(f"cannot write to {channel.topic}: the log is already finished")
        self._mcap.add_message(
            channel_id=channel_id, log_time=log_time, data=data, publish_time=publish_time
        )
        self._counts[channel.topic] = self._counts.get(channel.topic, 0) + 1

    def write_attachment(self, attachment: Attachment) -> None:
        """Copy an attachment record (e.g. from another log) into this log."""
        if self._finished:
            raise LogError(f"cannot write attachment {attachment.name!r}: the log is finished")
        self._mcap.add_attachment(
            create_time=attachment.create_time,
            log_time=attachment.log_time,
            name=attachment.name,
            media_type=attachment.media_type,
            data=attachment.data,
        )

    # --- typed writers -----------------------------------------------------------------------
    def write_cloud(
        self,
        topic: str,
        stamp_ns: int,
        points: ArrayLike,
        frame_id: str,
        fields: Sequence[str] = _XYZ,
    ) -> None:
        """Write a ``foxglove.PointCloud``: one float32 field per column of ``points``.

        Args:
            topic: e.g. :data:`cldet.io.topics.LIDAR_360`.
            stamp_ns: integer nanoseconds since the Unix epoch.
            points: (N, len(fields)) numbers, stored as little-endian float32 (N may be 0).
            frame_id: the coordinate frame, e.g. :data:`cldet.io.topics.FRAME_MID360`.
            fields: column names at offsets 0, 4, 8, ...; x, y, z first, then any extras
                such as ``cluster_id`` (float32 too). The pose is the identity.
        """
        names = tuple(fields)
        key = (frame_id, names)
        layout = self._layouts.get(key)
        if layout is None:
            if names[:3] != _XYZ:
                raise ValueError(f"cloud fields must start with x, y, z, got {names}")
            layout = self._layouts[key] = _CloudLayout(frame_id, names)
        array = np.asarray(points)
        if array.ndim != 2 or array.shape[1] != layout.n_fields:
            if array.size == 0:  # e.g. an empty radar frame of shape (0,)
                array = array.reshape(0, layout.n_fields)
            else:
                raise ValueError(
                    f"{topic}: points must have shape (N, {layout.n_fields}) for fields "
                    f"{names}, got {array.shape}"
                )
        data = np.ascontiguousarray(array, dtype="<f4")
        channel_id = self._channel(topic, PointCloud)
        self._add(
            channel_id,
            topic,
            stamp_ns,
            layout.serialize(int(stamp_ns), data.reshape(-1).view(np.uint8).data),
        )

    def write_timed_cloud(
        self,
        topic: str,
        stamp_ns: int,
        points: ArrayLike,
        times: ArrayLike | None,
        frame_id: str,
    ) -> None:
        """``write_cloud`` of (N, 3) ``points``, with each point's firing time after the stamp
        (``times``, (N,) seconds) as a ``time`` field when there are times (``Cloud.times``)."""
        if times is None:
            self.write_cloud(topic, stamp_ns, points, frame_id)
            return
        timed = np.column_stack([np.asarray(points).reshape(-1, 3), np.asarray(times)])
        self.write_cloud(topic, stamp_ns, timed, frame_id, topics.TIMED_CLOUD_FIELDS)

    def write_colored_cloud(
        self,
        topic: str,
        stamp_ns: int,
        points: ArrayLike,
        colors: ArrayLike,
        frame_id: str,
    ) -> None:
        """Write a ``foxglove.PointCloud`` with a colour per point, drawn so by both viewers.

        Args:
            points: (N, 3) metres, stored as float32 x, y, z at offsets 0, 4, 8.
            colors: (N, 4) or (4,) RGBA 0..255, stored as uint8 ``red``, ``green``, ``blue``,
                ``alpha`` at offsets 12..15 (the fields Foxglove and Rerun both read).
        """
        xyz = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        rgba = np.broadcast_to(np.asarray(colors, dtype=np.uint8), (len(xyz), 4))
        packed = np.empty(len(xyz), dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])
        packed["xyz"] = xyz
        packed["rgba"] = rgba
        msg = PointCloud(timestamp=_timestamp(int(stamp_ns)), frame_id=frame_id, point_stride=16)
        _identity_pose(msg.pose)
        for i, name in enumerate(_XYZ):
            msg.fields.add(name=name, offset=4 * i, type=PackedElementField.FLOAT32)
        for i, name in enumerate(("red", "green", "blue", "alpha")):
            msg.fields.add(name=name, offset=12 + i, type=PackedElementField.UINT8)
        msg.data = packed.tobytes()
        self.write_message(topic, stamp_ns, msg)

    def write_transforms(
        self,
        topic: str,
        stamp_ns: int,
        transforms: Sequence[FrameTransform],
        *,
        channel_metadata: Mapping[str, str] | None = None,
    ) -> None:
        """Write a ``foxglove.FrameTransforms``: each transform takes ``child`` into ``parent``.

        Translation and rotation are always present on the wire (a zero translation too), which
        Rerun's MCAP import needs.
        """
        from scipy.spatial.transform import Rotation

        stamp = int(stamp_ns)
        msg = FrameTransforms()
        for t in transforms:
            out = msg.transforms.add(
                timestamp=_timestamp(stamp), parent_frame_id=t.parent, child_frame_id=t.child
            )
            out.translation.SetInParent()
            out.translation.x, out.translation.y, out.translation.z = (
                float(v) for v in t.matrix[:3, 3]
            )
            qx, qy, qz, qw = Rotation.from_matrix(t.matrix[:3, :3]).as_quat()
            out.rotation.SetInParent()
            out.rotation.x, out.rotation.y, out.rotation.z = float(qx), float(qy), float(qz)
            out.rotation.w = float(qw)
        self.write_message(topic, stamp, msg, channel_metadata=channel_metadata)

    def write_pose(self, topic: str, stamp_ns: int, position: ArrayLike, frame_id: str) -> None:
        """Write a ``foxglove.PoseInFrame`` at ``position`` (3,) metres, identity orientation."""
        x, y, z = (float(v) for v in np.asarray(position, dtype=np.float64).reshape(3))
        msg = PoseInFrame(timestamp=_timestamp(int(stamp_ns)), frame_id=frame_id)
        msg.pose.position.SetInParent()
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = x, y, z
        msg.pose.orientation.w = 1.0
        self.write_message(topic, stamp_ns, msg)

    def write_poses(self, topic: str, stamp_ns: int, positions: ArrayLike, frame_id: str) -> None:
        """Write a ``foxglove.PosesInFrame`` (e.g. a trajectory): positions (N, 3) metres."""
        array = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        msg = PosesInFrame(timestamp=_timestamp(int(stamp_ns)), frame_id=frame_id)
        for x, y, z in array.tolist():
            pose = msg.poses.add()
            pose.position.SetInParent()
            pose.position.x, pose.position.y, pose.position.z = x, y, z
            pose.orientation.w = 1.0
        self.write_message(topic, stamp_ns, msg)

    def write_class(self, topic: str, stamp_ns: int, class_id: int) -> None:
        """Write a ``cldet.ClassLabel`` (drone type, 0..3)."""
        msg = ClassLabel(timestamp=_timestamp(int(stamp_ns)), class_id=int(class_id))
        self.write_message(topic, stamp_ns, msg)

    def write_image(
        self,
        topic: str,
        stamp_ns: int,
        png: bytes,
        frame_id: str,
        *,
        calibration_topic: str | None = None,
    ) -> None:
        """Write a PNG as ``foxglove.CompressedImage`` plus a ``foxglove.CameraCalibration``.

        The calibration (on ``calibration_topic``, default ``<topic>/calibration``, same stamp
        and frame id) carries the width and height from the PNG header and a nominal pinhole
        (focal length = height / 2, centre of the image): the real intrinsics are unknown, but
        Rerun's 3D view needs a camera for an image with a frame id.

        Raises:
            LogError: ``png`` is not a PNG image.
        """
        try:
            width, height = png_size(png)
        except ValueError as err:
            raise LogError(f"{topic} at {stamp_ns} ns: {err}") from err
        stamp = int(stamp_ns)
        image = CompressedImage(
            timestamp=_timestamp(stamp), frame_id=frame_id, data=png, format="png"
        )
        self.write_message(topic, stamp, image)
        f = height / 2.0
        cx, cy = width / 2.0, height / 2.0
        calibration = CameraCalibration(
            timestamp=_timestamp(stamp),
            frame_id=frame_id,
            width=width,
            height=height,
            distortion_model="",
            K=[f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0],
            R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            P=[f, 0.0, cx, 0.0, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        )
        self.write_message(calibration_topic or f"{topic}/calibration", stamp, calibration)

    def write_scene_update(
        self,
        topic: str,
        stamp_ns: int,
        clusters: Sequence[Cluster],
        frame_id: str,
        *,
        labels: Sequence[str] | None = None,
        color: tuple[float, float, float, float] = (1.0, 0.6, 0.0, 0.5),
        entity_id: str = "clusters",
    ) -> None:
        """Write a ``foxglove.SceneUpdate``: one entity with a box and a text label per cluster.

        Args:
            clusters: boxes from ``lower`` to ``upper`` (metres); the entity replaces the
                previous one with the same ``entity_id``.
            labels: one text per cluster (default: ``"#<cluster_id> <n_points> pts"``), drawn
                above the box.
            color: RGBA in 0..1 for boxes and labels.
        """
        if labels is not None and len(labels) != len(clusters):
            raise ValueError(f"{len(labels)} labels for {len(clusters)} clusters")
        stamp = int(stamp_ns)
        rgba = Color(r=color[0], g=color[1], b=color[2], a=color[3])
        entity = SceneEntity(timestamp=_timestamp(stamp), frame_id=frame_id, id=entity_id)
        for i, cluster in enumerate(clusters):
            lower = np.asarray(cluster.lower, dtype=np.float64)
            upper = np.asarray(cluster.upper, dtype=np.float64)
            centre = ((lower + upper) / 2.0).tolist()
            size = np.maximum(upper - lower, 0.0).tolist()
            cube: CubePrimitive = entity.cubes.add(color=rgba)
            cube.pose.position.SetInParent()
            cube.pose.position.x, cube.pose.position.y, cube.pose.position.z = centre
            cube.pose.orientation.w = 1.0
            cube.size.SetInParent()
            cube.size.x, cube.size.y, cube.size.z = size
            text: TextPrimitive = entity.texts.add(
                billboard=True,
                font_size=14.0,
                scale_invariant=True,
                color=rgba,
                text=labels[i]
                if labels is not None
                else f"#{cluster.cluster_id} {cluster.n_points} pts",
            )
            text.pose.position.SetInParent()
            text.pose.position.x, text.pose.position.y = centre[0], centre[1]
            text.pose.position.z = float(upper[2]) + 0.2
            text.pose.orientation.w = 1.0
        self.write_message(topic, stamp, SceneUpdate(entities=[entity]))

    def write_estimate(
        self, topic: str, stamp_ns: int, estimate: Estimate, *, track_id: int = 0
    ) -> None:
        """Write a ``cldet.Estimate`` (position, source, cluster size, sigma, track id)."""
        x, y, z = (float(v) for v in np.asarray(estimate.position, dtype=np.float64).reshape(3))
        msg = EstimateMessage(
            timestamp=_timestamp(int(stamp_ns)),
            x=x,
            y=y,
            z=z,
            source=int(estimate.source),
            n_points=int(estimate.n_points),
            sigma_m=float(estimate.sigma_m),
            track_id=int(track_id),
        )
        self.write_message(topic, stamp_ns, msg)

    def write_class_estimate(self, topic: str, estimate: ClassEstimate) -> None:
        """Write a ``cldet.ClassEstimate`` (the most probable class, every class's probability)."""
        msg = ClassEstimateMessage(
            timestamp=_timestamp(int(estimate.stamp_ns)),
            class_id=int(estimate.class_id),
            class_ids=[int(c) for c in estimate.class_ids],
            probabilities=[float(p) for p in estimate.probabilities],
        )
        self.write_message(topic, estimate.stamp_ns, msg)

    def write_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Write an MCAP metadata record ``name`` holding string keys and string values."""
        if self._finished:
            raise LogError(f"cannot write metadata {name!r}: the log is already finished")
        bad = {k: type(v).__name__ for k, v in data.items() if not isinstance(v, str)}
        if bad:
            raise ValueError(f"metadata {name!r} values must be strings, got {bad}")
        self._mcap.add_metadata(name, dict(data))
