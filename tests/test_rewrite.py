"""Rewriting a log with result channels: sources byte-identical, results replaced, atomic."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Channel, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.summary import Summary
from mcap.writer import IndexType, Writer

from cldet.errors import LogError
from cldet.io import topics
from cldet.io.mcap_write import LogWriter
from cldet.io.rewrite import rewrite_log


def _messages(path: Path) -> list[tuple[str, int, int, bytes]]:
    with open(path, "rb") as f:
        return [
            (channel.topic, message.log_time, message.publish_time, message.data)
            for _, channel, message in make_reader(f).iter_messages(log_time_order=True)
        ]


def _metadata(path: Path) -> dict[str, dict[str, str]]:
    with open(path, "rb") as f:
        return {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}


@pytest.fixture()
def log(tmp_path: Path) -> Path:
    path = tmp_path / "seq0001.mcap"
    rng = np.random.default_rng(1)
    with open(path, "wb") as f, LogWriter(f) as writer:
        for i in range(20):
            stamp = 1_706_255_621_600_227_000 + i * 100_000_000
            writer.write_cloud(
                topics.LIDAR_360, stamp, rng.normal(size=(50, 3)), topics.FRAME_MID360
            )
            writer.write_pose(
                topics.GROUND_TRUTH, stamp + 5_000_000, rng.normal(size=3), topics.FRAME_MID360
            )
        writer.write_metadata(topics.METADATA_SOURCE, {"sequence": "seq0001"})
    return path


def _pose_additions(stamps: list[int], offset: float) -> list:
    return [
        (
            s,
            lambda w, s=s: w.write_pose(topics.POSE, s, [offset, 0.0, 0.0], topics.FRAME_MID360),
        )
        for s in stamps
    ]


def test_rewrite_copies_sources_byte_for_byte_and_adds_results_in_time_order(
    log: Path, tmp_path: Path
) -> None:
    before = _messages(log)
    stamps = [m[1] for m in before if m[0] == topics.LIDAR_360]
    out = tmp_path / "out.mcap"
    stats = rewrite_log(
        log, out, _pose_additions(stamps[::-1], 1.0), metadata={"cldet.config": {"method": "x"}}
    )
    after = _messages(out)
    assert [m for m in after if not m[0].startswith("/cldet/")] == before
    results = [m for m in after if m[0] == topics.POSE]
    assert [m[1] for m in results] == stamps  # sorted by time although given reversed
    assert all(m[1] == m[2] for m in results)
    assert [m[1] for m in after] == sorted(m[1] for m in after)
    assert stats.copied_messages == len(before) and stats.added_messages == len(stamps)
    assert _metadata(out) == {
        topics.METADATA_SOURCE: {"sequence": "seq0001"},
        "cldet.config": {"method": "x"},
    }
    assert _messages(log) == before  # the input is untouched


def test_rewriting_twice_in_place_replaces_earlier_results(log: Path) -> None:
    stamps = [m[1] for m in _messages(log) if m[0] == topics.LIDAR_360]
    rewrite_log(log, log, _pose_additions(stamps, 1.0), metadata={"cldet.config": {"run": "1"}})
    stats = rewrite_log(
        log,
        log,
        _pose_additions(stamps[:5], 2.0),
        metadata={"cldet.config": {"run": "2"}},
        replace_metadata=["cldet.config"],
    )
    assert stats.dropped_messages == len(stamps)
    results = [m for m in _messages(log) if m[0] == topics.POSE]
    assert len(results) == 5
    assert _metadata(log)["cldet.config"] == {"run": "2"}
    assert not list(log.parent.glob(".*tmp*"))


def _summary(path: Path) -> Summary:
    with open(path, "rb") as f:
        summary = make_reader(f, validate_crcs=True).get_summary()
    assert summary is not None
    return summary


def _data_end(path: Path) -> int:
    """Offset of the log's DataEnd record (where its data section ends)."""
    with open(path, "rb") as f:
        f.seek(-37, 2)  # footer record (29 bytes) and magic (8)
        footer = f.read(29)
    assert footer[0] == 0x02
    return int.from_bytes(footer[9:17], "little") - 13  # DataEnd: opcode, length, crc


def test_results_are_appended_after_a_verbatim_copy_of_the_data_section(log: Path) -> None:
    """Sources are not decoded or recompressed: the output starts with the source's bytes."""
    source = log.read_bytes()
    data_end = _data_end(log)
    stamps = [m[1] for m in _messages(log) if m[0] == topics.LIDAR_360]
    out = log.with_name("out.mcap")
    rewrite_log(log, out, _pose_additions(stamps, 1.0), metadata={"cldet.config": {"run": "1"}})
    assert out.read_bytes()[:data_end] == source[:data_end]
    first = _summary(out)
    assert first.statistics is not None
    counts = {
        first.channels[c].topic: n for c, n in first.statistics.channel_message_counts.items()
    }
    assert counts == {topics.LIDAR_360: 20, topics.GROUND_TRUTH: 20, topics.POSE: 20}
    assert first.statistics.message_count == 60
    assert first.statistics.chunk_count == len(first.chunk_indexes)

    # again, in place: the earlier results are cut off, the sources still copied verbatim
    rewrite_log(
        out,
        out,
        _pose_additions(stamps[:3], 2.0),
        metadata={"cldet.config": {"run": "2"}},
        replace_metadata=["cldet.config"],
    )
    assert out.read_bytes()[:data_end] == source[:data_end]
    second = _summary(out)
    assert second.statistics is not None
    assert second.statistics.message_count == 43
    assert [m for m in _messages(out) if m[0] == topics.POSE][-1][1] == stamps[2]
    assert _metadata(out)["cldet.config"] == {"run": "2"}
    assert len(second.metadata_indexes) == 2  # the source's and the new cldet.config


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_appended_chunks_use_the_source_compression(compression: str, tmp_path: Path) -> None:
    path = tmp_path / "log.mcap"
    with open(path, "wb") as f, LogWriter(f, compression=compression) as writer:
        for i in range(5):
            writer.write_cloud(topics.LIDAR_360, 1_000 + i, np.ones((3, 3)), topics.FRAME_MID360)
    rewrite_log(path, path, _pose_additions([1_000, 1_004], 1.0))
    rewrite_log(path, path, [])  # no additions: the earlier results are only cut off
    summary = _summary(path)
    expected = "" if compression == "none" else compression
    assert {c.compression for c in summary.chunk_indexes} == {expected}
    assert [m[0] for m in _messages(path)] == [topics.LIDAR_360] * 5


def test_a_log_with_results_among_the_sources_is_rewritten_then_appended_to(
    tmp_path: Path,
) -> None:
    """Results interleaved with the sources (another tool): a full copy first, then appends."""
    path = tmp_path / "mixed.mcap"
    with open(path, "wb") as f, LogWriter(f) as writer:
        for i in range(10):
            stamp = 1_706_255_621_600_227_000 + i * 100_000_000
            writer.write_cloud(topics.LIDAR_360, stamp, np.ones((5, 3)), topics.FRAME_MID360)
            writer.write_pose(topics.POSE, stamp, [9.0, 9.0, 9.0], topics.FRAME_MID360)
    sources = [m for m in _messages(path) if m[0] == topics.LIDAR_360]
    stamps = [m[1] for m in sources]
    stats = rewrite_log(path, path, _pose_additions(stamps, 1.0))
    assert stats.dropped_messages == 10 and stats.copied_messages == 10
    after = _messages(path)
    assert [m for m in after if m[0] == topics.LIDAR_360] == sources
    assert [m[1] for m in after if m[0] == topics.POSE] == stamps
    assert not list(tmp_path.glob(".*"))  # neither the temporary file nor the clean copy
    summary = _summary(path)
    pose = next(c for c, ch in summary.channels.items() if ch.topic == topics.POSE)
    cut = min(
        c.chunk_start_offset for c in summary.chunk_indexes if pose in c.message_index_offsets
    )
    clean = path.read_bytes()[:cut]  # the clean copy of the sources
    rewrite_log(path, path, _pose_additions(stamps, 2.0))
    assert path.read_bytes()[:cut] == clean
    assert [m[1] for m in _messages(path) if m[0] == topics.POSE] == stamps


def test_failure_midway_leaves_the_input_intact_and_no_temporary_file(log: Path) -> None:
    original = log.read_bytes()

    def explode(writer: LogWriter) -> None:
        raise RuntimeError("boom")

    additions = [
        *_pose_additions([1_706_255_621_600_227_000], 1.0),
        (1_706_255_622_600_227_000, explode),
    ]
    with pytest.raises(RuntimeError, match="boom"):
        rewrite_log(log, log, additions)
    assert log.read_bytes() == original
    assert sorted(p.name for p in log.parent.iterdir()) == ["seq0001.mcap"]


def test_corrupt_source_names_the_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 40)
    with pytest.raises(LogError, match=r"bad\.mcap"):
        rewrite_log(bad, tmp_path / "out.mcap", [])
    assert not (tmp_path / "out.mcap").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.mcap"]


# --- logs written by other tools ------------------------------------------------------------
def _foreign_log(path: Path, **writer_options: object) -> Path:
    """Ten /lidar messages and an up-front /cldet/old channel that never publishes."""
    with open(path, "wb") as f:
        writer = Writer(f, **writer_options)  # type: ignore[arg-type]
        writer.start()
        lidar = writer.register_channel(
            "/lidar", "protobuf", writer.register_schema("a.Lidar", "protobuf", b"x")
        )
        writer.register_channel(
            "/cldet/old", "protobuf", writer.register_schema("b.Old", "protobuf", b"yy")
        )
        for i in range(10):
            stamp = 1_000_000_000 + i * 100_000_000
            writer.add_message(lidar, stamp, b"d" * 10, stamp)
        writer.add_metadata("cldet.config", {"old": "1"})
        writer.finish()
    return path


def _records(path: Path) -> list[object]:
    with open(path, "rb") as f:
        return list(StreamReader(f, validate_crcs=True).records)


def test_new_ids_stay_clear_of_a_replaced_channel_that_never_published(tmp_path: Path) -> None:
    log = _foreign_log(tmp_path / "upfront.mcap")
    out = tmp_path / "out.mcap"
    rewrite_log(log, out, _pose_additions([3_000_000_000], 1.0), replace_metadata=["cldet.config"])
    records = _records(out)
    for kind in (Schema, Channel):
        by_id: dict[int, object] = {}
        for r in records:
            if isinstance(r, kind):
                assert by_id.setdefault(r.id, r) == r, f"two different {kind.__name__}s, id {r.id}"
    assert [m[0] for m in _messages(out)] == ["/lidar"] * 10 + [topics.POSE]


@pytest.mark.parametrize(
    "options",
    [
        {"use_chunking": False},  # every message outside chunks
        {"index_types": IndexType.ALL & ~IndexType.METADATA},  # metadata without an index
        {"index_types": IndexType.ALL & ~IndexType.MESSAGE},  # chunks without message indexes
    ],
)
def test_unusual_layouts_are_copied_whole_then_appended_to(
    options: dict[str, object], tmp_path: Path
) -> None:
    log = _foreign_log(tmp_path / "foreign.mcap", **options)
    out = tmp_path / "out.mcap"
    stats = rewrite_log(
        log,
        out,
        _pose_additions([3_000_000_000], 1.0),
        metadata={"cldet.config": {"new": "1"}},
        replace_metadata=["cldet.config"],
    )
    assert stats.copied_messages == 10
    assert [m[0] for m in _messages(out)] == ["/lidar"] * 10 + [topics.POSE]
    assert [r.metadata for r in _records(out) if isinstance(r, Metadata)] == [{"new": "1"}]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["foreign.mcap", "out.mcap"]


def test_a_log_without_messages_is_appended_to(tmp_path: Path) -> None:
    log = tmp_path / "empty.mcap"
    with open(log, "wb") as f, LogWriter(f) as writer:
        writer.write_metadata(topics.METADATA_SOURCE, {"sequence": "seq0001"})
    source, end = log.read_bytes(), _data_end(log)
    rewrite_log(log, log, _pose_additions([5], 1.0))
    assert [m[0] for m in _messages(log)] == [topics.POSE]
    assert log.read_bytes()[:end] == source[:end]  # appended to, not rewritten
    assert _metadata(log) == {topics.METADATA_SOURCE: {"sequence": "seq0001"}}
