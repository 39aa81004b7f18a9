"""ROS recordings for the tests, written with independent writers only (never cldet's own).

ROS 2 MCAP logs with ``mcap-ros2-support``'s writer; ROS 1 bags and ROS 2 bag folders with
``rosbags``' writers. The message definitions are written out here, as a ROS 2 recorder stores
them, Livox's ``CustomMsg`` included.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from mcap_ros2.writer import Writer as Ros2Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

SEP = "=" * 80 + "\n"
TIME = "int32 sec\nuint32 nanosec\n"
HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
POINT_FIELD = "uint8 INT8=1\nuint8 UINT8=2\nuint8 INT16=3\nuint8 UINT16=4\nuint8 INT32=5\nuint8 UINT32=6\nuint8 FLOAT32=7\nuint8 FLOAT64=8\nstring name\nuint32 offset\nuint8 datatype\nuint32 count\n"
POINT_CLOUD2 = (
    "std_msgs/Header header\nuint32 height\nuint32 width\nPointField[] fields\n"
    "bool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n"
    f"{SEP}MSG: std_msgs/Header\n{HEADER}{SEP}MSG: builtin_interfaces/Time\n{TIME}"
    f"{SEP}MSG: sensor_msgs/PointField\n{POINT_FIELD}"
)
STRING = "string data\n"
VECTOR3 = "float64 x\nfloat64 y\nfloat64 z\n"
QUATERNION = "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"
TF_MESSAGE = (
    "geometry_msgs/TransformStamped[] transforms\n"
    f"{SEP}MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\n"
    "Transform transform\n"
    f"{SEP}MSG: std_msgs/Header\n{HEADER}{SEP}MSG: builtin_interfaces/Time\n{TIME}"
    f"{SEP}MSG: geometry_msgs/Transform\nVector3 translation\nQuaternion rotation\n"
    f"{SEP}MSG: geometry_msgs/Vector3\n{VECTOR3}{SEP}MSG: geometry_msgs/Quaternion\n{QUATERNION}"
)
POINT_STAMPED = (
    "std_msgs/Header header\nPoint point\n"
    f"{SEP}MSG: std_msgs/Header\n{HEADER}{SEP}MSG: builtin_interfaces/Time\n{TIME}"
    f"{SEP}MSG: geometry_msgs/Point\n{VECTOR3}"
)
# Livox's driver messages (livox_ros_driver2/msg/CustomMsg.msg and CustomPoint.msg)
CUSTOM_POINT = (
    "uint32 offset_time\nfloat32 x\nfloat32 y\nfloat32 z\nuint8 reflectivity\nuint8 tag\n"
    "uint8 line\n"
)
CUSTOM_MSG = (
    "std_msgs/Header header\nuint64 timebase\nuint32 point_num\nuint8 lidar_id\n"
    "uint8[3] rsvd\nCustomPoint[] points\n"
)

CUSTOM_MSG2 = (
    f"{CUSTOM_MSG}{SEP}MSG: std_msgs/Header\n{HEADER}{SEP}MSG: builtin_interfaces/Time\n{TIME}"
    f"{SEP}MSG: livox_ros_driver2/CustomPoint\n{CUSTOM_POINT}"
)

FIELD_TYPES = {"i1": 1, "u1": 2, "i2": 3, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}


def ros_time(stamp_ns: int) -> dict[str, int]:
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}


def point_cloud2(
    stamp_ns: int,
    frame_id: str,
    points: np.ndarray,
    *,
    xyz: str = "f4",
    extra: Iterable[tuple[str, str]] = (),
    values: Mapping[str, np.ndarray] | None = None,
    big_endian: bool = False,
    lead: int = 0,
    point_step: int | None = None,
    data: bytes | None = None,
    drop: str = "",
) -> dict[str, Any]:
    """A PointCloud2 (as a dict for mcap-ros2-support) of (N, 3) points.

    ``lead`` bytes of padding come before x, y, z (which are ``xyz`` typed), then the ``extra``
    (name, numpy type) fields, holding ``values[name]`` (7s where ``values`` has no such name);
    ``drop`` names a field left out of the list.
    """
    order = ">" if big_endian else "<"
    names = ["x", "y", "z", *(n for n, _ in extra)]
    kinds = [xyz, xyz, xyz, *(k for _, k in extra)]
    offsets, at = [], lead
    for kind in kinds:
        offsets.append(at)
        at += np.dtype(kind).itemsize
    dtype = np.dtype(
        {
            "names": names,
            "formats": [order + k for k in kinds],
            "offsets": offsets,
            "itemsize": at,
        }
    )
    records = np.zeros(len(points), dtype=dtype)
    for i, axis in enumerate("xyz"):
        records[axis] = points[:, i]
    for name, _ in extra:
        records[name] = (values or {}).get(name, 7)
    fields = [
        {"name": n, "offset": o, "datatype": FIELD_TYPES[k], "count": 1}
        for n, o, k in zip(names, offsets, kinds, strict=True)
        if n != drop
    ]
    return {
        "header": {"stamp": ros_time(stamp_ns), "frame_id": frame_id},
        "height": 1,
        "width": len(points),
        "fields": fields,
        "is_bigendian": big_endian,
        "point_step": point_step if point_step is not None else at,
        "row_step": at * len(points),
        "data": records.tobytes() if data is None else data,
        "is_dense": False,
    }


def custom_msg_dict(stamp_ns: int, frame_id: str, points: np.ndarray) -> dict[str, Any]:
    """A Livox CustomMsg (as a dict for mcap-ros2-support), stamped by its timebase only."""
    return {
        "header": {"stamp": ros_time(0), "frame_id": frame_id},  # the driver's header: unused
        "timebase": stamp_ns,
        "point_num": len(points),
        "lidar_id": 1,
        "rsvd": [0, 0, 0],
        "points": [
            {
                "offset_time": i,
                "x": float(p[0]),
                "y": float(p[1]),
                "z": float(p[2]),
                "reflectivity": 9,
                "tag": 0,
                "line": i % 4,
            }
            for i, p in enumerate(points)
        ],
    }


def tf_static(transforms: Iterable[tuple[str, str, tuple[float, ...], tuple[float, ...]]]) -> dict:
    """A TFMessage of (parent, child, translation xyz, rotation xyzw)."""
    return {
        "transforms": [
            {
                "header": {"stamp": ros_time(0), "frame_id": parent},
                "child_frame_id": child,
                "transform": {
                    "translation": dict(zip("xyz", t, strict=True)),
                    "rotation": dict(zip("xyzw", q, strict=True)),
                },
            }
            for parent, child, t, q in transforms
        ]
    }


class Ros2Log:
    """A ROS 2 MCAP log being written with mcap-ros2-support (a context manager)."""

    def __init__(self, path: Path) -> None:
        self._file = open(path, "wb")  # noqa: SIM115 - closed in __exit__
        self._writer = Ros2Writer(self._file)
        self._schemas: dict[str, Any] = {}

    def __enter__(self) -> Ros2Log:
        return self

    def __exit__(self, *exc: object) -> None:
        self._writer.finish()
        self._file.close()

    def write(self, topic: str, datatype: str, definition: str, message: dict, log_ns: int) -> None:
        schema = self._schemas.get(datatype)
        if schema is None:
            schema = self._schemas[datatype] = self._writer.register_msgdef(datatype, definition)
        self._writer.write_message(topic, schema, message, log_time=log_ns, publish_time=log_ns)


def livox_typestore(store: Stores = Stores.ROS1_NOETIC) -> Typestore:
    """A rosbags typestore with both Livox drivers' CustomMsg (and CustomPoint) registered."""
    typestore = get_typestore(store)
    types: dict[str, Any] = {}
    for package in ("livox_ros_driver", "livox_ros_driver2"):
        types.update(get_types_from_msg(CUSTOM_POINT, f"{package}/msg/CustomPoint"))
        types.update(get_types_from_msg(CUSTOM_MSG, f"{package}/msg/CustomMsg"))
    typestore.register(types)
    return typestore


def custom_msg(typestore: Typestore, package: str, stamp_ns: int, points: np.ndarray) -> Any:
    """A Livox CustomMsg (rosbags object) of (N, 3) points, stamped by its timebase."""
    types = typestore.types
    point = types[f"{package}/msg/CustomPoint"]
    header = types["std_msgs/msg/Header"]
    time = types["builtin_interfaces/msg/Time"]
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    header_args: dict[str, Any] = {
        "stamp": time(sec=sec, nanosec=nanosec),
        "frame_id": "livox_frame",
    }
    if any(name == "seq" for name, _ in typestore.fielddefs["std_msgs/msg/Header"][1]):
        header_args["seq"] = 0  # ROS 1's Header
    made = header(**header_args)
    return types[f"{package}/msg/CustomMsg"](
        header=made,
        timebase=stamp_ns,
        point_num=len(points),
        lidar_id=0,
        rsvd=np.zeros(3, np.uint8),
        points=[
            point(
                offset_time=i,
                x=float(p[0]),
                y=float(p[1]),
                z=float(p[2]),
                reflectivity=10,
                tag=0,
                line=0,
            )
            for i, p in enumerate(points)
        ],
    )
