"""The sensor channels of any MCAP log: which topics to read, and stamped clouds and positions.

A log written by ``cldet convert`` holds ``foxglove.PointCloud`` on ``/lidar_360`` and
``/livox_avia``; a ROS 2 recording (``ros2 bag record`` writes MCAP) holds
``sensor_msgs/msg/PointCloud2`` or Livox ``CustomMsg`` on topics of its own, in CDR (ROS 1
messages in MCAP are read too). :func:`select_topics` picks the LiDAR, Avia and truth topics;
:func:`iter_log_clouds` and :func:`iter_log_positions` stream them as cldet's plain data, every
stamp the message's own (its header stamp, integer ns), never the log time a recorder wrote.

The Avia's clouds are moved into the Mid-360's frame with the log's ``/tf_static`` when it
connects the two frames; otherwise they are taken as already in it (the challenge's layout).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray
from rosbags.serde import SerdeError

from cldet.errors import LogError
from cldet.io import ros, topics
from cldet.io.mcap_read import CORRUPT_ERRORS, LogReader, decode_timed, open_log
from cldet.types import PositionSample

__all__ = [
    "CLOUD_SCHEMAS",
    "POSITION_SCHEMAS",
    "TF_STATIC",
    "SensorTopics",
    "iter_log_clouds",
    "iter_log_positions",
    "reader_clouds",
    "reader_positions",
    "read_static_transforms",
    "select_topics",
]

TF_STATIC: Final = ros.TF_STATIC
# what bytes that do not decode raise (cldet's readers, protobuf, rosbags), and a bad cloud
_UNDECODABLE: tuple[type[BaseException], ...] = (*CORRUPT_ERRORS, SerdeError)
CLOUD_SCHEMAS: Final = (topics.SCHEMA_POINT_CLOUD, *ros.CLOUD_TYPES)
POSITION_SCHEMAS: Final = (topics.SCHEMA_POSE_IN_FRAME, topics.SCHEMA_ESTIMATE, *ros.POSITION_TYPES)


def _kind(schema_name: str) -> str:
    """A schema name as compared here: ROS types as ``pkg/msg/Name``, others as they are."""
    return (
        schema_name
        if schema_name.startswith(("foxglove.", "cldet."))
        else ros.normalize_type(schema_name)
    )


@dataclass(frozen=True)
class SensorTopics:
    """The topics of one log that annotate reads."""

    lidar: str  # the Mid-360 (or the one LiDAR) point clouds
    avia: str | None = None  # the Avia's, fused with the LiDAR's
    truth: str | None = None  # ground-truth positions, for the error in the report and review


def _listing(types: dict[str, str], counts: dict[str, int]) -> str:
    return (
        ", ".join(f"{t} ({types[t] or 'no schema'}, {counts.get(t, 0)} messages)" for t in types)
        or "none"
    )


def _check(
    log: Path,
    types: dict[str, str],
    counts: dict[str, int],
    topic: str,
    allowed: tuple[str, ...],
    what: str,
) -> None:
    if topic not in types:
        raise LogError(
            f"{log} has no topic {topic} ({what}); topics in the log: {_listing(types, counts)}"
        )
    if _kind(types[topic]) not in allowed:
        raise LogError(
            f"{log}: topic {topic} carries {types[topic] or 'schemaless messages'}, expected "
            f"{what}: one of {', '.join(allowed)}"
        )
    if not counts.get(topic):
        raise LogError(f"{log}: no message on its {topic} channel ({what}), nothing to annotate")


def select_topics(
    reader: LogReader, lidar: str | None = None, avia: str | None = None, truth: str | None = None
) -> SensorTopics:
    """The LiDAR, Avia and truth topics of the log open in ``reader``.

    Without ``lidar``: ``/lidar_360`` (with ``/livox_avia`` and ``/ground_truth`` when present)
    in a log written by ``cldet convert``; otherwise the log's only point-cloud topic. ``truth``
    defaults to ``/ground_truth`` when the log has one.

    Raises:
        LogError: a topic named is missing or carries another type; no topic, or several, could
            be the LiDAR (the message lists the candidates with their types).
    """
    log = reader.path
    types = reader.topic_types()
    counts = reader.list_topics()
    if lidar is None:
        if counts.get(topics.LIDAR_360):
            lidar = topics.LIDAR_360
            if avia is None and counts.get(topics.LIVOX_AVIA):
                avia = topics.LIVOX_AVIA
        else:
            candidates = {
                t: s for t, s in types.items() if _kind(s) in CLOUD_SCHEMAS and counts.get(t)
            }
            if len(candidates) > 1:
                raise LogError(
                    f"{log}: several point-cloud topics could be the LiDAR: "
                    + ", ".join(f"{t} ({s})" for t, s in candidates.items())
                    + "; choose one with --lidar TOPIC"
                )
            if not candidates:
                what = "no message on its" if topics.LIDAR_360 in types else "no"
                raise LogError(
                    f"{log}: {what} {topics.LIDAR_360} channel, nothing to annotate; topics in "
                    "the log: "
                    + (", ".join(f"{t} ({n})" for t, n in sorted(counts.items())) or "none")
                    + f"; no other point-cloud topic ({', '.join(CLOUD_SCHEMAS)}) either"
                )
            (lidar,) = candidates
    if truth is None and counts.get(topics.GROUND_TRUTH):
        truth = topics.GROUND_TRUTH
    _check(log, types, counts, lidar, CLOUD_SCHEMAS, "a point cloud")
    if avia is not None:
        _check(log, types, counts, avia, CLOUD_SCHEMAS, "a point cloud")
    if truth is not None:
        _check(log, types, counts, truth, POSITION_SCHEMAS, "positions")
    return SensorTopics(lidar=lidar, avia=avia, truth=truth)


class _Decoders:
    """One decoder per schema of a log, made by ``factory`` (a ``cldet.io.ros`` one) on first use."""

    def __init__(self, factory: Callable[[str, str, bytes, str], Callable[[bytes], Any]]) -> None:
        self._factory = factory
        self._by_schema: dict[int, Callable[[bytes], Any]] = {}

    def decode(self, schema: Any, channel: Any, data: bytes) -> Any:
        decoder = self._by_schema.get(channel.schema_id)
        if decoder is None:
            decoder = self._factory(
                schema.name, schema.encoding, schema.data, channel.message_encoding
            )
            self._by_schema[channel.schema_id] = decoder
        return decoder(data)


def _iter_decoded(
    reader: LogReader, topic: str, convert: Callable[[str, Any, Any, bytes], Any]
) -> Iterator[Any]:
    """``convert(kind, schema, channel, data)`` of every message of ``topic``; errors name it."""
    for schema, channel, message in reader.iter_messages([topic]):
        kind = _kind(schema.name if schema is not None else "")
        try:
            yield convert(kind, schema, channel, message.data)
        except _UNDECODABLE as err:  # the bytes do not decode, or not as expected
            raise reader.message_error(topic, message, err) from err


def _iter_clouds(reader: LogReader, topic: str) -> Iterator[ros.StampedCloud]:
    decoders = _Decoders(ros.cloud_decoder)

    def convert(kind: str, schema: Any, channel: Any, data: bytes) -> ros.StampedCloud:
        if kind == topics.SCHEMA_POINT_CLOUD:
            stamp_ns, frame_id, points, times = decode_timed(data)
            return ros.StampedCloud(stamp_ns, frame_id, points, times)
        cloud: ros.StampedCloud = decoders.decode(schema, channel, data)
        return cloud

    return _iter_decoded(reader, topic, convert)


def read_static_transforms(reader: LogReader) -> list[ros.FrameTransform]:
    """Every transform on the log's ``/tf_static`` (``tf2_msgs/msg/TFMessage``); [] without one."""
    if _kind(reader.topic_types().get(TF_STATIC, "")) != ros.TF_MESSAGE:
        return []
    decoders = _Decoders(ros.message_decoder)

    def convert(kind: str, schema: Any, channel: Any, data: bytes) -> list[ros.FrameTransform]:
        return ros.transforms_of(decoders.decode(schema, channel, data))

    return [t for batch in _iter_decoded(reader, TF_STATIC, convert) for t in batch]


def iter_log_clouds(
    path: str | os.PathLike[str],
    topic: str,
    *,
    target_frame: str | Callable[[], str | None] | None = None,
    fallback: NDArray[np.float64] | None = None,
) -> Iterator[ros.StampedCloud]:
    """The clouds of one point-cloud topic, at their header stamps, in log order.

    Args:
        path: the MCAP log.
        topic: a ``foxglove.PointCloud``, ``PointCloud2``, Livox ``CustomMsg`` or ``PointCloud``
            topic.
        target_frame: move the points into this frame (or the one this function returns, asked
            at the first cloud) with the log's ``/tf_static`` when it connects the cloud's frame
            to it; the points stay as they are otherwise (and their ``frame_id`` with them).
        fallback: the (4, 4) transform into ``target_frame`` for a cloud in another frame that
            ``/tf_static`` does not connect to it (None: such a cloud stays as it is).

    Raises:
        LogError: the log cannot be read; CorruptMessageError: a message does not decode or is
            malformed (names the log, topic, stamp and what was expected).
    """
    with open_log(path) as reader:
        yield from reader_clouds(reader, topic, target_frame=target_frame, fallback=fallback)


def reader_clouds(
    reader: LogReader,
    topic: str,
    *,
    target_frame: str | Callable[[], str | None] | None = None,
    fallback: NDArray[np.float64] | None = None,
) -> Iterator[ros.StampedCloud]:
    """:func:`iter_log_clouds` on an open log: several topics' iterators over one reader that
    move through the log together decompress each chunk once."""
    transforms = read_static_transforms(reader) if target_frame is not None else []
    matrices: dict[str, NDArray[np.float64] | None] = {}
    for cloud in _iter_clouds(reader, topic):
        if callable(target_frame):
            target_frame = target_frame()
        if target_frame is None or cloud.frame_id == target_frame:
            yield cloud
            continue
        if cloud.frame_id not in matrices:
            found = (
                ros.static_transform(transforms, target_frame, cloud.frame_id)
                if transforms
                else None
            )
            matrices[cloud.frame_id] = found if found is not None else fallback
        matrix = matrices[cloud.frame_id]
        if matrix is None:
            yield cloud
            continue
        points = ros.transform_points(matrix, cloud.points)
        yield ros.StampedCloud(cloud.stamp_ns, target_frame, points, cloud.times)


def iter_log_positions(path: str | os.PathLike[str], topic: str) -> Iterator[PositionSample]:
    """Positions of a ``foxglove.PoseInFrame``, ``cldet.Estimate``, ``PointStamped`` or
    ``PoseStamped`` topic, (3,) float64, at their header stamps (a log written by cldet: the log
    time, which is the message's own stamp there).

    Raises:
        LogError: the log cannot be read; CorruptMessageError: a message does not decode.
    """
    with open_log(path) as reader:
        yield from reader_positions(reader, topic)


def reader_positions(reader: LogReader, topic: str) -> Iterator[PositionSample]:
    """:func:`iter_log_positions` on an open log."""
    decoders = _Decoders(ros.message_decoder)

    def convert(kind: str, schema: Any, channel: Any, data: bytes) -> PositionSample:
        stamp, xyz = ros.position_of(decoders.decode(schema, channel, data), kind)
        return PositionSample(stamp, xyz)

    if _kind(reader.schema_name(topic)) in (topics.SCHEMA_POSE_IN_FRAME, topics.SCHEMA_ESTIMATE):
        yield from reader.iter_positions(topic)  # cldet's logs: log time = own stamp
    else:
        yield from _iter_decoded(reader, topic, convert)
