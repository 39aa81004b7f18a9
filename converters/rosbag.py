"""Convert a ROS bag (a ROS 1 ``.bag`` file, or a ROS 2 bag folder in ``.db3`` or ``.mcap``) to
cldet's MCAP layout, through the ``rosbags`` library (no ROS installation).

The log holds what ``cldet convert`` writes from the challenge's numpy folders (see
:mod:`cldet.io.topics`): ``/lidar_360`` and ``/livox_avia`` (``foxglove.PointCloud``, frame
``mid360``, finite points only, the Avia moved into the Mid-360's frame by the bag's
``/tf_static`` when it connects them), ``/radar_enhance_pcl`` and ``/ground_truth``, every
message stamped with its header stamp in integer nanoseconds (a Livox ``CustomMsg``: its
``timebase``). Which bag topic feeds which channel is a :class:`BagTopics`; the defaults are the
raw MMAUD recordings' topics.
"""

from __future__ import annotations

import heapq
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader, AnyReaderError

from cldet import __version__
from cldet.errors import CldetError, DatasetError
from cldet.io import ros, topics
from cldet.io.files import atomic_output
from cldet.io.mcap_write import Compression, LogWriter
from cldet.io.transforms import sensor_tree
from cldet.progress import NullProgress, Progress

__all__ = ["BagTopics", "convert_bag", "is_bag"]

_REORDER_NS = 1_000_000_000  # messages are written in header-stamp order within this window


@dataclass(frozen=True)
class BagTopics:
    """Which bag topic feeds which channel of the log (None: none; a prefix ends with ``/``)."""

    lidar: str = "/livox_mid360/lidar"  # livox_ros_driver2/CustomMsg in MMAUD
    avia: str | None = "/livox_avia/lidar"  # livox_ros_driver/CustomMsg
    radar: str | None = "/radar_enhance_pcl"  # sensor_msgs/PointCloud
    truth: str | None = "/leica/point/"  # geometry_msgs/PointStamped: the first topic under it


def is_bag(path: Path) -> bool:
    """True for a ROS 1 ``.bag`` file or a ROS 2 bag folder (one holding ``metadata.yaml``)."""
    return (path.is_file() and path.suffix == ".bag") or (path / "metadata.yaml").is_file()


def _listing(types: dict[str, str]) -> str:
    return ", ".join(f"{t} ({s})" for t, s in sorted(types.items())) or "none"


def _pick(
    bag: Path,
    types: dict[str, str],
    wanted: str | None,
    allowed: tuple[str, ...],
    what: str,
    required: bool,
) -> str | None:
    """The bag topic for one channel: ``wanted`` itself, or the first under a ``wanted/`` prefix."""
    if wanted is None:
        return None
    if wanted.endswith("/"):
        matches = sorted(t for t in types if t.startswith(wanted))
        found = matches[0] if matches else None
    else:
        found = wanted if wanted in types else None
    if found is None:
        if required:
            raise DatasetError(
                f"{bag}: no {what} topic {wanted}; expected one of {', '.join(allowed)}; "
                f"topics in the bag: {_listing(types)}"
            )
        return None
    if ros.normalize_type(types[found]) not in allowed:
        raise DatasetError(
            f"{bag}: topic {found} carries {types[found]}, expected {what}: one of {', '.join(allowed)}"
        )
    return found


def convert_bag(
    bag: Path,
    writer: LogWriter,
    *,
    bag_topics: BagTopics | None = None,
    progress: Progress | None = None,
) -> dict[str, int]:
    """Write one bag into an open :class:`LogWriter`, in header-stamp order.

    Args:
        bag: a ROS 1 ``.bag`` file or a ROS 2 bag folder.
        writer: where the messages go; not finished here (the caller owns it).
        bag_topics: the bag topics to read (default: the MMAUD raw topics). A missing LiDAR
            topic is an error; a missing default Avia, radar or truth topic is left out.
        progress: advanced by one per message written.

    Returns:
        Messages written per log topic.

    Raises:
        DatasetError: the bag cannot be read, has no such LiDAR topic (the message lists the
            topics with their types), a topic carries another type, or a message is malformed.
    """
    chosen = bag_topics or BagTopics()
    bar = progress if progress is not None else NullProgress()
    try:
        reader = AnyReader([Path(bag)])
        reader.open()
    except (AnyReaderError, OSError) as err:  # not a bag, a missing or unreadable file
        raise DatasetError(f"{bag} is not a readable ROS bag: {err}") from err
    try:
        types = {name: info.msgtype or "" for name, info in reader.topics.items()}
        defaults = BagTopics()
        lidar = _pick(bag, types, chosen.lidar, ros.CLOUD_TYPES, "a point cloud", True)
        avia = _pick(
            bag, types, chosen.avia, ros.CLOUD_TYPES, "a point cloud", chosen.avia != defaults.avia
        )
        radar = _pick(
            bag,
            types,
            chosen.radar,
            ros.CLOUD_TYPES,
            "a point cloud",
            chosen.radar != defaults.radar,
        )
        truth = _pick(
            bag,
            types,
            chosen.truth,
            ros.POSITION_TYPES,
            "positions",
            chosen.truth != defaults.truth,
        )
        assert lidar is not None
        targets = {lidar: topics.LIDAR_360}
        targets.update(
            {
                t: c
                for t, c in (
                    (avia, topics.LIVOX_AVIA),
                    (radar, topics.RADAR),
                    (truth, topics.GROUND_TRUTH),
                )
                if t
            }
        )
        transforms = _static_transforms(reader, types)
        counts = dict.fromkeys(targets.values(), 0)
        bar.start(sum(reader.topics[t].msgcount for t in targets), f"{Path(bag).name}: converting")
        lidar_frame: list[str] = []
        tree_written = False
        for stamp_ns, channel, item in _in_stamp_order(_items(bag, reader, targets)):
            if not tree_written:  # the static frame tree, at the first stamp
                writer.write_transforms(topics.TF, stamp_ns, sensor_tree())
                tree_written = True
            if isinstance(item, ros.StampedCloud):
                points = item.points
                if channel == topics.LIDAR_360 and not lidar_frame:
                    lidar_frame.append(item.frame_id)
                if channel == topics.LIVOX_AVIA and lidar_frame and transforms:
                    matrix = ros.static_transform(transforms, lidar_frame[0], item.frame_id)
                    if matrix is not None:
                        points = ros.transform_points(matrix, points)
                frame = topics.FRAME_RADAR if channel == topics.RADAR else topics.FRAME_MID360
                writer.write_timed_cloud(channel, stamp_ns, points, item.times, frame)
            else:
                writer.write_pose(channel, stamp_ns, item, topics.FRAME_MID360)
            counts[channel] += 1
            bar.advance(1)
        meta = {
            "split": "",
            "sequence": Path(bag).stem,
            "source": str(Path(bag).resolve()),
            "modalities": ",".join(targets.values()),
            "cldet_version": __version__,
            "bag_topics": ",".join(f"{b}={c}" for b, c in targets.items()),
        }
        meta.update({f"count.{c}": str(n) for c, n in counts.items()})
        meta["frames"] = str(sum(counts.values()))
        writer.write_metadata(topics.METADATA_SOURCE, meta)
        return counts
    finally:
        reader.close()


def _static_transforms(reader: AnyReader, types: dict[str, str]) -> list[ros.FrameTransform]:
    if ros.normalize_type(types.get(ros.TF_STATIC, "")) != ros.TF_MESSAGE:
        return []
    connections = [c for c in reader.connections if c.topic == ros.TF_STATIC]
    out: list[ros.FrameTransform] = []
    for connection, _, raw in reader.messages(connections=connections):
        out.extend(ros.transforms_of(reader.deserialize(raw, connection.msgtype)))
    return out


def _items(bag: Path, reader: AnyReader, targets: dict[str, str]) -> Iterator[tuple[int, str, Any]]:
    """``(stamp_ns, log channel, StampedCloud or (3,) position)`` in bag order."""
    connections = [c for c in reader.connections if c.topic in targets]
    encoding = "cdr" if reader.is2 else "ros1"
    fast = {c.id: ros.livox_decoder(reader.typestore, c.msgtype, encoding) for c in connections}
    for connection, log_ns, raw in reader.messages(connections=connections):
        channel = targets[connection.topic]
        try:
            livox = fast[connection.id]
            if livox is not None:  # Livox CustomMsg: straight from the bytes
                cloud = livox(raw)
                yield cloud.stamp_ns, channel, cloud
                continue
            message = reader.deserialize(raw, connection.msgtype)
            if channel == topics.GROUND_TRUTH:
                stamp, position = ros.position_of(message, connection.msgtype)
                yield stamp, channel, position
            else:
                cloud = ros.ros_cloud(message, connection.msgtype)
                yield cloud.stamp_ns, channel, cloud
        except (AnyReaderError, ValueError, struct.error) as err:  # undecodable, a bad cloud
            raise DatasetError(
                f"{bag}: the message on {connection.topic} recorded at {log_ns} ns cannot be "
                f"read as {connection.msgtype}: {err}"
            ) from err


def _in_stamp_order(items: Iterator[tuple[int, str, Any]]) -> Iterator[tuple[int, str, Any]]:
    """The items sorted by stamp within a sliding window (a bag is in arrival order)."""
    heap: list[tuple[int, int, str, Any]] = []
    newest = None
    for n, (stamp, channel, item) in enumerate(items):
        heapq.heappush(heap, (stamp, n, channel, item))
        newest = stamp if newest is None else max(newest, stamp)
        while heap and heap[0][0] < newest - _REORDER_NS:
            s, _, c, i = heapq.heappop(heap)
            yield s, c, i
    while heap:
        s, _, c, i = heapq.heappop(heap)
        yield s, c, i


def convert_bag_file(
    bag: Path,
    target: Path,
    *,
    bag_topics: BagTopics | None = None,
    compression: Compression | str = Compression.zstd,
    overwrite: bool = False,
    progress: Progress | None = None,
) -> dict[str, int]:
    """Convert ``bag`` into the log ``target``, written to a temporary file renamed into place.

    Raises:
        DatasetError: as :func:`convert_bag`; OutputExistsError: ``target`` exists and
            ``overwrite`` is false; CldetError: the output folder cannot be created.
    """
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise CldetError(f"cannot create output folder {target.parent}: {err}") from err
    with (
        atomic_output(target, overwrite=overwrite) as stream,
        LogWriter(stream, compression=compression) as writer,
    ):
        return convert_bag(bag, writer, bag_topics=bag_topics, progress=progress)
