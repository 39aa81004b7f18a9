"""Livox CustomMsg read straight from its bytes, against rosbags' deserializer as the reference."""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from cldet.io import ros
from tests.ros_writers import CUSTOM_MSG, CUSTOM_POINT, custom_msg, livox_typestore

T0 = 1_706_255_621_600_227_000


def _reference(store, raw: bytes, typename: str, encoding: str) -> ros.StampedCloud:  # type: ignore[no-untyped-def]
    message = (
        store.deserialize_cdr(raw, typename)
        if encoding == "cdr"
        else store.deserialize_ros1(raw, typename)
    )
    return ros.ros_cloud(message, typename)


@pytest.mark.parametrize(
    ("stores", "encoding"), [(Stores.ROS2_HUMBLE, "cdr"), (Stores.ROS1_NOETIC, "ros1")]
)
@pytest.mark.parametrize("package", ["livox_ros_driver2", "livox_ros_driver"])
def test_the_byte_reader_matches_rosbags(stores: Stores, encoding: str, package: str) -> None:
    store = livox_typestore(stores)
    typename = f"{package}/msg/CustomMsg"
    fast = ros.livox_decoder(store, typename, encoding)
    assert fast is not None
    rng = np.random.default_rng(0)
    for n in (0, 1, 7, 200):
        for frame_length in range(0, 10):  # every alignment of the fields after frame_id
            points = rng.uniform(-50, 50, (n, 3)).astype(np.float32)
            if n > 3:
                points[2, 1] = np.nan
                points[3, 0] = np.inf
            message = custom_msg(store, package, T0 + n, points)
            message.header.frame_id = "f" * frame_length
            for little in (True, False) if encoding == "cdr" else (True,):
                raw = bytes(
                    store.serialize_cdr(message, typename, little_endian=little)
                    if encoding == "cdr"
                    else store.serialize_ros1(message, typename)
                )
                expected = _reference(store, raw, typename, encoding)
                got = fast(raw)
                assert got.stamp_ns == expected.stamp_ns == T0 + n
                assert got.frame_id == expected.frame_id == "f" * frame_length
                np.testing.assert_array_equal(got.points, expected.points)
                assert len(got.points) == (n - 2 if n > 3 else n)
                # each point's offset_time (ns after the timebase; point i has i) as seconds
                kept = [i for i in range(n) if np.isfinite(points[i]).all()]
                assert got.times is not None and expected.times is not None
                np.testing.assert_array_equal(got.times, expected.times)
                np.testing.assert_allclose(got.times, np.array(kept) * 1e-9, rtol=1e-6)


@pytest.mark.parametrize(
    ("stores", "encoding"), [(Stores.ROS2_HUMBLE, "cdr"), (Stores.ROS1_NOETIC, "ros1")]
)
def test_truncated_bytes_are_an_error(stores: Stores, encoding: str) -> None:
    store = livox_typestore(stores)
    typename = "livox_ros_driver2/msg/CustomMsg"
    fast = ros.livox_decoder(store, typename, encoding)
    assert fast is not None
    message = custom_msg(store, "livox_ros_driver2", T0, np.ones((10, 3), np.float32))
    raw = bytes(
        store.serialize_cdr(message, typename)
        if encoding == "cdr"
        else store.serialize_ros1(message, typename)
    )
    with pytest.raises(ValueError, match="Livox CustomMsg is truncated"):
        fast(raw[:-8])


def test_another_definition_is_left_to_rosbags() -> None:
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = get_types_from_msg(
        CUSTOM_POINT.replace("float32 z", "float64 z"), "livox_ros_driver2/msg/CustomPoint"
    )
    types.update(get_types_from_msg(CUSTOM_MSG, "livox_ros_driver2/msg/CustomMsg"))
    store.register(types)
    assert ros.livox_decoder(store, "livox_ros_driver2/msg/CustomMsg", "cdr") is None
    assert (
        ros.livox_decoder(livox_typestore(Stores.ROS2_HUMBLE), "sensor_msgs/msg/PointCloud2", "cdr")
        is None
    )
    # cloud_decoder still reads it, through rosbags
    text = (
        CUSTOM_MSG
        + "=" * 80
        + "\nMSG: livox_ros_driver2/CustomPoint\n"
        + CUSTOM_POINT.replace("float32 z", "float64 z")
    )
    text += "=" * 80 + "\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
    text += "=" * 80 + "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
    decode = ros.cloud_decoder("livox_ros_driver2/msg/CustomMsg", "ros2msg", text.encode(), "cdr")
    message = custom_msg(store, "livox_ros_driver2", T0, np.full((4, 3), 2.5, np.float32))
    cloud = decode(bytes(store.serialize_cdr(message, "livox_ros_driver2/msg/CustomMsg")))
    assert cloud.stamp_ns == T0
    np.testing.assert_array_equal(cloud.points, np.full((4, 3), 2.5, np.float32))
