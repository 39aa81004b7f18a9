"""The MCAP layer: LogWriter -> readers round trips, schemas, errors, atomic output, Rerun interop."""

from __future__ import annotations

import io
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from cldet.errors import LogError, OutputExistsError
from cldet.io import (
    LogWriter,
    atomic_output,
    iter_classes,
    iter_cloud_fields,
    iter_clouds,
    iter_estimates,
    iter_positions,
    list_topics,
    open_log,
    png_size,
    read_metadata,
)
from cldet.io import topics as tp
from cldet.io.mcap_read import decode_timed
from cldet.simulate.sensors import encode_png
from cldet.types import Cluster, Estimate, Source

T0 = 1_706_255_621_600_227_000  # 1706255621.600227 s


def make_png(width: int, height: int) -> bytes:
    """A real (tiny, uniform grey) RGB PNG."""
    return encode_png(np.full((height, width, 3), 0x80, dtype=np.uint8))


def random_cloud(rng: np.random.Generator, n: int, k: int = 3) -> np.ndarray:
    return (rng.normal(size=(n, k)) * 30).astype(np.float32)


def write_sample_log(stream: io.BytesIO | io.BufferedWriter, compression: str = "zstd") -> dict:
    """Write a few frames of every message type; return what was written."""
    rng = np.random.default_rng(7)
    clouds = [(T0 + i * 100_000_000 + i, random_cloud(rng, 50 + i)) for i in range(5)]
    clouds.append((T0 + 600_000_000, np.zeros((0, 3), np.float32)))
    fg = [(T0 + i * 100_000_000, random_cloud(rng, 7, 4)) for i in range(3)]
    gt = [(T0 - 35_000_000 + i * 50_000_000, rng.normal(size=3)) for i in range(8)]
    estimates = [
        Estimate(T0 + i, np.array([1.0, 2.0, 3.0 + i]), Source(1 + i % 4), i, 0.05 * i)
        for i in range(4)
    ]
    with LogWriter(stream, compression=compression) as writer:
        for stamp, pts in clouds:
            writer.write_cloud(tp.LIDAR_360, stamp, pts, tp.FRAME_MID360)
        for stamp, pts in fg:
            writer.write_cloud(
                tp.FOREGROUND, stamp, pts, tp.FRAME_MID360, fields=("x", "y", "z", "cluster_id")
            )
        for stamp, xyz in gt:
            writer.write_pose(tp.GROUND_TRUTH, stamp, xyz, tp.FRAME_MID360)
            writer.write_class(tp.CLASS, stamp, 2)
        for i, est in enumerate(estimates):
            writer.write_estimate(tp.ESTIMATE, est.stamp_ns, est, track_id=10 + i)
        writer.write_image(tp.IMAGE, T0 + 5, make_png(32, 12), tp.FRAME_CAMERA)
        writer.write_poses(tp.TRAJECTORY, T0, np.arange(12.0).reshape(4, 3), tp.FRAME_MID360)
        writer.write_scene_update(
            tp.CLUSTERS,
            T0,
            [Cluster(0, np.zeros(3), -np.ones(3), np.ones(3), 12)],
            tp.FRAME_MID360,
        )
        writer.write_metadata(tp.METADATA_SOURCE, {"sequence": "seq0001", "n": "6"})
        counts = writer.counts
    return {"clouds": clouds, "fg": fg, "gt": gt, "estimates": estimates, "counts": counts}


@pytest.fixture(scope="module")
def sample_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    path = tmp_path_factory.mktemp("log") / "sample.mcap"
    with open(path, "wb") as f:
        written = write_sample_log(f)
    return path, written


# --- writing ---------------------------------------------------------------------------------
def test_cloud_bytes_equal_protobuf_serialization() -> None:
    pts = random_cloud(np.random.default_rng(0), 33)
    buf = io.BytesIO()
    with LogWriter(buf) as writer:
        writer.write_cloud(tp.LIDAR_360, T0, pts, tp.FRAME_MID360)
    buf.seek(0)
    ((_, _, message),) = make_reader(buf).iter_messages()
    expected = PointCloud(frame_id="mid360", point_stride=12, data=pts.tobytes())
    expected.timestamp.FromNanoseconds(T0)
    expected.pose.position.SetInParent()
    expected.pose.orientation.w = 1.0
    for i, name in enumerate("xyz"):
        expected.fields.add(name=name, offset=4 * i, type=PackedElementField.FLOAT32)
    assert message.data == expected.SerializeToString()
    decoded = PointCloud.FromString(message.data)
    assert decoded.pose.HasField("position")  # Rerun's importer needs it present


def test_writer_never_closes_the_stream_and_handles_raw_streams(tmp_path: Path) -> None:
    buf = io.BytesIO()
    with LogWriter(buf) as writer:
        writer.write_class(tp.CLASS, T0, 1)
    assert not buf.closed
    raw_path = tmp_path / "raw.mcap"
    with open(raw_path, "wb", buffering=0) as raw:  # an unbuffered io.FileIO
        with LogWriter(raw) as writer:
            writer.write_class(tp.CLASS, T0, 3)
        assert not raw.closed
    assert [c.class_id for c in iter_classes(raw_path)] == [3]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_round_trip_every_type(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "log.mcap"
    with open(path, "wb") as f:
        written = write_sample_log(f, compression)

    clouds = list(iter_clouds(path, tp.LIDAR_360))
    assert [c.stamp_ns for c in clouds] == [s for s, _ in written["clouds"]]
    for cloud, (_, pts) in zip(clouds, written["clouds"], strict=True):
        assert cloud.points.dtype == np.float32 and cloud.points.shape == pts.shape
        assert np.ascontiguousarray(cloud.points).tobytes() == pts.tobytes()  # bit for bit

    fields = list(iter_cloud_fields(path, tp.FOREGROUND))
    for (stamp, columns), (want_stamp, pts) in zip(fields, written["fg"], strict=True):
        assert stamp == want_stamp
        assert list(columns) == ["x", "y", "z", "cluster_id"]
        assert np.array_equal(np.stack(list(columns.values()), axis=1), pts)
    fg_xyz = next(iter_clouds(path, tp.FOREGROUND)).points
    assert np.array_equal(fg_xyz, written["fg"][0][1][:, :3])

    positions = list(iter_positions(path, tp.GROUND_TRUTH))
    assert [p.stamp_ns for p in positions] == [s for s, _ in written["gt"]]
    for p, (_, xyz) in zip(positions, written["gt"], strict=True):
        assert np.array_equal(p.position, xyz)
    assert [c.class_id for c in iter_classes(path)] == [2] * len(written["gt"])

    estimates = list(iter_estimates(path))
    assert [track for _, track in estimates] == [10, 11, 12, 13]
    for (got, _), want in zip(estimates, written["estimates"], strict=True):
        assert got.stamp_ns == want.stamp_ns and got.source == want.source
        assert np.array_equal(got.position, want.position)
        assert (got.n_points, got.sigma_m) == (want.n_points, want.sigma_m)
    # an estimate topic also reads as positions
    assert np.array_equal(next(iter_positions(path, tp.ESTIMATE)).position, [1.0, 2.0, 3.0])

    assert read_metadata(path) == {tp.METADATA_SOURCE: {"sequence": "seq0001", "n": "6"}}
    assert list_topics(path) == written["counts"]
    assert list_topics(path)[tp.IMAGE_CALIBRATION] == 1
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert {c.compression for c in summary.chunk_indexes} == {
        {"zstd": "zstd", "lz4": "lz4", "none": ""}[compression]
    }


def test_times_are_exact_and_schemas_self_contained(sample_log: tuple[Path, dict]) -> None:
    path, _ = sample_log
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        seen = set()
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert message.log_time == message.publish_time
            stamped = decoded.entities[0] if channel.topic == tp.CLUSTERS else decoded
            assert stamped.timestamp.ToNanoseconds() == message.log_time, channel.topic
            assert schema is not None and schema.encoding == "protobuf"
            seen.add(schema.name)
            if channel.topic == tp.ESTIMATE:  # decoded from the stored FileDescriptorSet alone
                assert decoded.DESCRIPTOR.full_name == "cldet.Estimate"
                assert decoded.track_id >= 10
    assert {"cldet.Estimate", "cldet.ClassLabel", "foxglove.PointCloud"} <= seen


def test_image_and_calibration_share_the_frame(sample_log: tuple[Path, dict]) -> None:
    path, _ = sample_log
    with open_log(path) as log:
        ((_, _, img),) = log.iter_messages([tp.IMAGE])
        ((_, _, cal),) = log.iter_messages([tp.IMAGE_CALIBRATION])
    image = CompressedImage.FromString(img.data)
    calibration = CameraCalibration.FromString(cal.data)
    assert image.format == "png" and png_size(image.data) == (32, 12)
    assert image.frame_id == calibration.frame_id == tp.FRAME_CAMERA
    assert (calibration.width, calibration.height) == (32, 12)
    assert img.log_time == cal.log_time == T0 + 5


def test_scene_update_has_box_and_label(sample_log: tuple[Path, dict]) -> None:
    path, _ = sample_log
    with open_log(path) as log:
        ((_, _, msg),) = log.iter_messages([tp.CLUSTERS])
    entity = SceneUpdate.FromString(msg.data).entities[0]
    assert entity.frame_id == tp.FRAME_MID360
    assert (entity.cubes[0].size.x, entity.cubes[0].size.z) == (2.0, 2.0)
    assert entity.texts[0].text == "#0 12 pts"


def test_time_window(sample_log: tuple[Path, dict]) -> None:
    path, written = sample_log
    stamps = [s for s, _ in written["clouds"]]
    with open_log(path) as log:
        got = [
            c.stamp_ns for c in log.iter_clouds(tp.LIDAR_360, start_ns=stamps[1], end_ns=stamps[3])
        ]
        assert log.time_range()[0] == min(s for s, _ in written["gt"])
    assert got == stamps[1:3]


def test_writer_rejects_mistakes() -> None:
    buf = io.BytesIO()
    with pytest.raises(LogError, match="unknown compression 'gzip'"):
        LogWriter(buf, compression="gzip")
    with LogWriter(buf) as writer:
        writer.write_class(tp.CLASS, T0, 1)
        with pytest.raises(LogError, match="topic /class carries cldet.ClassLabel"):
            writer.write_pose(tp.CLASS, T0, [0, 0, 0], tp.FRAME_MID360)
        with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
            writer.write_cloud(tp.LIDAR_360, T0, np.zeros((4, 2)), tp.FRAME_MID360)
        with pytest.raises(LogError, match="/image at .* not a PNG"):
            writer.write_image(tp.IMAGE, T0, b"GIF89a...", tp.FRAME_CAMERA)
        with pytest.raises(ValueError, match="must be strings"):
            writer.write_metadata("x", {"n": 3})  # type: ignore[dict-item]
    with pytest.raises(LogError, match="already finished"):
        writer.write_class(tp.CLASS, T0, 1)


def test_writer_leaves_log_unfinished_after_an_exception(tmp_path: Path) -> None:
    path = tmp_path / "half.mcap"
    with open(path, "wb") as f, pytest.raises(RuntimeError), LogWriter(f) as writer:
        writer.write_class(tp.CLASS, T0, 1)
        raise RuntimeError("boom")
    with pytest.raises(LogError, match=r"half\.mcap"):
        open_log(path)


# --- reading errors --------------------------------------------------------------------------
def test_missing_topic_lists_the_topics_that_exist(sample_log: tuple[Path, dict]) -> None:
    path, _ = sample_log
    with pytest.raises(
        LogError,
        match=r"sample\.mcap has no topic /livox_avia; topics in the file: "
        r"/lidar_360 \(6\), /cldet/foreground \(3\), /ground_truth \(8\)",
    ):
        list(iter_clouds(path, tp.LIVOX_AVIA))


def test_wrong_schema_is_named(sample_log: tuple[Path, dict]) -> None:
    path, _ = sample_log
    with pytest.raises(
        LogError,
        match="topic /ground_truth carries foxglove.PoseInFrame, expected foxglove.PointCloud",
    ):
        list(iter_clouds(path, tp.GROUND_TRUTH))


def test_truncated_file(sample_log: tuple[Path, dict], tmp_path: Path) -> None:
    data = sample_log[0].read_bytes()
    for cut in (len(data) - 1, len(data) // 2, 20):
        bad = tmp_path / f"cut{cut}.mcap"
        bad.write_bytes(data[:cut])
        with pytest.raises(LogError, match=rf"cut{cut}\.mcap .*(truncated|corrupt)"):
            list_topics(bad)


def test_not_mcap_and_missing_file(tmp_path: Path) -> None:
    bad = tmp_path / "notes.mcap"
    bad.write_text("hello, this is not an MCAP file at all")
    with pytest.raises(LogError, match=r"notes\.mcap is not a readable MCAP log"):
        open_log(bad)
    with pytest.raises(LogError, match=r"cannot open MCAP log .*absent\.mcap"):
        open_log(tmp_path / "absent.mcap")


def test_corrupt_chunk_names_file_and_topic(tmp_path: Path) -> None:
    path = tmp_path / "corrupt.mcap"
    with open(path, "wb") as f:
        write_sample_log(f)
    data = bytearray(path.read_bytes())
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunk = summary.chunk_indexes[0]
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle : middle + 64] = b"\xff" * 64  # garbage inside the compressed records
    path.write_bytes(bytes(data))
    with pytest.raises(LogError, match=r"corrupt\.mcap.*(/lidar_360|corrupt)"):
        list(iter_clouds(path, tp.LIDAR_360))


def write_log_with_a_corrupt_cloud(path: Path, bad_index: int = 2, n: int = 5) -> int:
    """A log of ``n`` Mid-360 clouds whose ``bad_index``-th message is not protobuf; its stamp."""
    rng = np.random.default_rng(3)
    source = io.BytesIO()
    with LogWriter(source) as writer:
        for i in range(n):
            writer.write_cloud(tp.LIDAR_360, T0 + i * 100_000_000, random_cloud(rng, 9), "mid360")
    source.seek(0)
    raw = list(make_reader(source).iter_messages())
    with open(path, "wb") as f, LogWriter(f) as writer:
        for i, (schema, channel, message) in enumerate(raw):
            data = b"\x0a\x02\x08\xff" if i == bad_index else message.data  # truncated stamp
            writer.write_raw(schema, channel, message.log_time, message.publish_time, data)
    return raw[bad_index][2].log_time


def test_corrupt_cloud_message_names_log_topic_and_stamp(tmp_path: Path) -> None:
    from cldet.errors import CorruptMessageError
    from cldet.stamps import format_stamp

    path = tmp_path / "badcloud.mcap"
    stamp = write_log_with_a_corrupt_cloud(path)
    with pytest.raises(CorruptMessageError) as caught:
        list(iter_clouds(path, tp.LIDAR_360))
    err = caught.value
    assert err.topic == tp.LIDAR_360 and err.stamp_ns == stamp and err.log == path
    text = str(err)
    assert str(path) in text and tp.LIDAR_360 in text and format_stamp(stamp) in text
    assert "Wire format was corrupt" in text and "\n" not in text
    with pytest.raises(CorruptMessageError, match=r"badcloud\.mcap: corrupt message on /lidar_360"):
        list(iter_cloud_fields(path, tp.LIDAR_360))
    import pickle  # crosses worker processes intact

    again = pickle.loads(pickle.dumps(err))
    assert str(again) == text and again.stamp_ns == stamp


def test_a_bug_is_not_reported_as_a_corrupt_log(
    sample_log: tuple[Path, dict], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Only what corrupt bytes raise becomes a LogError; a TypeError (a bug) goes through."""
    from cldet.io import mcap_read

    def broken(data: bytes) -> np.ndarray:
        raise TypeError("a bug")

    monkeypatch.setattr(mcap_read, "decode_timed", broken)
    with pytest.raises(TypeError, match="a bug"):
        list(iter_clouds(sample_log[0], tp.LIDAR_360))


def write_log_without_summary(path: Path) -> list:
    """A valid MCAP log with no summary section (mcap's Writer with every index turned off)."""
    from mcap.writer import IndexType, Writer

    source = io.BytesIO()
    write_sample_log(source)
    source.seek(0)
    raw = list(make_reader(source).iter_messages(log_time_order=True))
    with open(path, "wb") as f:
        writer = Writer(
            f,
            index_types=IndexType.NONE,
            repeat_channels=False,
            repeat_schemas=False,
            use_statistics=False,
            use_summary_offsets=False,
        )
        writer.start()
        ids: dict[str, int] = {}
        for schema, channel, message in raw:
            if channel.topic not in ids:
                schema_id = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.topic] = writer.register_channel(
                    channel.topic, channel.message_encoding, schema_id
                )
            writer.add_message(
                ids[channel.topic], message.log_time, message.data, message.publish_time
            )
        writer.add_metadata(tp.METADATA_SOURCE, {"sequence": "seq0001"})
        writer.finish()
    with open(path, "rb") as f:
        assert make_reader(f).get_summary() is None
    return raw


def test_a_log_without_summary_is_read_by_a_scan(tmp_path: Path) -> None:
    from cldet.io.rewrite import rewrite_log

    path = tmp_path / "nosummary.mcap"
    raw = write_log_without_summary(path)
    with_summary = io.BytesIO()
    written = write_sample_log(with_summary)
    assert list_topics(path) == {t: n for t, n in written["counts"].items()}
    clouds = list(iter_clouds(path, tp.LIDAR_360))
    assert [c.stamp_ns for c in clouds] == [s for s, _ in written["clouds"]]
    for cloud, (_, points) in zip(clouds, written["clouds"], strict=True):
        np.testing.assert_array_equal(cloud.points, points)
    assert read_metadata(path)[tp.METADATA_SOURCE] == {"sequence": "seq0001"}
    with open_log(path) as log:
        assert log.time_range() == (
            min(m.log_time for _, _, m in raw),
            max(m.log_time for _, _, m in raw),
        )
    out = tmp_path / "annotated.mcap"  # what annotate does with it: a full rewrite, with summary
    rewrite_log(path, out, [])
    with open(out, "rb") as f:
        assert make_reader(f).get_summary() is not None
    sources = {t: n for t, n in list_topics(path).items() if not t.startswith("/cldet/")}
    assert list_topics(out) == sources  # earlier results replaced, as always


# --- atomic output ---------------------------------------------------------------------------
def test_atomic_output_replaces_only_when_complete(tmp_path: Path) -> None:
    target = tmp_path / "seq0001.mcap"
    with atomic_output(target) as stream:
        stream.write(b"first")
    assert target.read_bytes() == b"first"
    with (
        pytest.raises(OutputExistsError, match=r"seq0001\.mcap already exists"),
        atomic_output(target),
    ):
        pass
    for exc in (RuntimeError("disk on fire"), KeyboardInterrupt()):
        with pytest.raises(type(exc)), atomic_output(target, overwrite=True) as stream:
            stream.write(b"half")
            raise exc
        assert target.read_bytes() == b"first"
        assert sorted(p.name for p in tmp_path.iterdir()) == ["seq0001.mcap"]
    with atomic_output(target, overwrite=True) as stream:
        stream.write(b"second")
    assert target.read_bytes() == b"second"


# --- interop ---------------------------------------------------------------------------------
def test_rerun_reads_the_log_as_points3d(sample_log: tuple[Path, dict], tmp_path: Path) -> None:
    rerun_cli = shutil.which("rerun")
    if rerun_cli is None:
        pytest.skip("the `rerun` binary is not in PATH (pip install rerun-sdk)")
    import rerun as rr

    path, written = sample_log
    rrd = tmp_path / "x.rrd"
    run = subprocess.run(
        [rerun_cli, "mcap", "convert", str(path), "-o", str(rrd)], capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    run = subprocess.run([rerun_cli, "rrd", "verify", str(rrd)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr

    reader = rr.chunk.RrdReader(str(rrd))
    columns = reader.store().schema().component_columns()
    points3d = {c.entity_path for c in columns if c.component == "Points3D:positions"}
    assert {tp.LIDAR_360, tp.FOREGROUND} <= points3d
    got: dict[int, np.ndarray] = {}
    for chunk in reader.stream():
        if str(chunk.entity_path) != tp.LIDAR_360:
            continue
        batch = chunk.to_record_batch()
        if "Points3D:positions" not in batch.schema.names:
            continue
        stamps = batch.column("timestamp").cast("int64").to_pylist()
        for stamp, cell in zip(stamps, batch.column("Points3D:positions"), strict=True):
            got[stamp] = np.array(cell.values.flatten().to_numpy(), np.float32).reshape(-1, 3)
    assert sorted(got) == [s for s, _ in written["clouds"]]
    for stamp, pts in written["clouds"]:
        assert np.array_equal(got[stamp], pts)


def test_reading_one_topic_skips_chunks_without_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import cldet.io.mcap_read as mcap_read

    rng = np.random.default_rng(3)
    big = make_png(400, 300)  # each image fills a chunk of its own
    log = tmp_path / "images.mcap"
    with open(log, "wb") as f, LogWriter(f, chunk_size=len(big) // 2) as writer:
        for k in range(6):
            writer.write_image(tp.IMAGE, T0 + k * 100, big, tp.FRAME_CAMERA)
            writer.write_cloud(tp.LIDAR_360, T0 + k * 100 + 50, rng.normal(size=(5, 3)), "mid360")
    opened: list[int] = []
    real = mcap_read._chunk_messages

    def counting(record: bytes, offset: int, ids: set[int] | None) -> list:  # type: ignore[type-arg]
        opened.append(offset)
        return real(record, offset, ids)

    monkeypatch.setattr(mcap_read, "_chunk_messages", counting)
    clouds = list(mcap_read.iter_clouds(log, tp.LIDAR_360))
    assert [c.stamp_ns for c in clouds] == [T0 + k * 100 + 50 for k in range(6)]
    reading_clouds = len(opened)
    opened.clear()
    images = [m for _, _, m in mcap_read.open_log(log).iter_messages([tp.IMAGE])]
    assert len(images) == 6
    with mcap_read.open_log(log) as reader:
        total = len(reader._summary.chunk_indexes)
    assert reading_clouds < total  # the image-only chunks were not opened for the clouds


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_own_chunk_reader_equals_the_mcap_library(tmp_path: Path, compression: str) -> None:
    """The reference: mcap's reader and protobuf decode the same messages and the same points.

    cldet keeps its own chunk parser and protobuf walker because they are faster (see
    benchmarks/bench_libraries.py); this holds them to the library, on a log with two chunk runs
    (the sources, then results appended by a rewrite).
    """
    from cldet.io.rewrite import rewrite_log

    source, path = tmp_path / "source.mcap", tmp_path / "annotated.mcap"
    with open(source, "wb") as f:
        written = write_sample_log(f, compression)
    extra = [
        (T0 + i * 50_000_000, lambda w, i=i: w.write_class("/cldet/class", T0 + i * 50_000_000, i))
        for i in range(6)
    ]
    rewrite_log(source, path, extra)
    with open(path, "rb") as f:
        reference = [
            (channel.topic, message.log_time, bytes(message.data))
            for _, channel, message in make_reader(f).iter_messages()
        ]
    with open_log(path) as log:
        ours = [(c.topic, m.log_time, bytes(m.data)) for _, c, m in log.iter_messages()]
        clouds = list(log.iter_clouds(tp.LIDAR_360))
    assert [t for _, t, _ in ours] == sorted(t for _, t, _ in ours)  # in log-time order
    kept = sum(n for topic, n in written["counts"].items() if not topic.startswith("/cldet/"))
    assert sorted(ours) == sorted(reference) and len(ours) == kept + 6  # earlier /cldet/ dropped
    expected = [
        (t, np.frombuffer(PointCloud.FromString(d).data, dtype=np.float32).reshape(-1, 3))
        for topic, t, d in reference
        if topic == tp.LIDAR_360
    ]
    assert len(clouds) == len(expected) == len(written["clouds"])
    for cloud, (stamp, points) in zip(clouds, expected, strict=True):
        assert cloud.stamp_ns == stamp
        np.testing.assert_array_equal(cloud.points, points)


def test_a_clouds_point_times_ride_along_as_a_time_field(tmp_path: Path) -> None:
    """``write_timed_cloud`` adds a FLOAT32 ``time`` field after x, y, z; cldet's readers give
    the times back bit for bit (``Cloud.times``); a cloud written without times reads as None;
    a ``time`` field beyond the point stride is a malformed message."""
    path = tmp_path / "log.mcap"
    pts = np.arange(12, dtype=np.float32).reshape(4, 3)
    times = np.array([0.0, 0.025, 0.05, 0.099], dtype=np.float32)
    with open(path, "wb") as f, LogWriter(f) as writer:
        writer.write_timed_cloud(tp.LIDAR_360, T0, pts, times, "mid360")
        writer.write_timed_cloud(tp.LIDAR_360, T0 + 100_000_000, pts, None, "mid360")
    timed, untimed = iter_clouds(path, tp.LIDAR_360)
    assert np.ascontiguousarray(timed.points).tobytes() == pts.tobytes()
    assert timed.times is not None and timed.times.tobytes() == times.tobytes()
    assert untimed.times is None
    with open(path, "rb") as f:
        first = next(make_reader(f).iter_messages(topics=[tp.LIDAR_360]))[2]
    header = PointCloud.FromString(first.data)
    assert [(f.name, f.offset) for f in header.fields][-1] == ("time", 12)
    assert header.point_stride == 16
    header.fields[-1].offset = 16  # past the 16-byte stride
    with pytest.raises(ValueError, match="beyond the stride"):
        decode_timed(header.SerializeToString())
