"""``annotate`` end to end: simulated sequence -> MCAP log -> results channels and Rerun recording."""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from cldet.cli import app
from cldet.config import CldetConfig, FramesConfig
from cldet.core import estimator as estimator_module
from cldet.errors import ConfigError, FrameOrderError, LogError
from cldet.io import topics
from cldet.io.mcap_read import iter_estimates, list_topics, open_log, read_metadata
from cldet.io.mcap_write import LogWriter
from cldet.io.sources import iter_log_positions, select_topics
from cldet.pipeline import annotate_log, annotate_logs, read_frames
from cldet.types import PositionSample


def _messages(path: Path) -> list[tuple[str, int, int, bytes]]:
    with open(path, "rb") as f:
        return [
            (c.topic, m.log_time, m.publish_time, m.data)
            for _, c, m in make_reader(f).iter_messages(log_time_order=True)
        ]


@pytest.fixture(scope="module")
def log_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("pipeline")


@pytest.fixture(scope="module")
def source_log(log_dir: Path, make_log: Callable[..., Path]) -> Path:
    return make_log(log_dir, seed=7101)


def test_annotate_adds_result_channels_and_keeps_sources_byte_identical(
    source_log: Path, tmp_path: Path
) -> None:
    out = tmp_path / "annotated.mcap"
    report = annotate_log(source_log, output=out, write_rrd=False)
    before = _messages(source_log)
    after = _messages(out)
    assert [m for m in after if not m[0].startswith("/cldet/")] == before
    counts = list_topics(out)
    n_frames = counts[topics.LIDAR_360]
    assert report.frames == n_frames
    for topic in (
        topics.ESTIMATE,
        topics.CAUSAL,
        topics.POSE,
        topics.FOREGROUND,
        topics.DRONE,
        topics.CENTROIDS,
    ):
        assert counts[topic] == n_frames, topic
    assert counts[topics.TRAJECTORY] == counts[topics.TRACK] == counts[topics.TRUTH_TRACK] == 1
    assert counts[topics.CLUSTERS] == 2 * n_frames  # the other clusters and the chosen one
    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    schema_of = {
        c.topic: summary.schemas[c.schema_id].name
        for c in summary.channels.values()
        if c.topic.startswith("/cldet/")
    }
    assert schema_of == {
        topics.ESTIMATE: "cldet.Estimate",
        topics.CAUSAL: "cldet.Estimate",
        topics.POSE: "foxglove.PoseInFrame",
        topics.TRAJECTORY: "foxglove.PosesInFrame",
        topics.CLUSTERS: "foxglove.SceneUpdate",
        topics.FOREGROUND: "foxglove.PointCloud",
        topics.DRONE: "foxglove.PointCloud",
        topics.TRACK: "foxglove.PointCloud",
        topics.TRUTH_TRACK: "foxglove.PointCloud",
        topics.CENTROIDS: "foxglove.PointCloud",
    }
    estimates = [e for e, _ in iter_estimates(out)]
    assert [e.stamp_ns for e in estimates] == [m[1] for m in before if m[0] == topics.LIDAR_360]
    meta = read_metadata(out)[topics.METADATA_CONFIG]
    assert meta["method"] == "track" and '"method": "track"' in meta["config"]
    assert report.rms_error_m is not None and report.rms_error_m < 1.0


def test_annotating_twice_replaces_the_earlier_results(source_log: Path, tmp_path: Path) -> None:
    log = tmp_path / "log.mcap"
    shutil.copy(source_log, log)
    annotate_log(log, write_rrd=False)
    first = list_topics(log)
    annotate_log(log, config=CldetConfig(method="cl-det"), write_rrd=False)
    assert list_topics(log) == first
    assert read_metadata(log)[topics.METADATA_CONFIG]["method"] == "cl-det"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.mcap"]


def test_a_failure_midway_leaves_the_log_intact_and_no_temporary_file(
    source_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    log = tmp_path / "log.mcap"
    shutil.copy(source_log, log)
    original = log.read_bytes()
    calls = {"n": 0}
    real_process = estimator_module.TrackEstimator.register_frame

    def failing(self: estimator_module.TrackEstimator, frame):  # type: ignore[no-untyped-def]
        calls["n"] += 1
        if calls["n"] == 10:
            raise RuntimeError("disk on fire")
        return real_process(self, frame)

    monkeypatch.setattr(estimator_module.TrackEstimator, "register_frame", failing)
    with pytest.raises(RuntimeError, match="disk on fire"):
        annotate_log(log)
    assert log.read_bytes() == original
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.mcap"]


def test_a_log_without_lidar_is_refused_with_the_topics_it_has(tmp_path: Path) -> None:
    log = tmp_path / "gt_only.mcap"
    with open(log, "wb") as f, LogWriter(f) as writer:
        writer.write_pose(topics.GROUND_TRUTH, 1_000, [0.0, 0.0, 1.0], topics.FRAME_MID360)
    with pytest.raises(LogError, match=r"no /lidar_360 channel.*/ground_truth"):
        annotate_log(log)


def test_one_bad_log_among_good_ones_is_reported(source_log: Path, tmp_path: Path) -> None:
    good = tmp_path / "good.mcap"
    shutil.copy(source_log, good)
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file")
    reports, failures = annotate_logs([bad, good], write_rrd=False, workers=1)
    assert [r.log for r in reports] == [good]
    assert len(failures) == 1 and failures[0][0] == bad and "bad.mcap" in failures[0][1]


def test_review_recording_has_the_entities_and_verifies(source_log: Path, tmp_path: Path) -> None:
    import rerun as rr

    out = tmp_path / "annotated.mcap"
    report = annotate_log(source_log, output=out)
    assert report.rrd == out.with_suffix(".rrd") and report.rrd.is_file()
    paths = set(rr.chunk.RrdReader(report.rrd).store().schema().entity_paths())
    expected = {
        "/world/lidar/mid360",
        "/world/lidar/avia",
        "/world/foreground",
        "/world/clusters",
        "/world/drone/estimate",
        "/world/drone/trajectory",
        "/world/truth/trajectory",
        "/world/truth/position",
        "/world/truth/error",
        "/plots/error_m",
    }
    assert expected <= paths, expected - paths
    rerun = shutil.which("rerun")
    if rerun is None:
        pytest.skip("the rerun CLI is not on PATH")
    done = subprocess.run(
        [rerun, "rrd", "verify", str(report.rrd)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr


def test_rerun_opens_the_annotated_log_with_its_result_channels(
    source_log: Path, tmp_path: Path
) -> None:
    """The appended layout (sources, then results, one summary) is read by Rerun's MCAP loader."""
    import rerun as rr

    rerun = shutil.which("rerun")
    if rerun is None:
        pytest.skip("the rerun CLI is not on PATH (pip install rerun-sdk)")
    log = tmp_path / "log.mcap"
    shutil.copy(source_log, log)
    annotate_log(log, write_rrd=False)
    annotate_log(log, write_rrd=False)  # the second run cuts the first one's results off
    rrd = tmp_path / "log.rrd"
    for command in (["mcap", "convert", str(log), "-o", str(rrd)], ["rrd", "verify", str(rrd)]):
        done = subprocess.run([rerun, *command], capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
    paths = {str(p) for p in rr.chunk.RrdReader(rrd).store().schema().entity_paths()}
    assert {topics.LIDAR_360, topics.FOREGROUND, topics.CLUSTERS} <= paths, paths


def test_cli_annotate_with_a_config_file(source_log: Path, tmp_path: Path) -> None:
    log = tmp_path / "log.mcap"
    shutil.copy(source_log, log)
    good = tmp_path / "good.yaml"
    good.write_text("method: cl-det\n")
    result = CliRunner().invoke(app, ["annotate", str(log), "--config", str(good), "--no-rrd"])
    assert result.exit_code == 0, result.output
    assert "seq0001" in result.output
    assert read_metadata(log)[topics.METADATA_CONFIG]["method"] == "cl-det"
    typo = tmp_path / "typo.yaml"
    typo.write_text("methd: track\n")
    result = CliRunner().invoke(app, ["annotate", str(log), "--config", str(typo), "--no-rrd"])
    assert result.exit_code == 1
    assert "methd" in result.output and "typo.yaml" in result.output


def test_config_errors_are_config_errors(tmp_path: Path) -> None:
    from cldet.config import load_config

    bad = tmp_path / "bad.yaml"
    bad.write_text("clustering:\n  eps_mm: 3\n")
    with pytest.raises(ConfigError, match="eps_mm"):
        load_config(bad)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [7301, 7302])
def test_track_beats_cl_det_on_unseen_seeds(
    log_dir: Path, make_log: Callable[..., Path], seed: int
) -> None:
    log = make_log(log_dir, seed=seed, duration_s=5.0)
    track = annotate_log(log, output=log_dir / f"t{seed}.mcap", write_rrd=False)
    baseline = annotate_log(
        log, config=CldetConfig(method="cl-det"), output=log_dir / f"c{seed}.mcap", write_rrd=False
    )
    assert track.rms_error_m is not None and baseline.rms_error_m is not None
    assert track.rms_error_m < 0.6
    assert track.rms_error_m < baseline.rms_error_m / 3
    assert np.isfinite(track.rms_error_m)


def test_annotate_reads_the_log_once_and_writes_the_causal_estimate(
    source_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import cldet.io.mcap_read

    # one pass: the LiDAR's, the Avia's and the truth's messages come from each chunk,
    # decompressed once
    decompressed: list[int] = []
    real = cldet.io.mcap_read._chunk_data

    def counting(record: bytes, offset: int) -> bytes:
        decompressed.append(offset)
        return real(record, offset)

    monkeypatch.setattr(cldet.io.mcap_read, "_chunk_data", counting)
    with open_log(source_log) as reader:
        sensors = select_topics(reader)
        n_chunks = len(reader.summary.chunk_indexes)
    truth: list[PositionSample] = []
    frames = list(read_frames(source_log, sensors, FramesConfig(), truth=truth))
    assert n_chunks > 1 and sorted(decompressed) == sorted(set(decompressed))
    assert len(decompressed) == n_chunks
    expected = list(iter_log_positions(source_log, topics.GROUND_TRUTH))
    assert [t.stamp_ns for t in truth] == [t.stamp_ns for t in expected]
    np.testing.assert_array_equal([t.position for t in truth], [t.position for t in expected])
    assert len(frames) == list_topics(source_log)[topics.LIDAR_360]
    # each point dated where in its scan it was fired (converted from the arrays' rows)
    assert all(f.mid360_times is not None and len(f.mid360_times) == len(f.mid360) for f in frames)
    assert all(f.avia_times is not None for f in frames if f.avia_stamp_ns is not None)

    out = tmp_path / "once.mcap"
    report = annotate_log(source_log, output=out, write_rrd=False)
    messages = _messages(out)
    causal = [m for m in messages if m[0] == "/cldet/causal"]
    refined = [m for m in messages if m[0] == "/cldet/estimate"]
    assert len(causal) == len(refined) == report.frames


def test_two_clouds_with_one_stamp_are_a_clear_error_and_the_cli_goes_on(tmp_path: Path) -> None:
    # another tool's log: two /lidar_360 clouds share a stamp
    bad = tmp_path / "dup.mcap"
    rng = np.random.default_rng(0)
    with open(bad, "wb") as f, LogWriter(f) as writer:
        for stamp in (1_000_000_000, 1_100_000_000, 1_100_000_000, 1_200_000_000):
            pts = rng.uniform(-5, 5, (50, 3)).astype(np.float32)
            writer.write_cloud(topics.LIDAR_360, stamp, pts, topics.FRAME_MID360)
    before = bad.read_bytes()
    with pytest.raises(FrameOrderError, match=r"dup\.mcap: frame stamped 1100000000 ns repeats"):
        annotate_log(bad, write_rrd=False)
    assert bad.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dup.mcap"]
    result = CliRunner().invoke(app, ["annotate", str(bad), "--no-rrd"])
    assert result.exit_code != 0
    assert "repeats the stamp" in result.output and "Traceback" not in result.output


def test_a_folder_stands_for_every_log_under_it(source_log: Path, tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    (logs / "val").mkdir(parents=True)
    shutil.copy(source_log, logs / "a.mcap")
    shutil.copy(source_log, logs / "val" / "b.mcap")
    (logs / ".b.mcap.12345.tmp.mcap").write_bytes(b"a run's temporary file")  # left out
    result = CliRunner().invoke(app, ["annotate", str(logs), "--no-rrd", "--workers", "1"])
    assert result.exit_code == 0, result.output
    for log in (logs / "a.mcap", logs / "val" / "b.mcap"):
        assert list_topics(log).get(topics.ESTIMATE), log
    empty = tmp_path / "empty"
    empty.mkdir()
    result = CliRunner().invoke(app, ["annotate", str(empty), "--no-rrd"])
    assert result.exit_code == 1
    assert f"{empty} is a folder with no MCAP log" in result.output
    assert "Traceback" not in result.output
