"""ROS messages (ROS 1 and ROS 2) into cldet's plain data: point clouds, positions, transforms.

The decoding is the ``rosbags`` library's (message definitions parsed from the log or the bag,
CDR and ROS 1 serialization); this module picks the fields out of the decoded messages. Every
stamp is integer nanoseconds from the message's own header (a Livox ``CustomMsg``: its
``timebase``), never the time a recorder received it.

Supported point clouds: ``sensor_msgs/msg/PointCloud2`` (x, y, z float32 or float64 at any
offset, either byte order; a per-point time field as below; other fields ignored),
``livox_ros_driver2/msg/CustomMsg`` and ``livox_ros_driver/msg/CustomMsg`` (``offset_time``),
``sensor_msgs/msg/PointCloud`` (radar). Non-finite points are dropped.

A PointCloud2's points are dated by the first of the fields ``offset_time``, ``t``, ``time``
and ``timestamp`` it has (one number a point). The drivers disagree on what it holds, so its
type and size tell: integers are nanoseconds after the header stamp (Ouster's ``t``, Livox's
``offset_time``), floats seconds after it (Velodyne's ``time``), but floats from 1e8 up are
times since the epoch, in whichever of seconds (Hesai's and RoboSense's ``timestamp``),
milliseconds, microseconds or nanoseconds (livox_ros_driver2's ``timestamp``) puts the
first point nearest the stamp. Times that are not finite, or lie more than ``MAX_SCAN_S``
from the stamp, are not used: the cloud is then read as one without times (every point at
the configured ``frames.scan_offset_s``).

Positions: ``geometry_msgs/msg/PointStamped`` and ``PoseStamped``. Transforms:
``tf2_msgs/msg/TFMessage`` (``/tf_static``).
"""

from __future__ import annotations

import functools
import struct
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray
from rosbags.typesys import (
    Stores,
    TypesysError,
    get_types_from_idl,
    get_types_from_msg,
    get_typestore,
)
from rosbags.typesys.base import Nodetype
from rosbags.typesys.store import Typestore

from cldet.stamps import NS_PER_S

__all__ = [
    "CLOUD_TYPES",
    "MAX_SCAN_S",
    "POINT_TIME_FIELDS",
    "POSITION_TYPES",
    "TF_MESSAGE",
    "TF_STATIC",
    "FrameTransform",
    "cloud_decoder",
    "livox_decoder",
    "StampedCloud",
    "message_decoder",
    "normalize_type",
    "position_of",
    "ros_cloud",
    "static_transform",
    "transform_points",
    "transforms_of",
]

POINT_CLOUD2: Final = "sensor_msgs/msg/PointCloud2"
POINT_CLOUD: Final = "sensor_msgs/msg/PointCloud"  # ROS 1 era radar clouds: Point32[] points
LIVOX_CUSTOM: Final = ("livox_ros_driver2/msg/CustomMsg", "livox_ros_driver/msg/CustomMsg")
CLOUD_TYPES: Final = (POINT_CLOUD2, *LIVOX_CUSTOM, POINT_CLOUD)
POINT_STAMPED: Final = "geometry_msgs/msg/PointStamped"
POSE_STAMPED: Final = "geometry_msgs/msg/PoseStamped"
POSITION_TYPES: Final = (POINT_STAMPED, POSE_STAMPED)
TF_MESSAGE: Final = "tf2_msgs/msg/TFMessage"
TF_STATIC: Final = "/tf_static"  # the topic of the static transforms

# sensor_msgs/PointField datatype -> numpy type (without byte order)
_POINT_FIELD_TYPES: Final = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
_FLOATS: Final = {7: "f4", 8: "f8"}
_IDL_SEPARATOR = "=" * 80 + "\n"


def normalize_type(name: str) -> str:
    """A ROS message type as ``pkg/msg/Name`` (ROS 1 writes ``pkg/Name``)."""
    parts = name.strip("/").split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return "/".join(parts)


@functools.lru_cache(maxsize=64)
def _typestore(schema_name: str, schema_encoding: str, schema_data: bytes) -> tuple[Typestore, str]:
    """A rosbags typestore holding one schema's definitions, and the type's ``pkg/msg/Name``.

    Cached per definition: rosbags generates a type's deserializer on its first message (tens of
    milliseconds), once per process instead of once per topic read.
    """
    typename = normalize_type(schema_name)
    text = schema_data.decode("utf-8", "replace")
    if schema_encoding not in ("ros2msg", "ros1msg", "ros2idl"):
        raise ValueError(f"schema encoding {schema_encoding!r} is not a ROS one")
    try:
        if schema_encoding == "ros2idl":
            types = {}
            chunks = text.split(_IDL_SEPARATOR)[1:] if text.startswith(_IDL_SEPARATOR) else [text]
            for chunk in chunks:
                idl = chunk.split("\n", 1)[1] if chunk.startswith("IDL: ") else chunk
                types.update(get_types_from_idl(idl))
        else:
            types = get_types_from_msg(text, typename)
        store = get_typestore(Stores.EMPTY)
        store.register(types)
    except TypesysError as err:
        raise ValueError(f"cannot parse the definition of {schema_name}: {err}") from err
    return store, typename


def _deserializer(store: Typestore, typename: str, message_encoding: str) -> Callable[[bytes], Any]:
    if message_encoding == "cdr":
        return lambda raw: store.deserialize_cdr(raw, typename)
    if message_encoding == "ros1":
        return lambda raw: store.deserialize_ros1(raw, typename)
    raise ValueError(f"message encoding {message_encoding!r} is not cdr or ros1")


def message_decoder(
    schema_name: str, schema_encoding: str, schema_data: bytes, message_encoding: str
) -> Callable[[bytes], Any]:
    """A function deserializing the messages of one MCAP schema (rosbags' deserializers).

    Args:
        schema_name: the message type, ``pkg/msg/Name`` or ``pkg/Name``.
        schema_encoding: ``ros2msg``, ``ros2idl`` or ``ros1msg``.
        schema_data: the message definition with its dependencies, as a ROS recorder stores it.
        message_encoding: ``cdr`` (ROS 2) or ``ros1``.

    Raises:
        ValueError: the encodings are not ROS ones, or the definition cannot be parsed.
    """
    store, typename = _typestore(schema_name, schema_encoding, schema_data)
    return _deserializer(store, typename, message_encoding)


def cloud_decoder(
    schema_name: str, schema_encoding: str, schema_data: bytes, message_encoding: str
) -> Callable[[bytes], StampedCloud]:
    """A function reading the point clouds of one MCAP schema (see :func:`message_decoder`).

    A Livox ``CustomMsg`` of the drivers' own definition is read straight from its bytes
    (:func:`livox_decoder`); everything else is deserialized by rosbags.
    """
    store, typename = _typestore(schema_name, schema_encoding, schema_data)
    fast = livox_decoder(store, typename, message_encoding)
    if fast is not None:
        return fast
    deserialize = _deserializer(store, typename, message_encoding)
    return lambda raw: ros_cloud(deserialize(raw), typename)


@dataclass(frozen=True)
class StampedCloud:
    """The points of one point-cloud message, with its own stamp and frame."""

    stamp_ns: int  # the header stamp (a Livox CustomMsg: its timebase), integer ns
    frame_id: str
    points: NDArray[np.float32]  # (N, 3) x, y, z metres, finite rows only
    times: NDArray[np.float32] | None = None  # (N,) firing times after stamp_ns, s (Cloud.times)


def header_stamp_ns(header: Any) -> int:
    """A ``std_msgs/Header``'s stamp as integer nanoseconds."""
    return int(header.stamp.sec) * NS_PER_S + int(header.stamp.nanosec)


def _finite(points: NDArray[np.float32]) -> NDArray[np.float32]:
    """The rows of (N, 3) ``points`` without a NaN or infinity (``points`` itself when all are)."""
    return _finite_timed(points, None)[0]


def _finite_timed(
    points: NDArray[np.float32], times: NDArray[np.float32] | None
) -> tuple[NDArray[np.float32], NDArray[np.float32] | None]:
    """``_finite`` and the kept rows' ``times`` (N,), where there are any."""
    finite = np.isfinite(points)
    if finite.all():  # one pass over the flat array: far cheaper than a per-row reduction
        return points, times
    keep = finite.all(axis=1)
    return points[keep], None if times is None else times[keep]


_NS = 1e-9  # a Livox point's offset_time is in nanoseconds after the message's timebase
# a PointCloud2's per-point time fields, in the order they are looked for (module docstring)
POINT_TIME_FIELDS: Final = ("offset_time", "t", "time", "timestamp")
MAX_SCAN_S: Final = 1.0  # point times farther from the stamp than this are not a scan's


def _seconds_after(values: NDArray[Any], stamp_ns: int) -> NDArray[np.float32] | None:
    """A PointCloud2 time field's ``values`` as seconds after ``stamp_ns`` (module docstring);
    None where they are not finite or not within ``MAX_SCAN_S`` of it."""
    seconds = values.astype(np.float64)
    if values.dtype.kind in "iu":  # nanoseconds after the stamp (PointField has no 64-bit int)
        seconds *= _NS
    elif len(values) and np.isfinite(values).all():
        first = float(seconds[0])
        if abs(first) >= 1e8:  # since the epoch, in the unit that puts it nearest the stamp
            ns_per_unit = min((1e9, 1e6, 1e3, 1.0), key=lambda u: abs(first * u - stamp_ns))
            seconds = (seconds * ns_per_unit - stamp_ns) * _NS
    if not (np.abs(seconds) <= MAX_SCAN_S).all():  # NaN too
        return None
    return seconds.astype(np.float32)


def _point_cloud2(msg: Any) -> tuple[NDArray[np.float32], NDArray[np.float32] | None]:
    """The finite points of a ``sensor_msgs/PointCloud2``, (N, 3) float32, and their times after
    the header stamp (None: no usable time field); ValueError says what is wrong."""
    fields = {f.name: f for f in msg.fields}
    listing = ", ".join(
        f"{f.name} ({_POINT_FIELD_TYPES.get(f.datatype, f.datatype)})" for f in msg.fields
    )
    expected = "x, y, z fields of float32 or float64"
    for axis in "xyz":
        if axis not in fields:
            raise ValueError(
                f"PointCloud2 without a {axis} field; expected {expected}, found: {listing or 'no fields'}"
            )
        if fields[axis].datatype not in _FLOATS:
            raise ValueError(
                f"PointCloud2 field {axis} is {_POINT_FIELD_TYPES.get(fields[axis].datatype, fields[axis].datatype)}; expected {expected}"
            )
    step = int(msg.point_step)
    for f in msg.fields:
        size = np.dtype(_POINT_FIELD_TYPES.get(f.datatype, "u1")).itemsize * max(int(f.count), 1)
        if f.offset + size > step:
            raise ValueError(
                f"PointCloud2 point_step {step} is smaller than its fields "
                f"({f.name} at offset {f.offset} takes {size} bytes)"
            )
    width, height, row_step = int(msg.width), int(msg.height), int(msg.row_step)
    if width and height and row_step < width * step:
        raise ValueError(f"PointCloud2 row_step {row_step} < width {width} x point_step {step}")
    data = np.asarray(msg.data, dtype=np.uint8)
    needed = (height - 1) * row_step + width * step if width and height else 0
    if len(data) < needed:
        raise ValueError(
            f"PointCloud2 data is truncated: {len(data)} bytes for {height} x {width} points "
            f"of {step} bytes (expected {needed})"
        )
    if not needed:
        return np.zeros((0, 3), np.float32), None
    order = ">" if msg.is_bigendian else "<"
    times = _point_cloud2_times(msg, fields, data, order)
    packed = [int(fields[a].offset) for a in "xyz"] == [0, 4, 8]
    if (
        packed
        and not msg.is_bigendian
        and all(fields[a].datatype == 7 for a in "xyz")
        and step % 4 == 0
        and row_step == width * step
    ):  # the common layout: a view of the bytes, no copy (as foxglove.PointCloud is read)
        flat = np.frombuffer(data, dtype="<f4", count=height * width * step // 4)
        xyz = flat.reshape(height * width, step // 4)[:, :3]
        # every float of the buffer finite (one contiguous pass): so are x, y, z
        return (xyz, times) if np.isfinite(flat).all() else _finite_timed(xyz, times)
    dtype = np.dtype(
        {
            "names": ["x", "y", "z"],
            "formats": [order + _FLOATS[fields[a].datatype] for a in "xyz"],
            "offsets": [int(fields[a].offset) for a in "xyz"],
            "itemsize": step,
        }
    )
    grid = np.ndarray((height, width), dtype=dtype, buffer=data, strides=(row_step, step))
    points = np.empty((height * width, 3), np.float32)
    for i, axis in enumerate("xyz"):
        points[:, i] = grid[axis].reshape(-1)
    return _finite_timed(points, times)


def _point_cloud2_times(
    msg: Any, fields: dict[str, Any], data: NDArray[np.uint8], order: str
) -> NDArray[np.float32] | None:
    """(N,) seconds after the header stamp of a PointCloud2's first time field (module
    docstring), every point's, finite or not; None without a usable one."""
    name = next((n for n in POINT_TIME_FIELDS if n in fields), None)
    if name is None:
        return None
    field = fields[name]
    kind = _POINT_FIELD_TYPES.get(field.datatype)
    if kind is None or int(field.count) > 1:
        return None
    dtype = np.dtype(
        {
            "names": ["t"],
            "formats": [order + kind],
            "offsets": [int(field.offset)],
            "itemsize": int(msg.point_step),
        }
    )
    values = np.ndarray(
        (int(msg.height), int(msg.width)),
        dtype=dtype,
        buffer=data,
        strides=(int(msg.row_step), int(msg.point_step)),
    )["t"].reshape(-1)
    return _seconds_after(values, header_stamp_ns(msg.header))


def _point_list_xyz(points: Iterable[Any]) -> NDArray[np.float32]:
    """(N, 3) float32 of a list of messages with x, y, z (Livox CustomPoint, Point32)."""
    xyz = np.array([(p.x, p.y, p.z) for p in points], dtype=np.float32)
    return xyz.reshape(-1, 3)


def ros_cloud(msg: Any, typename: str) -> StampedCloud:
    """The stamp, frame and finite points of a decoded point-cloud message of ``typename``.

    Raises:
        ValueError: the type is not a supported point cloud, or the message is malformed (a
            PointCloud2 without x, y, z, a point_step smaller than its fields, truncated data).
            A PointCloud2 time field that is not usable is not an error (module docstring).
    """
    typename = normalize_type(typename)
    times = None
    if typename == POINT_CLOUD2:
        points, times = _point_cloud2(msg)
        stamp = header_stamp_ns(msg.header)
    elif typename in LIVOX_CUSTOM:
        offsets = np.array([p.offset_time for p in msg.points], dtype=np.float64) * _NS
        points, times = _finite_timed(_point_list_xyz(msg.points), offsets.astype(np.float32))
        stamp = int(msg.timebase)
    elif typename == POINT_CLOUD:
        points = _finite(_point_list_xyz(msg.points))
        stamp = header_stamp_ns(msg.header)
    else:
        raise ValueError(
            f"{typename} is not a point cloud; expected one of {', '.join(CLOUD_TYPES)}"
        )
    frame_id = msg.header.frame_id.lstrip("/")
    return StampedCloud(stamp_ns=stamp, frame_id=frame_id, points=points, times=times)


# --- Livox CustomMsg straight from its bytes ----------------------------------------------------
# rosbags builds one Python object per point (about 50 ms for a 20,000-point scan, against
# 0.4 ms to read a foxglove.PointCloud of it: benchmarks/bench_ros_read.py); the drivers' layout
# is fixed, so the points are read as a strided view instead. rosbags stays the reference in the
# tests (tests/test_ros_livox.py).
_LIVOX_MSG_FIELDS: Final = [
    ("timebase", "uint64"),
    ("point_num", "uint32"),
    ("lidar_id", "uint8"),
    ("rsvd", "uint8[3]"),
    ("points", "CustomPoint[]"),
]
_LIVOX_POINT_FIELDS: Final = [
    ("offset_time", "uint32"),
    ("x", "float32"),
    ("y", "float32"),
    ("z", "float32"),
    ("reflectivity", "uint8"),
    ("tag", "uint8"),
    ("line", "uint8"),
]
_LIVOX_XYZ_OFFSET = 4  # x, y, z after offset_time
_CDR_POINT_STRIDE = 20  # 19 bytes, the next point's uint32 aligned to 4
_ROS1_POINT_STRIDE = 19  # packed


def _field_types(store: Typestore, typename: str) -> list[tuple[str, str]]:
    """``(name, type)`` of a registered type's fields, types spelt as in a ``.msg`` file."""
    out: list[tuple[str, str]] = []
    fields: Any = store.fielddefs[typename][1]  # rosbags' nested (kind, detail) tuples
    for name, (kind, detail) in fields:
        if kind == Nodetype.BASE:
            out.append((name, detail[0]))
        elif kind == Nodetype.NAME:
            out.append((name, detail.rsplit("/", 1)[-1]))
        else:  # an array (fixed size) or a sequence, of a base type or a message
            (inner_kind, inner), size = detail
            inner_name = inner[0] if inner_kind == Nodetype.BASE else inner.rsplit("/", 1)[-1]
            out.append((name, f"{inner_name}[{size if kind == Nodetype.ARRAY else ''}]"))
    return out


def livox_decoder(
    store: Typestore, typename: str, message_encoding: str
) -> Callable[[bytes], StampedCloud] | None:
    """A reader of Livox ``CustomMsg`` bytes straight into points, or None.

    None unless ``typename`` is a Livox ``CustomMsg`` whose definition in ``store`` is the
    drivers' own (the reader relies on its layout) and the encoding is ``cdr`` or ``ros1``.
    """
    typename = normalize_type(typename)
    if typename not in LIVOX_CUSTOM or message_encoding not in ("cdr", "ros1"):
        return None
    try:
        fields = _field_types(store, typename)
        point = typename.rsplit("/", 1)[0] + "/CustomPoint"
        if fields[1:] != _LIVOX_MSG_FIELDS or _field_types(store, point) != _LIVOX_POINT_FIELDS:
            return None
    except (KeyError, ValueError, TypeError, IndexError):
        return None
    if message_encoding == "ros1":
        return _livox_ros1
    return _livox_cdr


def _livox_points(
    raw: bytes, start: int, n: int, stride: int, order: str, what: str
) -> tuple[NDArray[np.float32], NDArray[np.float32] | None]:
    """The finite points of a CustomMsg's point array and their times after its timebase, s."""
    need = start + (n - 1) * stride + _LIVOX_XYZ_OFFSET + 12 if n else start
    if len(raw) < need:
        raise ValueError(
            f"{what} is truncated: {len(raw)} bytes for {n} points (expected at least {need})"
        )
    dtype = np.dtype(
        {
            "names": ["t", "x", "y", "z"],
            "formats": [order + "u4"] + [order + "f4"] * 3,
            "offsets": [0, _LIVOX_XYZ_OFFSET, _LIVOX_XYZ_OFFSET + 4, _LIVOX_XYZ_OFFSET + 8],
            "itemsize": _LIVOX_XYZ_OFFSET + 12,
        }
    )
    records = np.ndarray((n,), dtype=dtype, buffer=raw, offset=start, strides=(stride,))
    points = np.empty((n, 3), np.float32)
    for i, axis in enumerate("xyz"):
        points[:, i] = records[axis]
    times = (records["t"].astype(np.float64) * _NS).astype(np.float32)
    return _finite_timed(points, times)


def _livox_cdr(raw: bytes) -> StampedCloud:
    """A CDR-encoded Livox CustomMsg (either byte order)."""
    if len(raw) < 16 or raw[0] != 0 or raw[1] not in (0, 1):
        raise ValueError("not a CDR-encoded message (bad encapsulation header)")
    order = "<" if raw[1] else ">"
    body = 4  # alignment counts from the end of the encapsulation header
    (length,) = struct.unpack_from(order + "I", raw, body + 8)  # after stamp sec, nanosec
    frame_id = raw[body + 12 : body + 12 + max(length - 1, 0)].decode("utf-8", "replace")
    pos = body + ((12 + length + 7) // 8) * 8  # timebase, aligned to 8
    timebase, _point_num = struct.unpack_from(order + "QI", raw, pos)
    pos += 8 + 4 + 4  # timebase, point_num, lidar_id and rsvd[3]
    (n,) = struct.unpack_from(order + "I", raw, pos)
    points, times = _livox_points(raw, pos + 4, n, _CDR_POINT_STRIDE, order, "Livox CustomMsg")
    return StampedCloud(int(timebase), frame_id.lstrip("/"), points, times)


def _livox_ros1(raw: bytes) -> StampedCloud:
    """A ROS 1-serialized Livox CustomMsg."""
    (length,) = struct.unpack_from("<I", raw, 12)  # after seq, stamp sec, nsec
    frame_id = raw[16 : 16 + length].decode("utf-8", "replace")
    pos = 16 + length
    timebase, _point_num = struct.unpack_from("<QI", raw, pos)
    pos += 8 + 4 + 4
    (n,) = struct.unpack_from("<I", raw, pos)
    points, times = _livox_points(raw, pos + 4, n, _ROS1_POINT_STRIDE, "<", "Livox CustomMsg")
    return StampedCloud(int(timebase), frame_id.lstrip("/"), points, times)


def position_of(msg: Any, typename: str) -> tuple[int, NDArray[np.float64]]:
    """``(stamp_ns, (3,) float64)`` of a decoded ``PointStamped`` or ``PoseStamped``.

    Raises:
        ValueError: the type is neither.
    """
    typename = normalize_type(typename)
    if typename == POINT_STAMPED:
        p = msg.point
    elif typename == POSE_STAMPED:
        p = msg.pose.position
    else:
        raise ValueError(
            f"{typename} is not a position; expected one of {', '.join(POSITION_TYPES)}"
        )
    return header_stamp_ns(msg.header), np.array((p.x, p.y, p.z), dtype=np.float64)


@dataclass(frozen=True)
class FrameTransform:
    """A rigid transform taking points in ``child`` coordinates into ``parent`` coordinates."""

    parent: str
    child: str
    matrix: NDArray[np.float64]  # (4, 4) homogeneous


def _quaternion_matrix(x: float, y: float, z: float, w: float) -> NDArray[np.float64]:
    norm = np.sqrt(x * x + y * y + z * z + w * w)
    if norm == 0:
        raise ValueError("a transform with a zero quaternion")
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def transform_points(
    matrix: NDArray[np.float64], points: NDArray[np.floating]
) -> NDArray[np.float32]:
    """(N, 3) points moved by a (4, 4) transform, computed in float64, returned as float32."""
    moved = points.astype(np.float64) @ matrix[:3, :3].T + matrix[:3, 3]
    return moved.astype(np.float32)


def transforms_of(msg: Any) -> list[FrameTransform]:
    """The transforms of a decoded ``tf2_msgs/TFMessage``."""
    out: list[FrameTransform] = []
    for t in msg.transforms:
        tr, q = t.transform.translation, t.transform.rotation
        matrix = np.eye(4)
        matrix[:3, :3] = _quaternion_matrix(q.x, q.y, q.z, q.w)
        matrix[:3, 3] = (tr.x, tr.y, tr.z)
        out.append(
            FrameTransform(t.header.frame_id.lstrip("/"), t.child_frame_id.lstrip("/"), matrix)
        )
    return out


def static_transform(
    transforms: Iterable[FrameTransform], target: str, source: str
) -> NDArray[np.float64] | None:
    """The (4, 4) transform taking points in frame ``source`` into frame ``target``.

    Follows the tree both ways (parent to child and back) from ``source`` to ``target``; the
    identity when the frames are the same; None when no chain of transforms connects them.
    """
    target, source = target.lstrip("/"), source.lstrip("/")
    edges: dict[str, list[tuple[str, NDArray[np.float64]]]] = {}
    for t in transforms:  # a later transform of the same pair wins: listed first
        edges.setdefault(t.child, []).insert(0, (t.parent, t.matrix))
        edges.setdefault(t.parent, []).insert(
            0, (t.child, np.asarray(np.linalg.inv(t.matrix), np.float64))
        )
    # breadth-first from source; each entry: frame, transform source -> frame
    seen = {source}
    queue: deque[tuple[str, NDArray[np.float64]]] = deque([(source, np.eye(4))])
    while queue:
        frame, to_frame = queue.popleft()
        if frame == target:
            return to_frame
        for nxt, step in edges.get(frame, []):
            if nxt not in seen:
                seen.add(nxt)
                queue.append((nxt, step @ to_frame))
    return None
