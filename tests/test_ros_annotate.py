"""Annotating ROS 2 recordings (MCAP, CDR): PointCloud2 and Livox clouds, topic choice, bad input.

Every input is written with mcap-ros2-support's writer (tests/ros_writers.py), never cldet's.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner, Result

from cldet.cli import app
from cldet.config import load_config
from cldet.errors import CorruptMessageError, LogError
from cldet.io import ros
from cldet.io.mcap_read import iter_estimates, list_topics, open_log
from cldet.io.sources import iter_log_clouds, iter_log_positions, select_topics
from cldet.pipeline import annotate_log
from tests.ros_writers import (
    CUSTOM_MSG2,
    POINT_CLOUD2,
    POINT_STAMPED,
    STRING,
    TF_MESSAGE,
    Ros2Log,
    custom_msg_dict,
    point_cloud2,
    ros_time,
    tf_static,
)

T0 = 1_706_255_621_600_227_000
LATE_NS = 30_000_000  # a recorder's log time: 30 ms after the header stamp
PC2 = "sensor_msgs/msg/PointCloud2"


def _points(rng: np.random.Generator, n: int = 50) -> np.ndarray:
    return rng.uniform(-20, 20, (n, 3)).astype(np.float32)


def write_pc2_log(path: Path, clouds: list[tuple[str, int, dict]]) -> None:
    with Ros2Log(path) as log:
        for topic, stamp_ns, message in clouds:
            log.write(topic, PC2, POINT_CLOUD2, message, stamp_ns + LATE_NS)


@pytest.mark.parametrize(
    ("xyz", "extra", "big_endian", "lead"),
    [
        ("f4", (), False, 0),
        ("f8", (("intensity", "f4"), ("ring", "u2")), False, 4),
        ("f4", (("t", "u4"),), True, 2),
    ],
)
def test_point_cloud2_layouts_read_at_the_header_stamp(
    tmp_path: Path, xyz: str, extra: tuple, big_endian: bool, lead: int
) -> None:
    rng = np.random.default_rng(0)
    expected = [_points(rng) for _ in range(3)]
    expected[1][[3, 7]] = np.nan  # NaN points are dropped
    log = tmp_path / "pc2.mcap"
    write_pc2_log(
        log,
        [
            (
                "/points",
                T0 + i * 100_000_000,
                point_cloud2(
                    T0 + i * 100_000_000,
                    "lidar",
                    p,
                    xyz=xyz,
                    extra=extra,
                    big_endian=big_endian,
                    lead=lead,
                ),
            )
            for i, p in enumerate(expected)
        ],
    )
    got = list(iter_log_clouds(log, "/points"))
    assert [c.stamp_ns for c in got] == [T0 + i * 100_000_000 for i in range(3)]  # not log time
    assert all(c.frame_id == "lidar" for c in got)
    for cloud, points in zip(got, expected, strict=True):
        finite = points[np.isfinite(points).all(axis=1)]
        assert cloud.points.dtype == np.float32
        np.testing.assert_array_equal(cloud.points, finite)
    assert len(got[1].points) == 48


# each driver's per-point time: (field, type, its values for times t after the stamp in
# seconds, when its scans start after the stamp: Velodyne's ROS driver stamps a scan late, so
# its first points come before the stamp)
TIME_CONVENTIONS = {
    "ouster t: ns after the stamp": ("t", "u4", lambda t, stamp: np.round(t * 1e9), 0.0),
    "livox offset_time: ns after": (
        "offset_time",
        "u4",
        lambda t, stamp: np.round(t * 1e9),
        0.0,
    ),
    "velodyne time: s after (or before)": ("time", "f4", lambda t, stamp: t, -0.05),
    "hesai timestamp: s since the epoch": (
        "timestamp",
        "f8",
        lambda t, stamp: stamp * 1e-9 + t,
        0.0,
    ),
    "livox2 timestamp: ns since the epoch": (
        "timestamp",
        "f8",
        lambda t, stamp: stamp + np.round(t * 1e9),
        0.0,
    ),
    "timestamp: ms since the epoch": (
        "timestamp",
        "f8",
        lambda t, stamp: stamp * 1e-6 + t * 1e3,
        0.0,
    ),
    "timestamp: us since the epoch": (
        "timestamp",
        "f8",
        lambda t, stamp: stamp // 1000 + np.round(t * 1e6),
        0.0,
    ),
}


@pytest.mark.parametrize("convention", sorted(TIME_CONVENTIONS))
def test_point_cloud2_time_fields_give_each_point_its_time_after_the_stamp(
    tmp_path: Path, convention: str
) -> None:
    name, kind, encode, start_s = TIME_CONVENTIONS[convention]
    rng = np.random.default_rng(11)
    points = _points(rng, 40)
    points[[5, 9]] = np.nan  # dropped with their times
    after = start_s + np.sort(rng.uniform(0.0, 0.1, len(points)))  # a 100 ms scan
    values = {name: encode(after, T0)}
    message = point_cloud2(T0, "lidar", points, extra=((name, kind),), values=values)
    write_pc2_log(tmp_path / "timed.mcap", [("/points", T0, message)])
    (cloud,) = iter_log_clouds(tmp_path / "timed.mcap", "/points")
    keep = np.isfinite(points).all(axis=1)
    assert cloud.times is not None and cloud.times.dtype == np.float32
    np.testing.assert_allclose(cloud.times, after[keep], atol=1e-6)  # float64 epoch ns: 256 ns
    np.testing.assert_array_equal(cloud.points, points[keep])


@pytest.mark.parametrize(
    ("kind", "values"),
    [
        ("f8", T0 * 1e-9 + 5.0),  # seconds since the epoch, but 5 s after the stamp
        ("f4", np.nan),  # not finite
        ("u4", 2_000_000_000),  # 2 s after the stamp
    ],
)
def test_point_cloud2_times_that_are_not_a_scans_are_not_used(
    tmp_path: Path, kind: str, values: float
) -> None:
    points = _points(np.random.default_rng(12), 10)
    message = point_cloud2(T0, "lidar", points, extra=(("t", kind),), values={"t": values})
    write_pc2_log(tmp_path / "untimed.mcap", [("/points", T0, message)])
    (cloud,) = iter_log_clouds(tmp_path / "untimed.mcap", "/points")
    assert cloud.times is None
    np.testing.assert_array_equal(cloud.points, points)


def test_the_avia_is_moved_into_the_lidar_frame_by_tf_static(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    points = _points(rng)
    log = tmp_path / "tf.mcap"
    quarter = (0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5))  # +90 deg about z
    with Ros2Log(log) as w:
        # base <- lidar (a shift) and base <- avia (a shift and a quarter turn): a chain via base
        message = tf_static(
            [
                ("base", "lidar", (0.0, 0.0, 1.0), (0, 0, 0, 1)),
                ("base", "avia", (1.0, 2.0, 1.0), quarter),
            ]
        )
        w.write("/tf_static", "tf2_msgs/msg/TFMessage", TF_MESSAGE, message, T0)
        w.write("/avia", PC2, POINT_CLOUD2, point_cloud2(T0, "avia", points), T0 + LATE_NS)
    (moved,) = iter_log_clouds(log, "/avia", target_frame="lidar")
    expected = np.column_stack([-points[:, 1] + 1.0, points[:, 0] + 2.0, points[:, 2]])
    np.testing.assert_allclose(moved.points, expected, atol=1e-5)
    assert moved.frame_id == "lidar"
    # without a transform to the frame asked for, the points stay as they are
    (kept,) = iter_log_clouds(log, "/avia", target_frame="elsewhere")
    np.testing.assert_array_equal(kept.points, points)


def test_without_tf_static_the_configured_avia_extrinsic_applies(tmp_path: Path) -> None:
    from cldet.io.sources import SensorTopics
    from cldet.pipeline import read_frames

    rng = np.random.default_rng(2)
    lidar, avia = _points(rng), _points(rng)
    log = tmp_path / "no_tf.mcap"
    with Ros2Log(log) as w:
        w.write("/lidar", PC2, POINT_CLOUD2, point_cloud2(T0, "lidar", lidar), T0 + LATE_NS)
        w.write("/avia", PC2, POINT_CLOUD2, point_cloud2(T0, "avia", avia), T0 + LATE_NS)
    sensors = SensorTopics(lidar="/lidar", avia="/avia")
    turned = load_config(
        overrides={"frames": {"avia_xyz_m": (1.0, 2.0, 3.0), "avia_rpy_deg": (0.0, 0.0, 90.0)}}
    )
    (frame,) = read_frames(log, sensors, turned.frames)
    expected = np.column_stack([-avia[:, 1] + 1.0, avia[:, 0] + 2.0, avia[:, 2] + 3.0])
    np.testing.assert_allclose(frame.avia, expected, atol=1e-5)
    np.testing.assert_array_equal(frame.mid360, lidar)
    # the default: the challenge's layout, the Avia already in the LiDAR's frame
    (frame,) = read_frames(log, sensors, load_config().frames)
    np.testing.assert_array_equal(frame.avia, avia)


def test_static_transform_inverts_and_chains() -> None:
    turn = ros.FrameTransform(
        "a", "b", np.array([[0, -1, 0, 1], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    )
    shift = ros.FrameTransform(
        "b", "c", np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5], [0, 0, 0, 1.0]])
    )
    a_from_c = ros.static_transform([turn, shift], "a", "c")
    assert a_from_c is not None
    np.testing.assert_allclose(a_from_c @ [1, 0, 0, 1], [1, 1, 5, 1])
    c_from_a = ros.static_transform([turn, shift], "c", "a")
    assert c_from_a is not None
    np.testing.assert_allclose(c_from_a @ a_from_c, np.eye(4), atol=1e-12)
    assert ros.static_transform([turn], "a", "z") is None
    np.testing.assert_array_equal(ros.static_transform([], "a", "a"), np.eye(4))


# --- annotate: the same frames give the same estimates, whatever the encoding -------------------
@pytest.fixture(scope="module")
def sim(
    tmp_path_factory: pytest.TempPathFactory, make_log: Callable[..., Path]
) -> tuple[Path, Path]:
    """A simulated sequence as a cldet log and as a ROS 2 recording of the same clouds."""
    from cldet.io.mcap_read import iter_clouds, iter_positions

    root = tmp_path_factory.mktemp("ros2")
    cldet_log = make_log(root, seed=3, duration_s=3.0)
    ros_log = root / "ros2.mcap"
    items: list[tuple[int, str, str, str, dict]] = []
    for topic, ros_topic in (("/lidar_360", "/livox/lidar"), ("/livox_avia", "/livox/avia")):
        for c in iter_clouds(cldet_log, topic):
            assert c.times is not None  # the simulator records each point's firing time
            message = point_cloud2(
                c.stamp_ns,
                "livox_frame",
                np.asarray(c.points),
                extra=(("intensity", "f4"), ("time", "f4")),  # Velodyne's seconds after the stamp
                values={"time": np.asarray(c.times)},
            )
            items.append((c.stamp_ns, ros_topic, PC2, POINT_CLOUD2, message))
    for p in iter_positions(cldet_log, "/ground_truth"):
        point = {
            "header": {"stamp": ros_time(p.stamp_ns), "frame_id": "livox_frame"},
            "point": dict(zip("xyz", map(float, p.position), strict=True)),
        }
        items.append(
            (p.stamp_ns, "/leica/point/pos", "geometry_msgs/msg/PointStamped", POINT_STAMPED, point)
        )
    items.sort(key=lambda item: item[0])
    with Ros2Log(ros_log) as w:
        for stamp, topic, datatype, definition, message in items:
            w.write(topic, datatype, definition, message, stamp + LATE_NS)
    return cldet_log, ros_log


def test_a_ros2_log_annotates_like_the_cldet_log(sim: tuple[Path, Path], tmp_path: Path) -> None:
    cldet_log, ros_log = sim
    source = ros_log.read_bytes()
    reference = annotate_log(cldet_log, output=tmp_path / "ref.mcap", write_rrd=False)
    out = tmp_path / "ros-annotated.mcap"
    report = annotate_log(
        ros_log,
        output=out,
        write_rrd=False,
        lidar="/livox/lidar",
        avia="/livox/avia",
        truth="/leica/point/pos",
    )
    assert ros_log.read_bytes() == source  # -o: the source is untouched
    assert report.frames == reference.frames
    assert report.rms_error_m is not None and reference.rms_error_m is not None
    assert report.rms_error_m == pytest.approx(reference.rms_error_m, abs=1e-9)
    ours = [e for e, _ in iter_estimates(out)]
    theirs = [e for e, _ in iter_estimates(tmp_path / "ref.mcap")]
    assert [e.stamp_ns for e in ours] == [e.stamp_ns for e in theirs]  # header stamps
    np.testing.assert_allclose([e.position for e in ours], [e.position for e in theirs])
    # the ROS channels are kept beside the Foxglove protobuf results
    found = list_topics(out)
    assert found["/livox/lidar"] == found["/cldet/estimate"] == report.frames
    with open_log(out) as log:
        types = log.topic_types()
        assert types["/livox/lidar"] == PC2 and types["/cldet/pose"] == "foxglove.PoseInFrame"
        originals = {
            (c.topic, m.log_time, m.data) for _, c, m in log.iter_messages(["/livox/lidar"])
        }
    with open_log(ros_log) as log:
        assert originals == {
            (c.topic, m.log_time, m.data) for _, c, m in log.iter_messages(["/livox/lidar"])
        }
    # PointStamped truth at its header stamps (the log times are 30 ms later)
    truth = list(iter_log_positions(ros_log, "/leica/point/pos"))
    gt = list(iter_log_positions(cldet_log, "/ground_truth"))
    assert [t.stamp_ns for t in truth] == [g.stamp_ns for g in gt]
    np.testing.assert_array_equal([t.position for t in truth], [g.position for g in gt])


# --- topic choice ----------------------------------------------------------------------------
def write_chatter_and_scan(log: Path) -> Path:
    """A log of one std_msgs/String on /chatter and one PointCloud2 on /scan."""
    points = _points(np.random.default_rng(2))
    with Ros2Log(log) as w:
        w.write("/chatter", "std_msgs/msg/String", STRING, {"data": "hi"}, T0)
        w.write("/scan", PC2, POINT_CLOUD2, point_cloud2(T0, "l", points), T0 + LATE_NS)
    return log


def test_the_only_point_cloud_topic_is_the_lidar(tmp_path: Path) -> None:
    log = write_chatter_and_scan(tmp_path / "one.mcap")
    with open_log(log) as reader:
        assert select_topics(reader).lidar == "/scan"


def cli_run(*args: object) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args])


def assert_error(result: Result, *needles: str) -> None:
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("ERROR:")]
    assert errors, result.output
    for needle in needles:
        assert needle in errors[0], (needle, errors[0])


def assert_untouched(log: Path, before: bytes) -> None:
    assert log.read_bytes() == before
    assert sorted(p.name for p in log.parent.iterdir()) == [log.name]  # no .rrd, no temporary


def test_several_point_cloud_topics_are_listed_with_their_types(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    log = tmp_path / "two.mcap"
    write_pc2_log(
        log,
        [
            ("/a", T0, point_cloud2(T0, "l", _points(rng))),
            ("/b", T0, point_cloud2(T0, "l", _points(rng))),
        ],
    )
    before = log.read_bytes()
    assert_error(cli_run("annotate", log), str(log), f"/a ({PC2})", f"/b ({PC2})", "--lidar")
    assert_untouched(log, before)


def _bad_logs(rng: np.random.Generator) -> dict[str, tuple[dict, str]]:
    p = _points(rng, 20)
    good = point_cloud2(T0, "l", p)
    return {
        "no-x": (point_cloud2(T0, "l", p, drop="x"), "without a x field"),
        "short-step": (
            point_cloud2(T0, "l", p, point_step=8),
            "point_step 8 is smaller than its fields",
        ),
        "truncated": (dict(good, data=good["data"][:-5]), "truncated"),
    }


@pytest.mark.parametrize("case", ["no-x", "short-step", "truncated"])
def test_a_malformed_point_cloud2_is_a_clear_error_and_nothing_is_written(
    tmp_path: Path, case: str
) -> None:
    message, needle = _bad_logs(np.random.default_rng(4))[case]
    log = tmp_path / f"{case}.mcap"
    write_pc2_log(log, [("/points", T0, message)])
    before = log.read_bytes()
    with pytest.raises(CorruptMessageError, match=needle):
        annotate_log(log, lidar="/points")
    assert_error(cli_run("annotate", log, "--lidar", "/points"), str(log), "/points", needle)
    assert_untouched(log, before)


def test_a_wrong_type_or_a_missing_topic_names_what_exists(tmp_path: Path) -> None:
    log = write_chatter_and_scan(tmp_path / "types.mcap")
    before = log.read_bytes()
    assert_error(
        cli_run("annotate", log, "--lidar", "/chatter"),
        str(log),
        "/chatter carries std_msgs/msg/String",
        "sensor_msgs/msg/PointCloud2",
    )
    assert_error(
        cli_run("annotate", log, "--lidar", "/nope"),
        f"{log} has no topic /nope",
        f"/scan ({PC2}, 1 messages)",
        "/chatter (std_msgs/msg/String",
    )
    with pytest.raises(LogError, match="/chatter carries std_msgs/msg/String, expected positions"):
        annotate_log(log, lidar="/scan", truth="/chatter")
    assert_untouched(log, before)
    # the CLI: --avia and --truth are accepted and the log is annotated in place
    ok = cli_run("annotate", log, "--lidar", "/scan", "--no-rrd")
    assert ok.exit_code == 0, ok.output
    assert list_topics(log)["/cldet/estimate"] == 1


# --- the real sample, recorded the ROS 2 way -----------------------------------------------------
def _rms_against(log: Path, reference: list) -> float:
    """RMS distance of the log's refined estimate (nearest in time) to each reference position."""
    estimates = [e for e, _ in iter_estimates(log)]
    stamps = np.array([e.stamp_ns for e in estimates])
    d = [
        np.linalg.norm(estimates[int(np.argmin(np.abs(stamps - r.stamp_ns)))].position - r.position)
        for r in reference
    ]
    return float(np.sqrt(np.mean(np.square(d))))


def test_real_sample_as_a_ros2_log_scores_like_the_challenge_log(
    real_sample: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import warnings

    from converters import mmaud
    from converters.mcap_convert import convert_dataset

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the sample's reference/ folder is not a split
        convert_dataset(real_sample, tmp_path / "logs", splits=["val"], workers=1)
        (seq,) = mmaud.find_sequences(real_sample, splits=["val"])
    challenge = tmp_path / "logs" / "val" / "seq0001.mcap"
    annotate_log(challenge, write_rrd=False)
    ros_log = tmp_path / "seq0001-ros2.mcap"
    clouds = [
        (c.stamp_ns, topic, c.points, c.times)
        for modality, topic in (("lidar_360", "/livox/lidar"), ("livox_avia", "/livox/avia"))
        for c in mmaud.iter_clouds(seq, modality)
    ]
    with Ros2Log(ros_log) as w:
        for stamp, topic, points, times in sorted(clouds, key=lambda c: c[0]):
            message = point_cloud2(  # livox_ros_driver2's: float64 ns since the epoch
                stamp,
                "livox_frame",
                points,
                extra=(("timestamp", "f8"),),
                values={"timestamp": stamp + np.round(times.astype(np.float64) * 1e9)},
            )
            w.write(topic, PC2, POINT_CLOUD2, message, stamp + LATE_NS)
    result = cli_run(
        "annotate", ros_log, "--lidar", "/livox/lidar", "--avia", "/livox/avia", "--no-rrd"
    )
    assert result.exit_code == 0, result.output
    reference = list(mmaud.iter_positions(real_sample / "reference" / "seq0001"))
    rms_challenge = _rms_against(challenge, reference)
    rms_ros = _rms_against(ros_log, reference)
    with capsys.disabled():
        print(
            f"\nreal sample RMS vs reference: challenge log {rms_challenge:.4f} m, ROS 2 log {rms_ros:.4f} m"
        )
    assert rms_challenge < 0.2
    assert abs(rms_ros - rms_challenge) < 1e-3  # the times rounded to float64 ns since the epoch


# --- other encodings and messages in MCAP ------------------------------------------------------
def test_livox_custom_msg_in_a_ros2_log_is_read_at_its_timebase(tmp_path: Path) -> None:
    rng = np.random.default_rng(6)
    expected = [_points(rng, 30) for _ in range(2)]
    expected[0][4] = np.nan
    log = tmp_path / "livox.mcap"
    with Ros2Log(log) as w:
        for i, points in enumerate(expected):
            stamp = T0 + i * 100_000_000
            message = custom_msg_dict(stamp, "livox_frame", points)
            w.write(
                "/livox/lidar",
                "livox_ros_driver2/msg/CustomMsg",
                CUSTOM_MSG2,
                message,
                stamp + LATE_NS,
            )
    got = list(iter_log_clouds(log, "/livox/lidar"))
    assert [c.stamp_ns for c in got] == [T0, T0 + 100_000_000]
    np.testing.assert_array_equal(got[0].points, np.delete(expected[0], 4, axis=0))
    np.testing.assert_array_equal(got[1].points, expected[1])
    with open_log(log) as reader:
        assert select_topics(reader).lidar == "/livox/lidar"


def test_ros1_messages_in_mcap_are_read_too(tmp_path: Path) -> None:
    """An MCAP log of ROS 1 messages (ros1msg schemas): mcap's writer, rosbags' serializer."""
    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS1_NOETIC)
    types = typestore.types
    points = _points(np.random.default_rng(7), 25)
    header = types["std_msgs/msg/Header"](
        seq=3,
        stamp=types["builtin_interfaces/msg/Time"](sec=T0 // 10**9, nanosec=T0 % 10**9),
        frame_id="/lidar",
    )
    message = types["sensor_msgs/msg/PointCloud2"](
        header=header,
        height=1,
        width=len(points),
        fields=[
            types["sensor_msgs/msg/PointField"](name=c, offset=4 * i, datatype=7, count=1)
            for i, c in enumerate("xyz")
        ],
        is_bigendian=False,
        point_step=12,
        row_step=12 * len(points),
        data=np.ascontiguousarray(points, "<f4").reshape(-1).view(np.uint8),
        is_dense=True,
    )
    log = tmp_path / "ros1.mcap"
    text, _ = typestore.generate_msgdef(PC2)
    with open(log, "wb") as f:
        writer = Writer(f)
        writer.start(profile="ros1")
        schema = writer.register_schema("sensor_msgs/PointCloud2", "ros1msg", text.encode())
        channel = writer.register_channel("/points", "ros1", schema)
        writer.add_message(
            channel, T0 + LATE_NS, bytes(typestore.serialize_ros1(message, PC2)), T0 + LATE_NS
        )
        writer.finish()
    (cloud,) = iter_log_clouds(log, "/points")
    assert cloud.stamp_ns == T0 and cloud.frame_id == "lidar"
    np.testing.assert_array_equal(cloud.points, points)


def test_bytes_that_do_not_decode_are_a_corrupt_message(tmp_path: Path) -> None:
    from mcap.writer import Writer

    log = tmp_path / "bad-cdr.mcap"
    with open(log, "wb") as f:
        writer = Writer(f)
        writer.start(profile="ros2")
        schema = writer.register_schema(PC2, "ros2msg", POINT_CLOUD2.encode())
        channel = writer.register_channel("/points", "cdr", schema)
        writer.add_message(channel, T0, b"\x00\x01\x00\x00\x07", T0)  # a header cut short
        writer.finish()
    before = log.read_bytes()
    assert_error(cli_run("annotate", log), str(log), "corrupt message on /points")
    assert_untouched(log, before)
