"""`cldet convert` of ROS bags (ROS 1 .bag, ROS 2 folders in .db3 and .mcap), end to end.

The bags are written with rosbags' own writers, Livox's CustomMsg registered in its typestore
(tests/ros_writers.py); never with cldet's writer.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Bag1Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Bag2Writer
from rosbags.typesys import Stores, get_typestore
from typer.testing import CliRunner, Result

from cldet.cli import app
from cldet.io import topics
from cldet.io.mcap_read import iter_clouds, iter_positions, list_topics
from cldet.simulate import simulate_sequence
from converters import mmaud
from tests.ros_writers import custom_msg, livox_typestore

LATE_NS = 30_000_000  # the bag's receive time: 30 ms after the header stamp


def cli_run(*args: object) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> mmaud.SequenceRef:
    root = tmp_path_factory.mktemp("bag-data")
    simulate_sequence(
        root / "train" / "seq0001", seed=5, duration_s=3.0, scenario="mixed", images=False
    )
    (seq,) = mmaud.find_sequences(root)
    return seq


def _stamped(seq: mmaud.SequenceRef) -> list[tuple[int, str, object]]:
    """Every item of the sequence as (stamp_ns, folder, Cloud or PositionSample), by stamp."""
    items = [
        (c.stamp_ns, m, c)
        for m in ("lidar_360", "livox_avia", "radar_enhance_pcl")
        for c in mmaud.iter_clouds(seq, m)
    ]
    items += [(p.stamp_ns, "ground_truth", p) for p in mmaud.iter_ground_truth(seq)]
    return sorted(items, key=lambda item: (item[0], item[1]))


def _header(typestore, stamp_ns: int, frame: str):  # type: ignore[no-untyped-def]
    types = typestore.types
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    args = {
        "stamp": types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
        "frame_id": frame,
    }
    if any(name == "seq" for name, _ in typestore.fielddefs["std_msgs/msg/Header"][1]):
        args["seq"] = 0
    return types["std_msgs/msg/Header"](**args)


def _point_stamped(typestore, stamp_ns: int, xyz: np.ndarray):  # type: ignore[no-untyped-def]
    types = typestore.types
    point = types["geometry_msgs/msg/Point"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))
    return types["geometry_msgs/msg/PointStamped"](
        header=_header(typestore, stamp_ns, "leica"), point=point
    )


def _radar(typestore, stamp_ns: int, points: np.ndarray):  # type: ignore[no-untyped-def]
    types = typestore.types
    return types["sensor_msgs/msg/PointCloud"](
        header=_header(typestore, stamp_ns, "radar"),
        points=[
            types["geometry_msgs/msg/Point32"](x=float(p[0]), y=float(p[1]), z=float(p[2]))
            for p in points
        ],
        channels=[],
    )


def _pc2(typestore, stamp_ns: int, points: np.ndarray, times: np.ndarray):  # type: ignore[no-untyped-def]
    """x, y, z float32 and Ouster's ``t``: uint32 nanoseconds after the stamp."""
    types = typestore.types
    field = types["sensor_msgs/msg/PointField"]
    records = np.zeros(len(points), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("t", "<u4")])
    for i, axis in enumerate("xyz"):
        records[axis] = points[:, i]
    records["t"] = np.round(times.astype(np.float64) * 1e9)
    return types["sensor_msgs/msg/PointCloud2"](
        header=_header(typestore, stamp_ns, "livox_frame"),
        height=1,
        width=len(points),
        fields=[
            field(name=c, offset=4 * i, datatype=7 if c != "t" else 6, count=1)
            for i, c in enumerate("xyzt")
        ],
        is_bigendian=False,
        point_step=16,
        row_step=16 * len(points),
        data=records.view(np.uint8),
        is_dense=True,
    )


MMAUD = {
    "lidar_360": ("/livox_mid360/lidar", "livox_ros_driver2/msg/CustomMsg"),
    "livox_avia": ("/livox_avia/lidar", "livox_ros_driver/msg/CustomMsg"),
    "radar_enhance_pcl": ("/radar_enhance_pcl", "sensor_msgs/msg/PointCloud"),
    "ground_truth": ("/leica/point/pos", "geometry_msgs/msg/PointStamped"),
}


def write_ros1_bag(path: Path, seq: mmaud.SequenceRef) -> None:
    """The raw MMAUD layout: Livox CustomMsg Mid-360 and Avia, PointCloud radar, PointStamped truth."""
    typestore = livox_typestore(Stores.ROS1_NOETIC)
    with Bag1Writer(path) as bag:
        conns = {m: bag.add_connection(t, ty, typestore=typestore) for m, (t, ty) in MMAUD.items()}
        for stamp, modality, item in _stamped(seq):
            if modality == "ground_truth":
                message = _point_stamped(typestore, stamp, item.position)  # type: ignore[attr-defined]
            elif modality == "radar_enhance_pcl":
                message = _radar(typestore, stamp, item.points)  # type: ignore[attr-defined]
            else:
                package = MMAUD[modality][1].split("/")[0]
                message = custom_msg(typestore, package, stamp, item.points)  # type: ignore[attr-defined]
            raw = typestore.serialize_ros1(message, MMAUD[modality][1])
            bag.write(conns[modality], stamp + LATE_NS, raw)


def test_a_ros1_bag_converts_annotates_and_evaluates(
    sequence: mmaud.SequenceRef, tmp_path: Path
) -> None:
    bag = tmp_path / "flight.bag"
    write_ros1_bag(bag, sequence)
    result = cli_run("convert", bag, "-o", tmp_path / "logs")
    assert result.exit_code == 0, result.output
    log = tmp_path / "logs" / "flight.mcap"
    # the same channels and stamps as from the numpy folders: header stamps, not the bag's times
    for modality, topic in (
        ("lidar_360", topics.LIDAR_360),
        ("livox_avia", topics.LIVOX_AVIA),
        ("radar_enhance_pcl", topics.RADAR),
    ):
        expected = list(mmaud.iter_clouds(sequence, modality))
        got = list(iter_clouds(log, topic))
        assert [c.stamp_ns for c in got] == [c.stamp_ns for c in expected]
        for a, b in zip(got, expected, strict=True):
            np.testing.assert_array_equal(a.points, b.points)
    truth = list(iter_positions(log, topics.GROUND_TRUTH))
    assert [t.stamp_ns for t in truth] == [t.stamp_ns for t in mmaud.iter_ground_truth(sequence)]
    # a second conversion skips the existing log, as for the numpy folders; --overwrite replaces
    before = log.read_bytes()
    result = cli_run("convert", bag, "-o", tmp_path / "logs")
    assert result.exit_code == 0 and "skipped existing log" in result.output, result.output
    assert log.read_bytes() == before
    result = cli_run("convert", bag, "-o", tmp_path / "logs", "--overwrite")
    assert result.exit_code == 0 and "converted" in result.output, result.output
    # annotate, export (queries at the truth's stamps) and evaluate the log
    result = cli_run("annotate", log, "--no-rrd")
    assert result.exit_code == 0, result.output
    assert "RMS error" in result.output
    assert list_topics(log)[topics.ESTIMATE] == len(list(mmaud.iter_clouds(sequence, "lidar_360")))
    csv = tmp_path / "results.csv"
    result = cli_run("export", log, "-o", csv)
    assert result.exit_code == 0, result.output
    result = cli_run("evaluate", csv, "--logs", log, "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["counts"]["truth"] == summary["counts"]["matched"] == len(truth)
    assert summary["rmse_m"] < 1.0


@pytest.mark.parametrize("storage", [StoragePlugin.SQLITE3, StoragePlugin.MCAP])
def test_a_ros2_bag_folder_converts_to_the_same_log(
    sequence: mmaud.SequenceRef, tmp_path: Path, storage: StoragePlugin
) -> None:
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    folder = tmp_path / "flight2"
    with Bag2Writer(folder, version=9, storage_plugin=storage) as bag:
        conns = {
            "lidar_360": bag.add_connection(
                "/livox/lidar", "sensor_msgs/msg/PointCloud2", typestore=typestore
            ),
            "ground_truth": bag.add_connection(
                "/leica/point/pos", "geometry_msgs/msg/PointStamped", typestore=typestore
            ),
        }
        for stamp, modality, item in _stamped(sequence):
            if modality == "lidar_360":
                message = _pc2(typestore, stamp, item.points, item.times)  # type: ignore[attr-defined]
                kind = "sensor_msgs/msg/PointCloud2"
            elif modality == "ground_truth":
                message, kind = (
                    _point_stamped(typestore, stamp, item.position),
                    "geometry_msgs/msg/PointStamped",
                )  # type: ignore[attr-defined]
            else:
                continue
            bag.write(conns[modality], stamp + LATE_NS, typestore.serialize_cdr(message, kind))
    result = cli_run("convert", folder, "-o", tmp_path / "logs", "--lidar-topic", "/livox/lidar")
    assert result.exit_code == 0, result.output
    log = tmp_path / "logs" / "flight2.mcap"
    assert set(list_topics(log)) == {topics.TF, topics.LIDAR_360, topics.GROUND_TRUTH}
    expected = list(mmaud.iter_clouds(sequence, "lidar_360"))
    got = list(iter_clouds(log, topics.LIDAR_360))
    assert [c.stamp_ns for c in got] == [c.stamp_ns for c in expected]
    np.testing.assert_array_equal(got[5].points, expected[5].points)
    # each point's firing time, from the PointCloud2's t field into the log's time field
    assert got[5].times is not None and expected[5].times is not None
    np.testing.assert_allclose(got[5].times, expected[5].times, atol=1e-9)


def test_a_bag_without_the_point_cloud_topic_is_a_clear_error(tmp_path: Path) -> None:
    typestore = get_typestore(Stores.ROS1_NOETIC)
    bag = tmp_path / "chat.bag"
    with Bag1Writer(bag) as writer:
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=typestore)
        writer.write(
            conn,
            1,
            typestore.serialize_ros1(
                typestore.types["std_msgs/msg/String"](data="hi"), "std_msgs/msg/String"
            ),
        )
    out = tmp_path / "logs"
    out.mkdir()
    for args, needle in (
        ((), "no a point cloud topic /livox_mid360/lidar"),
        (
            ("--lidar-topic", "/chatter"),
            "/chatter carries std_msgs/msg/String, expected a point cloud",
        ),
        (
            ("--avia-topic", "/nope", "--lidar-topic", "/livox_mid360/lidar"),
            "topics in the bag: /chatter (std_msgs/msg/String)",
        ),
    ):
        result = cli_run("convert", bag, "-o", out, *args)
        assert result.exit_code == 1, result.output
        assert "Traceback" not in result.output
        (error,) = [line for line in result.output.splitlines() if line.startswith("ERROR:")]
        assert str(bag) in error and needle in error, error
    assert list(out.iterdir()) == []  # nothing written, no temporary left
