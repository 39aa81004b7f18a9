"""Fuzzing the two inputs users hand in: corrupted ``.npy`` frames (convert) and corrupted small
logs (annotate, export's reader). Only cldet's own errors may come out, never a traceback of
numpy, mcap or protobuf, and never a temporary file. Bounded to a few seconds each.
"""

from __future__ import annotations

import io
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from cldet.errors import CldetError
from cldet.io import LogWriter, list_topics, open_log
from cldet.io import topics as tp
from cldet.pipeline import annotate_log
from converters.mcap_convert import convert_dataset

FUZZ = settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    derandomize=True,  # CI must never be flaky: the same cases every run
)
T0 = 1_706_255_621_600_227_000


def npy_bytes(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


GOOD_NPY = npy_bytes(np.arange(30, dtype=np.float64).reshape(10, 3) + 1)


@st.composite
def corrupted(draw: st.DrawFn, good: bytes) -> bytes:
    """``good`` truncated, with bytes overwritten, or with garbage appended."""
    data = bytearray(good)
    kind = draw(st.sampled_from(["truncate", "flip", "splice", "append"]))
    if kind == "truncate":
        return bytes(data[: draw(st.integers(0, len(data) - 1))])
    if kind == "append":
        return bytes(data) + draw(st.binary(min_size=1, max_size=64))
    n = draw(st.integers(1, 8))
    for _ in range(n):
        at = draw(st.integers(0, len(data) - 1))
        if kind == "flip":
            data[at] ^= draw(st.integers(1, 255))
        else:
            chunk = draw(st.binary(min_size=1, max_size=16))
            data[at : at + len(chunk)] = chunk
    return bytes(data)


@given(bad=corrupted(GOOD_NPY))
@FUZZ
def test_corrupted_npy_frames_give_only_cldet_errors(bad: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        root, out = Path(tmp) / "data", Path(tmp) / "logs"
        for s in (1, 2):
            folder = root / "val" / f"seq{s:04d}" / "lidar_360"
            folder.mkdir(parents=True)
            for i in range(3):
                (folder / f"1706255621.{i}00000.npy").write_bytes(GOOD_NPY)
        (root / "val" / "seq0002" / "lidar_360" / "1706255621.100000.npy").write_bytes(bad)
        report = convert_dataset(root, out, workers=1)  # raises nothing but CldetError
        assert out / "val" / "seq0001.mcap" in report.converted
        for failure in report.failed:
            assert failure.sequence == "val/seq0002" and "1706255621.100000.npy" in failure.message
            assert "\n" not in failure.message
        assert not [p for p in out.rglob(".*") if ".tmp-" in p.name]


def small_log() -> bytes:
    rng = np.random.default_rng(5)
    stream = io.BytesIO()
    with LogWriter(stream) as writer:
        for i in range(6):
            stamp = T0 + i * 100_000_000
            points = rng.normal(0, 15, (60, 3)).astype(np.float32)
            writer.write_cloud(tp.LIDAR_360, stamp, points, tp.FRAME_MID360)
            writer.write_pose(tp.GROUND_TRUTH, stamp, [1.0, 2.0, 3.0], tp.FRAME_MID360)
        writer.write_metadata(tp.METADATA_SOURCE, {"sequence": "seq0001", "split": "val"})
    return stream.getvalue()


GOOD_LOG = small_log()


@given(bad=corrupted(GOOD_LOG))
@FUZZ
def test_corrupted_logs_give_only_cldet_errors(bad: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "seq0001.mcap"
        log.write_bytes(bad)
        try:
            with open_log(log) as reader:
                for topic in reader.list_topics():
                    for _ in reader.iter_messages([topic]):
                        pass
        except CldetError as err:
            assert "\n" not in str(err)
        try:
            annotate_log(log, write_rrd=False)
        except CldetError as err:
            assert str(err) and "\n" not in str(err)
            assert log.read_bytes() == bad  # never damaged
        else:  # annotated: mcap's own reader must read the whole result
            assert list_topics(log)[tp.ESTIMATE] > 0
            with open(log, "rb") as f:
                reader = make_reader(f)
                reader.get_header()
                assert sum(1 for _ in reader.iter_messages()) > 0
        assert sorted(p.name for p in Path(tmp).iterdir()) == ["seq0001.mcap"]


def test_a_log_with_a_corrupt_header_is_refused_not_copied(tmp_path: Path) -> None:
    """Annotate copies the header unparsed: a header mcap cannot read must stop it (found by the
    fuzz above; the copy was unreadable by mcap's reader and the run exited 0)."""
    from cldet.errors import LogError

    data = bytearray(GOOD_LOG)
    data[9:17] = (2**32 + 19).to_bytes(8, "little")  # the header record's length
    log = tmp_path / "badheader.mcap"
    log.write_bytes(bytes(data))
    with pytest.raises(LogError, match=r"badheader\.mcap is not a readable MCAP log .*HEADER"):
        annotate_log(log, write_rrd=False)
    assert log.read_bytes() == bytes(data)


def test_the_fuzz_inputs_are_valid_before_corruption(tmp_path: Path) -> None:
    log = tmp_path / "ok.mcap"
    log.write_bytes(GOOD_LOG)
    annotate_log(log, write_rrd=False)
    assert list_topics(log)[tp.ESTIMATE] == 6
    shutil.rmtree(tmp_path)
