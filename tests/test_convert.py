"""``converters.mcap_convert`` and ``cldet convert``: round trips bit for bit, crashes, bad input."""

from __future__ import annotations

import io
import os
import re
import shutil
import subprocess
import tracemalloc
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from mcap.reader import make_reader
from typer.testing import CliRunner

import cldet
from cldet.io import LogReader, LogWriter, list_topics, open_log, read_metadata
from cldet.io import topics as tp
from cldet.simulate.sensors import encode_png
from converters import mcap_convert, mmaud
from converters.mcap_convert import convert_dataset, convert_sequence

CLOUD_DIRS = {"lidar_360": tp.LIDAR_360, "livox_avia": tp.LIVOX_AVIA, "radar_enhance_pcl": tp.RADAR}


# --- building tiny datasets --------------------------------------------------------------------
def make_png(width: int, height: int) -> bytes:
    """A real (tiny, uniform grey) RGB PNG."""
    return encode_png(np.full((height, width, 3), 0x40, dtype=np.uint8))


def stamp_names(start_s: int, n: int, period_us: int, offset_us: int = 0) -> list[str]:
    names = []
    for i in range(n):
        us = offset_us + i * period_us + (i * 37) % 1000
        names.append(f"{start_s + us // 1_000_000}.{us % 1_000_000:06d}")
    return names


def build_sequence(seq_dir: Path, rng: np.random.Generator, *, labels: bool, n: int = 6) -> None:
    """A tiny challenge sequence: clouds with zero rows, empty radar frames, labels, PNGs."""
    start = 1_706_255_621
    for name in stamp_names(start, n, 100_000, 600_227):  # Mid-360: packets of zero rows
        a = np.round(rng.normal(0, 20, (96 * 5, 3)), 3)
        a[96:288] = 0.0
        a[rng.random(len(a)) < 0.3] = 0.0
        np.save(seq_dir / "lidar_360" / f"{name}.npy", a)
    for i, name in enumerate(stamp_names(start, n, 100_000, 614_227)):  # Avia: -0.0 zeros
        a = np.tile(np.array([-0.0, -0.0, 0.0]), (240, 1))
        if i % 2:
            a[:i] = rng.normal(0, 50, (i, 3))
        np.save(seq_dir / "livox_avia" / f"{name}.npy", a)
    for i, name in enumerate(stamp_names(start, n + 3, 66_667, 601_000)):  # radar: (0,) empties
        a = np.empty((0,)) if i % 3 == 0 else rng.normal(0, 5, (2 + i, 3))
        np.save(seq_dir / "radar_enhance_pcl" / f"{name}.npy", a)
    if labels:
        gt_names = stamp_names(start, 2 * n, 50_000, 565_000)
        gt_names[1] = gt_names[1].rstrip("0") or gt_names[1]  # a float-printed name
        gt_names[2] = f"{start}.71419"  # fewer than 6 decimals = .714190
        for name in gt_names:
            np.save(seq_dir / "ground_truth" / f"{name}.npy", rng.normal(0, 10, 3))
            np.save(seq_dir / "class" / f"{name}.npy", np.array([2]))
    for name in stamp_names(start, 3, 33_333, 602_000):
        (seq_dir / "Image" / f"{name}.png").write_bytes(make_png(24, 8))


def build_dataset(root: Path, n_train: int = 2, n_val: int = 1, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    for split, count, labels in (("train", n_train, True), ("val", n_val, False)):
        for i in range(1, count + 1):
            seq_dir = root / split / f"seq{i:04d}"
            folders = list(CLOUD_DIRS) + ["Image"] + (["ground_truth", "class"] if labels else [])
            for folder in folders:
                (seq_dir / folder).mkdir(parents=True)
            build_sequence(seq_dir, rng, labels=labels)
    return root


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    return build_dataset(tmp_path / "data")


# --- an independent reference of what a log must hold --------------------------------------------
def ns_from_name(name: str) -> int:
    seconds, fraction = name.split(".")
    return int(seconds) * 1_000_000_000 + int(fraction.ljust(6, "0")) * 1000


def stamped_files(folder: Path, suffix: str) -> list[tuple[int, Path]]:
    return sorted((ns_from_name(p.name[: -len(suffix)]), p) for p in folder.glob(f"*{suffix}"))


def expected_points(path: Path) -> np.ndarray:
    a = np.load(path)
    if a.size == 0:
        return np.empty((0, 3), np.float32)
    return a[~np.all(a == 0, axis=1)].astype(np.float32)


def expected_times(path: Path) -> np.ndarray:
    """Each kept row's firing time, the obvious way: row i of N fired at i / N of 100 ms."""
    a = np.load(path)
    rows = np.flatnonzero(np.any(a != 0, axis=1))  # (a row at a time took 2 min on the real sample)
    return (rows * (0.1 / len(a))).astype(np.float32)


def raw_messages(log: Path, topic: str) -> list:
    with open(log, "rb") as f:
        return [m for _, _, m in make_reader(f).iter_messages(topics=[topic])]


def check_log(log: Path, seq_dir: Path, *, images: bool = True) -> None:
    """Every channel of ``log`` equals the source folder, bit for bit, with exact stamps."""
    with open_log(log) as reader:
        check_log_with(reader, log, seq_dir, images=images)


def check_log_with(reader: LogReader, log: Path, seq_dir: Path, *, images: bool) -> None:
    topics_in_log = reader.list_topics()
    for folder, topic in CLOUD_DIRS.items():
        if not (seq_dir / folder).is_dir():
            assert topic not in topics_in_log
            continue
        files = stamped_files(seq_dir / folder, ".npy")
        messages = raw_messages(log, topic)
        assert len(messages) == len(files), topic
        for message, (stamp, path) in zip(messages, files, strict=True):
            assert message.log_time == message.publish_time == stamp, path
            cloud = PointCloud.FromString(message.data)
            assert cloud.timestamp.ToNanoseconds() == stamp
            assert cloud.frame_id == ("radar" if folder == "radar_enhance_pcl" else "mid360")
            xyz = [("x", 0), ("y", 4), ("z", 8)]
            assert cloud.pose.HasField("position") and cloud.pose.orientation.w == 1.0
            want = expected_points(path)
            if folder == "radar_enhance_pcl":  # a radar's rows are targets, not timed shots
                assert cloud.point_stride == 12
                assert [(f.name, f.offset) for f in cloud.fields] == xyz
                assert cloud.data == want.tobytes(), path  # float32 bit for bit
                continue
            # a LiDAR's rows: each point's firing time after the stamp rides along (Cloud.times)
            assert cloud.point_stride == 16
            assert [(f.name, f.offset) for f in cloud.fields] == [*xyz, ("time", 12)]
            timed = np.column_stack([want, expected_times(path)]).astype(np.float32)
            assert cloud.data == timed.tobytes(), path  # float32 bit for bit
        clouds = list(reader.iter_clouds(topic))  # and through cldet's own reader
        for cloud_read, (stamp, path) in zip(clouds, files, strict=True):
            assert cloud_read.stamp_ns == stamp
            want = expected_points(path)
            assert np.ascontiguousarray(cloud_read.points).tobytes() == want.tobytes()
            if folder == "radar_enhance_pcl":
                assert cloud_read.times is None
            else:
                assert cloud_read.times is not None
                np.testing.assert_array_equal(cloud_read.times, expected_times(path))
    if (seq_dir / "ground_truth").is_dir():
        files = stamped_files(seq_dir / "ground_truth", ".npy")
        got = list(reader.iter_positions(tp.GROUND_TRUTH))
        assert [g.stamp_ns for g in got] == [s for s, _ in files]
        for g, (_, path) in zip(got, files, strict=True):
            assert np.array_equal(g.position, np.load(path))
        messages = raw_messages(log, tp.GROUND_TRUTH)
        assert all(m.log_time == m.publish_time for m in messages)
        labels = list(reader.iter_classes(tp.CLASS))
        assert [(c.stamp_ns, c.class_id) for c in labels] == [
            (s, int(np.load(p)[0])) for s, p in stamped_files(seq_dir / "class", ".npy")
        ]
    if (seq_dir / "Image").is_dir() and images:
        files = stamped_files(seq_dir / "Image", ".png")
        messages = raw_messages(log, tp.IMAGE)
        calibrations = raw_messages(log, tp.IMAGE_CALIBRATION)
        assert [m.log_time for m in messages] == [s for s, _ in files]
        assert [m.log_time for m in calibrations] == [s for s, _ in files]
        for message, cal, (_, path) in zip(messages, calibrations, files, strict=True):
            image = CompressedImage.FromString(message.data)
            assert image.data == path.read_bytes() and image.format == "png"
            assert CameraCalibration.FromString(cal.data).frame_id == image.frame_id
    else:
        assert tp.IMAGE not in topics_in_log
    meta = reader.metadata()[tp.METADATA_SOURCE]
    assert meta["split"] == seq_dir.parent.name and meta["sequence"] == seq_dir.name
    assert Path(meta["source"]) == seq_dir.resolve()
    assert meta["cldet_version"] == cldet.__version__
    for folder in mmaud.MODALITIES:
        if (seq_dir / folder).is_dir() and (images or folder != "Image"):
            n = len(list((seq_dir / folder).iterdir()))
            assert meta[f"count.{folder}"] == str(n), folder
            assert topics_in_log[tp.MODALITY_TOPICS[folder]] == n


def leftovers(out: Path) -> list[str]:
    return sorted(p.name for p in out.rglob("*") if p.is_file() and ".tmp-" in p.name)


class CountingProgress:
    def __init__(self) -> None:
        self.total = -1
        self.done = 0

    def start(self, total: int, description: str) -> None:
        self.total = total

    def advance(self, n: int = 1) -> None:
        self.done += n


# --- round trips -----------------------------------------------------------------------------
def test_convert_tiny_dataset_round_trips(tiny: Path, tmp_path: Path) -> None:
    out = tmp_path / "logs"
    progress = CountingProgress()
    report = convert_dataset(tiny, out, workers=1, progress=progress)
    assert report.ok and not report.skipped
    expected = [out / "train/seq0001.mcap", out / "train/seq0002.mcap", out / "val/seq0001.mcap"]
    assert list(report.converted) == expected
    for log in expected:
        check_log(log, tiny / log.parent.name / log.stem)
    n_files = sum(1 for p in tiny.rglob("*") if p.is_file())
    assert report.frames == progress.total == progress.done == n_files
    assert report.bytes_in == sum(p.stat().st_size for p in tiny.rglob("*") if p.is_file())
    assert report.bytes_out == sum(p.stat().st_size for p in expected)
    assert leftovers(out) == []


def test_convert_sequence_into_memory(tiny: Path) -> None:
    (seq,) = mmaud.find_sequences(tiny, splits=["val"])
    buffer = io.BytesIO()
    with LogWriter(buffer, compression="lz4") as writer:
        counts = convert_sequence(seq, writer, images=False)
    assert counts == {m: len(list((seq.path / m).iterdir())) for m in CLOUD_DIRS}
    assert not buffer.closed
    log = tiny.parent / "mem.mcap"
    log.write_bytes(buffer.getvalue())
    check_log(log, seq.path, images=False)


def test_real_sample_round_trips(real_sample: Path, tmp_path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the sample's reference/ folder is not a split
        report = convert_dataset(real_sample, tmp_path, splits=["val"], workers=1)
    assert report.ok, report.describe()
    log = tmp_path / "val" / "seq0001.mcap"
    check_log(log, real_sample / "val" / "seq0001")
    counts = list_topics(log)
    assert counts == {tp.TF: 1, tp.LIDAR_360: 88, tp.LIVOX_AVIA: 88, tp.RADAR: 132}
    assert report.bytes_out < report.bytes_in / 10  # valid float32 rows only, compressed


def test_simulated_sequence_round_trips(tmp_path: Path) -> None:
    simulate = pytest.importorskip("cldet.simulate")
    if not hasattr(simulate, "simulate_sequence"):
        pytest.skip("cldet.simulate.simulate_sequence is not available yet")
    seq_dir = tmp_path / "sim" / "train" / "seq0007"
    simulate.simulate_sequence(seq_dir, seed=11, duration_s=1.0)
    report = convert_dataset(tmp_path / "sim", tmp_path / "logs", workers=1)
    assert report.ok, report.describe()
    check_log(tmp_path / "logs" / "train" / "seq0007.mcap", seq_dir)


def test_memory_stays_flat_with_sequence_length(tmp_path: Path) -> None:
    """Peak Python/numpy memory of a conversion does not grow with the number of frames."""
    rng = np.random.default_rng(3)
    peaks = []
    for n_frames in (8, 32):
        seq_dir = tmp_path / f"n{n_frames}" / "val" / "seq0001"
        (seq_dir / "lidar_360").mkdir(parents=True)
        for name in stamp_names(1_706_255_621, n_frames, 100_000):
            frame = np.zeros((20064, 3))
            frame[::5] = rng.normal(0, 20, (4013, 3))
            np.save(seq_dir / "lidar_360" / f"{name}.npy", frame)
        (seq,) = mmaud.find_sequences(seq_dir.parent.parent)
        with open(tmp_path / f"n{n_frames}.mcap", "wb") as stream:
            tracemalloc.start()
            with LogWriter(stream, chunk_size=1 << 17) as writer:  # both runs fill chunks
                convert_sequence(seq, writer)
            peaks.append(tracemalloc.get_traced_memory()[1])
            tracemalloc.stop()
    # 32 frames of 481 kB (15 MB of input) need no more memory than 8 frames (4 MB)
    assert peaks[1] < 1.2 * peaks[0], peaks


def test_no_images(tiny: Path, tmp_path: Path) -> None:
    report = convert_dataset(tiny, tmp_path / "logs", splits=["train"], workers=1, images=False)
    assert report.ok
    log = tmp_path / "logs" / "train" / "seq0001.mcap"
    check_log(log, tiny / "train" / "seq0001", images=False)
    assert "count.Image" not in read_metadata(log)[tp.METADATA_SOURCE]


def test_rerun_imports_the_converted_log_as_points3d(tiny: Path, tmp_path: Path) -> None:
    rerun_cli = shutil.which("rerun")
    if rerun_cli is None:
        pytest.skip("the `rerun` binary is not in PATH (pip install rerun-sdk)")
    import rerun as rr

    convert_dataset(tiny, tmp_path / "logs", sequences=["seq0001"], splits=["train"], workers=1)
    rrd = tmp_path / "x.rrd"
    log = tmp_path / "logs" / "train" / "seq0001.mcap"
    run = subprocess.run(
        [rerun_cli, "mcap", "convert", str(log), "-o", str(rrd)], capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    run = subprocess.run([rerun_cli, "rrd", "verify", str(rrd)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    columns = rr.chunk.RrdReader(str(rrd)).store().schema().component_columns()
    points3d = {c.entity_path for c in columns if c.component == "Points3D:positions"}
    assert points3d >= {tp.LIDAR_360, tp.LIVOX_AVIA, tp.RADAR}


# --- crashes, bad input, existing outputs -------------------------------------------------------
def fail_on_nth_cloud(monkeypatch: pytest.MonkeyPatch, n: int, exc: BaseException) -> None:
    original: Callable[..., None] = LogWriter.write_cloud
    calls = {"n": 0}

    def failing(self: LogWriter, *args: object, **kwargs: object) -> None:
        calls["n"] += 1
        if calls["n"] == n:
            raise exc
        original(self, *args, **kwargs)

    monkeypatch.setattr(LogWriter, "write_cloud", failing)


@pytest.mark.parametrize("exc", [KeyboardInterrupt(), RuntimeError("disk on fire")])
def test_crash_midway_leaves_no_file(
    tiny: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exc: BaseException
) -> None:
    out = tmp_path / "logs"
    fail_on_nth_cloud(monkeypatch, 5, exc)
    with pytest.raises(type(exc)):
        convert_dataset(tiny, out, splits=["val"], workers=1)
    assert sorted(p.name for p in (out / "val").iterdir()) == []  # no .mcap, no temp file


@pytest.mark.parametrize("exc", [KeyboardInterrupt(), RuntimeError("disk on fire")])
def test_crash_keeps_the_earlier_output(
    tiny: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exc: BaseException
) -> None:
    out = tmp_path / "logs"
    assert convert_dataset(tiny, out, splits=["val"], workers=1).ok
    earlier = (out / "val" / "seq0001.mcap").read_bytes()
    fail_on_nth_cloud(monkeypatch, 9, exc)
    with pytest.raises(type(exc)):
        convert_dataset(tiny, out, splits=["val"], workers=1, overwrite=True)
    assert (out / "val" / "seq0001.mcap").read_bytes() == earlier
    assert sorted(p.name for p in (out / "val").iterdir()) == ["seq0001.mcap"]


def corrupt_one_file(tiny: Path) -> Path:
    bad = sorted((tiny / "train" / "seq0002" / "lidar_360").iterdir())[3]
    bad.write_bytes(bad.read_bytes()[:100])  # truncated .npy
    return bad


@pytest.mark.parametrize("workers", [1, 2])
def test_bad_sequence_is_reported_and_others_convert(
    tiny: Path, tmp_path: Path, workers: int
) -> None:
    bad = corrupt_one_file(tiny)
    out = tmp_path / "logs"
    progress = CountingProgress()
    report = convert_dataset(tiny, out, workers=workers, progress=progress)
    assert not report.ok
    assert [f.sequence for f in report.failed] == ["train/seq0002"]
    assert (
        str(bad) in report.failed[0].message and "truncated or corrupt" in report.failed[0].message
    )
    assert list(report.converted) == [out / "train/seq0001.mcap", out / "val/seq0001.mcap"]
    check_log(out / "train/seq0001.mcap", tiny / "train/seq0001")
    assert not (out / "train/seq0002.mcap").exists()
    assert leftovers(out) == []
    assert progress.done >= report.frames > 0  # worker progress reached the parent
    assert "FAILED 1 sequence(s)" in report.describe() and str(bad) in report.describe()


def test_parallel_progress_counts_every_frame_exactly(tiny: Path, tmp_path: Path) -> None:
    progress = CountingProgress()
    report = convert_dataset(tiny, tmp_path / "logs", workers=2, progress=progress)
    assert report.ok and report.frames == progress.total == progress.done > 0


@pytest.mark.parametrize("case", ["no-modality", "empty-modalities", "seq2-beside-seq0002"])
@pytest.mark.parametrize("workers", [1, 2])
def test_one_unusable_sequence_folder_does_not_stop_the_dataset(
    tiny: Path, tmp_path: Path, case: str, workers: int
) -> None:
    bad = tiny / "train" / "seq0003"
    if case == "no-modality":
        bad.mkdir()
        expected = r"empty sequence .*seq0003: no modality folder"
    elif case == "empty-modalities":
        (bad / "lidar_360").mkdir(parents=True)
        (bad / "Image").mkdir()
        expected = (
            r"empty sequence .*seq0003: its modality folders \(lidar_360, Image\) are all empty"
        )
    else:
        shutil.copytree(tiny / "train" / "seq0002", tiny / "train" / "seq2")
        bad = tiny / "train" / "seq2"
        expected = r"two folders in .*train name sequence seq0002: seq0002 and seq2"
    out = tmp_path / "logs"
    report = convert_dataset(tiny, out, workers=workers)
    assert not report.ok and len(report.failed) == 1
    (failure,) = report.failed
    assert failure.sequence == ("train/seq0002" if "seq2" in case else "train/seq0003")
    assert re.search(expected, failure.message), failure.message
    good = [out / "train/seq0001.mcap", out / "val/seq0001.mcap"]
    if "seq2" not in case:
        good.insert(1, out / "train/seq0002.mcap")
    assert list(report.converted) == good
    assert leftovers(out) == []


def test_cli_reports_an_empty_sequence_and_exits_1(
    cli: Callable[..., object], tiny: Path, tmp_path: Path
) -> None:
    (tiny / "val" / "seq0002").mkdir()
    result = cli("convert", tiny, "-o", tmp_path / "logs", "--workers", 1)
    assert result.exit_code == 1  # type: ignore[attr-defined]
    output = result.output  # type: ignore[attr-defined]
    assert "val/seq0002: empty sequence" in output and "converted 3 sequence(s)" in output
    assert "ERROR: 1 sequence(s) failed to convert" in output and "Traceback" not in output


def test_unknown_folder_in_a_sequence_is_warned_about(
    cli: Callable[..., object], tiny: Path, tmp_path: Path
) -> None:
    seq = tiny / "val" / "seq0001"
    (seq / "lidar_360").rename(seq / "Lidar_360")
    with pytest.warns(
        UserWarning, match=r"not modalities .*: Lidar_360 \(did you mean lidar_360\?\)"
    ):
        mmaud.find_sequences(tiny, splits=["val"])
    result = cli("convert", tiny, "-o", tmp_path / "logs", "--split", "val", "--workers", 1)
    assert result.exit_code == 0  # type: ignore[attr-defined]
    assert (
        "WARNING: ignoring folders in" in result.output  # type: ignore[attr-defined]
        and "Lidar_360 (did you mean lidar_360?)" in result.output  # type: ignore[attr-defined]
    )


@pytest.mark.parametrize("kind", ["fifo", "folder", "broken-link"])
def test_a_frame_that_is_not_a_regular_file_is_named(tiny: Path, tmp_path: Path, kind: str) -> None:
    folder = tiny / "train" / "seq0002" / "lidar_360"
    odd = folder / "1706255630.000000.npy"
    if kind == "fifo":
        os.mkfifo(odd)
        shown = "a FIFO (named pipe)"
    elif kind == "folder":
        odd.mkdir()
        shown = "a folder"
    else:
        odd.symlink_to(tmp_path / "nowhere.npy")
        shown = "a broken symbolic link"
    out = tmp_path / "logs"
    report = convert_dataset(tiny, out, workers=1)  # would block forever on np.load of a FIFO
    (failure,) = report.failed
    assert failure.sequence == "train/seq0002"
    assert failure.message == (f"{odd} is {shown}, not a regular file: expected a <stamp>.npy file")
    assert len(report.converted) == 2 and leftovers(out) == []


def test_existing_output_is_skipped_unless_overwrite(tiny: Path, tmp_path: Path) -> None:
    out = tmp_path / "logs"
    convert_dataset(tiny, out, splits=["val"], workers=1)
    log = out / "val" / "seq0001.mcap"
    log.write_bytes(b"an older log")
    report = convert_dataset(tiny, out, splits=["val"], workers=1)
    assert report.skipped == (log,) and report.converted == () and report.ok
    assert log.read_bytes() == b"an older log"
    assert "skipped 1 existing log(s)" in report.describe()
    report = convert_dataset(tiny, out, splits=["val"], workers=1, overwrite=True)
    assert report.converted == (log,)
    check_log(log, tiny / "val" / "seq0001")


def test_unknown_compression_and_missing_root(tmp_path: Path) -> None:
    from cldet.errors import DatasetError, LogError

    with pytest.raises(LogError, match="unknown compression 'gzip'"):
        convert_dataset(tmp_path, tmp_path / "out", compression="gzip")
    with pytest.raises(DatasetError, match="absent"):
        convert_dataset(tmp_path / "absent", tmp_path / "out")


def test_image_with_a_bad_header_names_the_folder(tiny: Path, tmp_path: Path) -> None:
    png = sorted((tiny / "val" / "seq0001" / "Image").iterdir())[1]
    png.write_bytes(png.read_bytes()[:10])  # PNG signature, no IHDR
    report = convert_dataset(tiny, tmp_path / "logs", splits=["val"], workers=1)
    (failure,) = report.failed
    assert str(tiny / "val" / "seq0001" / "Image") in failure.message
    assert "not a valid PNG" in failure.message


# --- the CLI ---------------------------------------------------------------------------------
@pytest.fixture
def cli() -> Callable[..., object]:
    from cldet.cli import app

    runner = CliRunner()
    return lambda *args: runner.invoke(app, [str(a) for a in args])


def test_cli_help_teaches(cli: Callable[..., object]) -> None:
    result = cli("convert", "--help")
    assert result.exit_code == 0  # type: ignore[attr-defined]
    text = result.output  # type: ignore[attr-defined]
    for word in (
        "--split",
        "--sequence",
        "--workers",
        "--compression",
        "--no-images",
        "--overwrite",
        "/lidar_360",
    ):
        assert word in text


def test_cli_converts_and_reports_failures(
    cli: Callable[..., object], tiny: Path, tmp_path: Path
) -> None:
    bad = corrupt_one_file(tiny)
    out = tmp_path / "logs"
    result = cli(
        "convert", tiny, "-o", out, "--workers", 1, "--compression", "lz4", "--split", "train"
    )
    assert result.exit_code == 1  # type: ignore[attr-defined]
    output = result.output  # type: ignore[attr-defined]
    assert (
        "train/seq0002" in output and str(bad) in output and "ERROR: 1 sequence(s) failed" in output
    )
    log = out / "train" / "seq0001.mcap"
    check_log(log, tiny / "train" / "seq0001")
    with open(log, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and {c.compression for c in summary.chunk_indexes} == {"lz4"}

    result = cli("convert", tiny, "-o", out, "--sequence", "seq1", "--split", "train")
    assert result.exit_code == 0  # type: ignore[attr-defined]
    assert "skipped 1 existing log(s)" in result.output  # type: ignore[attr-defined]


def test_cli_error_for_missing_split(
    cli: Callable[..., object], tiny: Path, tmp_path: Path
) -> None:
    result = cli("convert", tiny, "-o", tmp_path / "logs", "--split", "test")
    assert result.exit_code == 1  # type: ignore[attr-defined]
    assert "ERROR: split folder" in result.output  # type: ignore[attr-defined]


def test_module_exports() -> None:
    assert mcap_convert.__all__ == [
        "ConvertFailure",
        "ConvertReport",
        "convert_dataset",
        "convert_sequence",
    ]
