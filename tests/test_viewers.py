"""What the viewers see: one frame tree, results Rerun draws, the review recording, screenshots.

The annotated log is read here with independent code (the ``mcap`` library and protobuf
classes built from each channel's own schema, not :mod:`cldet.io`), as a third-party tool
would read it.
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from cldet.core.estimator import FrameDetections, SequenceEstimate
from cldet.io import topics
from cldet.io.mcap_write import LogWriter
from cldet.io.transforms import sensor_tree, tree_problem
from cldet.pipeline import annotate_log
from cldet.types import ClassEstimate, Cluster, Estimate, LidarFrame, Source
from cldet.view import (
    MIN_BOX_HALF_M,
    NOISE_CLASS,
    RerunView,
    camera_for,
    drone_type_text,
    min_half_sizes,
)


@pytest.fixture(scope="module")
def log_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("viewers")


@pytest.fixture(scope="module")
def annotated(log_dir: Path, make_log: Callable[..., Path]) -> Path:
    """A simulated log with ground truth, annotated, with its review recording beside it."""
    log = make_log(log_dir, seed=7101)
    out = log_dir / "annotated.mcap"
    annotate_log(log, output=out)
    return out


# --- independent decoding -------------------------------------------------------------------
def _message_class(schema_name: str, data: bytes) -> Any:
    """A protobuf class from an MCAP schema's FileDescriptorSet, in a pool of its own."""
    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(data).file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


def _decoded(path: Path) -> Iterator[tuple[str, Any, dict[str, str]]]:
    """(topic, decoded message, channel metadata) of every message, via the mcap library."""
    classes: dict[int, Any] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            assert schema is not None and schema.encoding == "protobuf", channel.topic
            if schema.id not in classes:
                classes[schema.id] = _message_class(schema.name, schema.data)
            yield channel.topic, classes[schema.id].FromString(message.data), dict(channel.metadata)


def _frame_ids(msg: Any) -> Iterator[str]:
    """Every ``frame_id`` field anywhere in a decoded message."""
    for field, value in msg.ListFields():
        if field.name == "frame_id":
            yield value
        elif field.type == field.TYPE_MESSAGE:
            values = value if field.is_repeated else [value]
            for v in values:
                yield from _frame_ids(v)


def _check_one_tree(edges: list[tuple[str, str]], frames: set[str]) -> str:
    """The root of the tree ``edges`` (parent, child) holding ``frames``; fails otherwise."""
    parent: dict[str, str] = {}
    for p, c in edges:
        assert parent.get(c, p) == p, f"{c} has two parents"
        parent[c] = p
    roots = set()
    for frame in frames | set(parent) | set(parent.values()):
        seen = set()
        while frame in parent:
            assert frame not in seen, f"cycle through {frame}"
            seen.add(frame)
            frame = parent[frame]
        roots.add(frame)
    assert len(roots) == 1, f"unconnected trees rooted at {sorted(roots)}"
    return roots.pop()


def _tree_of(path: Path) -> tuple[list[tuple[str, str]], set[str], dict[str, int]]:
    edges: list[tuple[str, str]] = []
    frames: set[str] = set()
    tf_messages: dict[str, int] = {}
    for topic, msg, _ in _decoded(path):
        frames.update(_frame_ids(msg))
        if msg.DESCRIPTOR.full_name == "foxglove.FrameTransforms":
            tf_messages[topic] = tf_messages.get(topic, 0) + 1
            edges.extend((t.parent_frame_id, t.child_frame_id) for t in msg.transforms)
    return edges, frames, tf_messages


def test_every_message_decodes_and_all_frame_ids_form_one_tree(annotated: Path) -> None:
    edges, frames, tf_messages = _tree_of(annotated)
    assert tf_messages == {topics.TF: 1}  # written by convert, kept by annotate
    assert {topics.FRAME_MID360, topics.FRAME_RADAR} <= frames
    assert _check_one_tree(edges, frames) == topics.FRAME_WORLD


def test_the_tree_starts_the_log_and_places_the_sensor_above_the_ground(annotated: Path) -> None:
    with open(annotated, "rb") as f:
        reader = make_reader(f)
        first = min(m.log_time for _, _, m in reader.iter_messages())
    with open(annotated, "rb") as f:
        (tf,) = [m for _, c, m in make_reader(f).iter_messages(topics=[topics.TF])]
    assert tf.log_time == first
    (world,) = [t for t in sensor_tree() if t.parent == topics.FRAME_WORLD]
    assert world.matrix[2, 3] == pytest.approx(1.0)  # the configured default height


def test_estimate_schema_has_no_json_names(annotated: Path) -> None:
    with open(annotated, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    (schema,) = [s for s in summary.schemas.values() if s.name == topics.SCHEMA_ESTIMATE]
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    fields = [f for file in fds.file for m in file.message_type for f in m.field]
    # protobufjs shows a field by its json_name: it must be the field's own name, or absent
    assert any(f.name == "n_points" for f in fields)
    assert not [f.name for f in fields if f.HasField("json_name") and f.json_name != f.name]


def _bare_log(path: Path, n: int = 30) -> Path:
    """A log without /tf: Mid-360 clouds with a small object moving in front, radar clouds."""
    rng = np.random.default_rng(3)
    wall = np.column_stack(
        [np.full(400, 12.0), rng.uniform(-6, 6, 400), rng.uniform(-1, 4, 400)]
    ).astype(np.float32)
    with open(path, "wb") as f, LogWriter(f) as writer:
        for i in range(n):
            stamp = 1_700_000_000_000_000_000 + i * 100_000_000
            drone = np.array([4.0, -2.0 + 0.1 * i, 2.0]) + rng.normal(0, 0.05, (12, 3))
            cloud = np.vstack([wall, drone.astype(np.float32)])
            writer.write_cloud(topics.LIDAR_360, stamp, cloud, topics.FRAME_MID360)
            writer.write_cloud(topics.RADAR, stamp + 1, np.zeros((0, 3)), topics.FRAME_RADAR)
    return path


def test_annotate_adds_a_tree_to_a_log_without_one_and_replaces_it_next_time(
    tmp_path: Path,
) -> None:
    log = _bare_log(tmp_path / "bare.mcap")
    annotate_log(log, write_rrd=False)
    edges, frames, tf_messages = _tree_of(log)
    assert tf_messages == {topics.TF: 1}
    assert _check_one_tree(edges, frames) == topics.FRAME_WORLD
    tf_meta = [meta for topic, _, meta in _decoded(log) if topic == topics.TF]
    assert tf_meta == [{topics.RESULT_CHANNEL_KEY: "annotate"}]
    annotate_log(log, write_rrd=False)  # the second run replaces the first one's tree
    assert _tree_of(log)[2] == {topics.TF: 1}


def test_tree_problem_names_unconnected_frames() -> None:
    assert tree_problem(sensor_tree(), [topics.FRAME_MID360, topics.FRAME_CAMERA]) is None
    problem = tree_problem(sensor_tree(), ["livox_frame"])
    assert problem is not None and "2 unconnected trees" in problem


# --- Rerun's own MCAP import --------------------------------------------------------------------
def _rerun() -> str:
    rerun = shutil.which("rerun")
    if rerun is None:
        pytest.skip("the rerun CLI is not on PATH (pip install rerun-sdk)")
    return rerun


def test_rerun_mcap_convert_draws_the_estimate_trajectory_and_truth(
    annotated: Path, tmp_path: Path
) -> None:
    import rerun as rr

    rrd = tmp_path / "log.rrd"
    done = subprocess.run(
        [_rerun(), "mcap", "convert", str(annotated), "-o", str(rrd)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    drawn: dict[str, set[str]] = {}
    for column in rr.chunk.RrdReader(rrd).store().schema():
        name = str(getattr(column, "component", ""))
        if name.split(":")[0] in ("Points3D", "LineStrips3D", "Boxes3D"):
            drawn.setdefault(str(column.entity_path), set()).add(name)
    for topic in (topics.DRONE, topics.TRACK, topics.TRUTH_TRACK, topics.CENTROIDS):
        assert "Points3D:positions" in drawn.get(topic, set()), (topic, drawn)
        assert "Points3D:colors" in drawn[topic], topic
    # the Foxglove-only channels are still there, and are not what Rerun draws
    assert topics.POSE not in drawn and topics.CLUSTERS not in drawn


# --- the review recording -----------------------------------------------------------------------
def test_review_camera_looks_at_the_track_not_at_far_outliers() -> None:
    track = np.column_stack([np.linspace(3, 5, 50), np.zeros(50), np.full(50, 2.0)])
    track[-2:] = [[400.0, 0.0, 50.0], [350.0, 10.0, 80.0]]  # two wild estimates
    eye, target = camera_for(track)
    assert np.linalg.norm(target - [4.0, 0.0, 2.0]) < 0.5
    assert 5.9 < np.linalg.norm(eye - target) < 15.0
    assert eye[2] > target[2]  # from above


def test_boxes_have_a_minimum_size() -> None:
    point = np.array([1.0, 2.0, 3.0])
    np.testing.assert_array_equal(min_half_sizes(point, point), [MIN_BOX_HALF_M] * 3)
    np.testing.assert_allclose(min_half_sizes(point, point + [2.0, 0.0, 0.0]), [1.0, 0.1, 0.1])


def test_drone_type_text_is_shown_only_when_the_results_carry_a_class() -> None:
    plain = SequenceEstimate(estimates=(), chosen={}, events=())
    assert drone_type_text(plain) is None
    classes = (
        ClassEstimate(1, 0, (0, 1, 2, 3), (0.4, 0.3, 0.2, 0.1)),
        ClassEstimate(2, 2, (0, 1, 2, 3), (0.1, 0.1, 0.7, 0.1)),  # the final one
    )
    with_class = SequenceEstimate(estimates=(), chosen={}, events=(), classes=classes)
    assert drone_type_text(with_class) == "drone type 2 (p = 0.70)"


def _entity_paths(rrd: Path) -> set[str]:
    import rerun as rr

    return {str(p) for p in rr.chunk.RrdReader(rrd).store().schema().entity_paths()}


def test_review_without_truth_has_no_error_panel_data_and_noise_is_its_own_class(
    tmp_path: Path,
) -> None:
    import rerun as rr

    rrd = tmp_path / "r.rrd"
    view = RerunView(rrd, recording_name="t", application_id="cldet-test", max_range_m=50.0)
    stamp = 1_700_000_000_000_000_000
    frame = LidarFrame(
        stamp_ns=stamp,
        mid360=np.array([[1.0, 0, 0], [300.0, 0, 0]], np.float32),  # one far outlier
        avia=np.zeros((0, 3), np.float32),
    )
    cluster = Cluster(0, np.array([2.0, 0, 1]), np.array([2.0, 0, 1]), np.array([2.0, 0, 1]), 1)
    det = FrameDetections(
        stamp_ns=stamp,
        foreground=np.array([[2.0, 0, 1], [5.0, 5, 5]], np.float32),
        labels=np.array([0, -1], np.int32),
        clusters=(cluster,),
    )
    view.log_frame(frame, det)
    est = Estimate(stamp, np.array([2.0, 0, 1]), Source.DETECTED, 1, 0.1)
    view.log_result(SequenceEstimate(estimates=(est,), chosen={stamp: 0}, events=()), [det])
    assert view.close() == rrd
    paths = _entity_paths(rrd)
    assert "/world/drone/estimate" in paths and "/world/drone/chosen" in paths
    assert not any(p.startswith("/plots") or p.startswith("/drone/type") for p in paths)
    classes: list[int] = []
    mid360: list[np.ndarray] = []
    for chunk in rr.chunk.RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        path = str(chunk.entity_path)
        for name in batch.schema.names:
            if path == "/world/foreground" and name.endswith("Points3D:class_ids"):
                classes += [v for row in batch.column(name).to_pylist() if row for v in row]
            if path == "/world/lidar/mid360" and name.endswith("Points3D:positions"):
                mid360 += [np.array(row) for row in batch.column(name).to_pylist() if row]
    assert sorted(classes) == [0, NOISE_CLASS]
    assert len(mid360) == 1 and len(mid360[0]) == 1  # the point at 300 m is not logged


# --- the real viewer, headless ---------------------------------------------------------------
def _screenshot_tools() -> None:
    from cldet.screenshot import missing_tools

    missing = missing_tools()
    if missing:
        pytest.skip(
            f"{', '.join(missing)} not found: the real-viewer screenshots need Debian's xvfb and "
            "mesa-vulkan-drivers (.ci/run installs them) and the rerun CLI"
        )


@pytest.mark.slow
def test_the_real_viewer_draws_the_review_and_the_annotated_log(
    annotated: Path, tmp_path: Path
) -> None:
    from cldet.screenshot import scene_fill, screenshot

    _screenshot_tools()
    bare = _bare_log(tmp_path / "bare.mcap")
    before = scene_fill(screenshot(bare, tmp_path / "bare-before.png"))
    annotate_log(bare, write_rrd=False)
    after = scene_fill(screenshot(bare, tmp_path / "bare-after.png"))
    review = scene_fill(screenshot(annotated.with_suffix(".rrd"), tmp_path / "review.png"))
    log = scene_fill(screenshot(annotated, tmp_path / "log.png"))
    # without a frame tree Rerun's 3D view of a log stays empty (only the faint grid)
    assert before < 0.002, before
    assert after > 0.003 and review > 0.003 and log > 0.003, (after, review, log)
