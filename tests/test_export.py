"""Tests of cldet.export and ``cldet export``: submission rows from small annotated logs."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import cldet.cli  # noqa: F401  (registers the commands)
from cldet.commands._app import app
from cldet.errors import LogError, OutputExistsError, ResultsError
from cldet.export import FALLBACK_POSITION_M, export_results, read_log_track
from cldet.io import LogWriter, topics
from cldet.results import read_log_truth, read_results
from cldet.types import Estimate, Source

T0 = 1_713_163_000_000_000_000  # test-split epoch, ns
V = np.array([2.0, -1.0, 0.5])  # m/s
P0 = np.array([1.0, -9.0, 30.0])  # m, at T0


def line(stamps_ns: Sequence[int] | np.ndarray) -> np.ndarray:
    """The known straight-line flight: P0 + V * (t - T0)."""
    t = (np.asarray(stamps_ns, dtype=np.int64) - T0).astype(np.float64) / 1e9
    return P0 + t[:, None] * V


def make_log(
    path: Path,
    sequence: str,
    *,
    estimates: Sequence[tuple[int, np.ndarray, Source]] = (),
    truth: Sequence[tuple[int, np.ndarray]] = (),
    classes: Sequence[tuple[int, int]] = (),
    metadata: bool = True,
) -> Path:
    """Write a small annotated log: cldet.source metadata, estimates, ground truth, classes."""
    with open(path, "wb") as stream, LogWriter(stream) as writer:
        if metadata:
            writer.write_metadata(topics.METADATA_SOURCE, {"split": "test", "sequence": sequence})
        for stamp, position, source in estimates:
            est = Estimate(stamp, np.asarray(position, float), source, 5, 0.1)
            writer.write_estimate(topics.ESTIMATE, stamp, est)
        for stamp, position in truth:
            writer.write_pose(topics.GROUND_TRUTH, stamp, position, topics.FRAME_MID360)
        for stamp, class_id in classes:
            writer.write_class(topics.CLASS, stamp, class_id)
    return path


def line_estimates(start_s: float, end_s: float) -> list[tuple[int, np.ndarray, Source]]:
    stamps = T0 + np.arange(round(start_s * 10), round(end_s * 10) + 1, dtype=np.int64) * 10**8
    return [(int(s), p, Source.SMOOTHED) for s, p in zip(stamps, line(stamps), strict=True)]


@pytest.fixture
def logs(tmp_path: Path) -> list[Path]:
    """seq0001 with estimates on the line from T0+1 s to T0+3 s; seq0002 without any estimate."""
    truth = [(T0 + k * 50_000_000, line([T0 + k * 50_000_000])[0]) for k in range(20, 61)]
    return [
        make_log(
            tmp_path / "seq0001.mcap", "seq0001", estimates=line_estimates(1.0, 3.0), truth=truth
        ),  # fmt: skip
        make_log(tmp_path / "seq0002.mcap", "seq0002", truth=[(T0, np.zeros(3))]),
    ]


QUERY = (
    "Sequence,Timestamp,Position,Classification\n"
    "seq1,1713163000.2,,\n"  # 0.8 s before the first estimate
    "seq0002,1713163001.000000,,\n"  # no estimate in its log
    "seq1,1713163001.550000,,\n"  # between two estimates
    "seq1,1713163002.000000,,\n"  # on an estimate
    "seq0003,1713163001.000000,,\n"  # no log at all
    "seq1,1713163004.500001,,\n"  # 1.5 s after the last estimate
    "seq0002,1713163000.000001,,\n"
)


def test_export_rows_match_the_query_file(tmp_path: Path, logs: list[Path]) -> None:
    query = tmp_path / "test_timestamps.csv"
    query.write_text(QUERY)
    out = tmp_path / "mmaud_results.csv"

    report = export_results(logs, out, query, allow_fallback=True, max_extrapolation_ns=None)

    rows = read_results(out)
    assert [(r.sequence, r.timestamp) for r in rows] == [
        ("seq1", "1713163000.2"),
        ("seq0002", "1713163001.000000"),
        ("seq1", "1713163001.550000"),
        ("seq1", "1713163002.000000"),
        ("seq0003", "1713163001.000000"),
        ("seq1", "1713163004.500001"),
        ("seq0002", "1713163000.000001"),
    ]
    got = np.array([r.position for r in rows])
    on_line = [0, 2, 3, 5]
    np.testing.assert_allclose(got[on_line], line([rows[i].stamp_ns for i in on_line]), atol=1e-6)
    np.testing.assert_allclose(got[0], [1.4, -9.2, 30.1], atol=1e-6)  # extrapolated back
    np.testing.assert_allclose(got[5], [10.000002, -13.500001, 32.2500005], atol=1e-6)
    for i in (1, 4, 6):
        assert rows[i].position == FALLBACK_POSITION_M
    assert {r.class_id for r in rows} == {0}
    assert (
        out.read_text().splitlines()[1] == 'seq1,1713163000.2,"[1.400000, -9.200000, 30.100000]",0'
    )

    assert report.n_rows == 7
    assert report.n_sequences == 3
    assert report.n_interpolated == 2
    assert report.n_extrapolated == 2
    assert report.n_fallback_rows == 3
    assert report.fallback_sequences == ("seq0002", "seq0003")
    assert any("seq0002: no estimate in" in w for w in report.warnings)
    assert any("seq0003: no log" in w and "1 rows" in w for w in report.warnings)


def test_fallback_estimates_are_bridged_by_the_track(tmp_path: Path) -> None:
    fallback = [(T0 + k * 10**8, np.array(FALLBACK_POSITION_M), Source.FALLBACK) for k in range(10)]
    log = make_log(tmp_path / "a.mcap", "seq0007", estimates=fallback + line_estimates(1.0, 2.0))
    track = read_log_track(log)
    assert track.n_fallback_dropped == 10
    assert track.stamps_ns[0] == T0 + 10**9
    query = tmp_path / "q.csv"
    query.write_text("Sequence,Timestamp,Position,Classification\nseq0007,1713163000.500000,,\n")
    report = export_results([log], tmp_path / "r.csv", query, class_id=3)
    row = read_results(tmp_path / "r.csv")[0]
    np.testing.assert_allclose(row.position, line([T0 + 5 * 10**8])[0], atol=1e-6)
    assert row.class_id == 3
    assert report.n_extrapolated == 1
    assert any("ignored 10 FALLBACK" in w for w in report.warnings)


def test_export_without_timestamps_uses_ground_truth_stamps(
    tmp_path: Path, logs: list[Path]
) -> None:
    out = tmp_path / "r.csv"
    report = export_results(logs, out, allow_fallback=True)
    rows = read_results(out)
    assert len(rows) == 41 + 1
    assert rows[0].timestamp == "1713163001.000000"
    assert rows[0].sequence == "seq0001"
    np.testing.assert_allclose(
        [r.position for r in rows[:41]], line([r.stamp_ns for r in rows[:41]]), atol=1e-6
    )
    assert rows[-1].position == FALLBACK_POSITION_M
    assert report.fallback_sequences == ("seq0002",)


def test_read_log_truth_attaches_classes(tmp_path: Path) -> None:
    log = make_log(
        tmp_path / "t.mcap",
        "seq0005",
        truth=[(T0 + k * 10**8, np.array([k, 0.0, 1.0])) for k in range(3)],
        classes=[(T0 + 10**8, 2), (T0 + 2 * 10**8, 1)],
    )
    rows = read_log_truth(log)
    assert [(r.sequence, r.timestamp, r.position, r.class_id) for r in rows] == [
        ("seq0005", "1713163000.000000", (0.0, 0.0, 1.0), 2),  # before the first label
        ("seq0005", "1713163000.100000", (1.0, 0.0, 1.0), 2),
        ("seq0005", "1713163000.200000", (2.0, 0.0, 1.0), 1),
    ]


def test_log_without_ground_truth(tmp_path: Path) -> None:
    log = make_log(tmp_path / "e.mcap", "seq0009", estimates=line_estimates(0.0, 1.0))
    with pytest.raises(LogError, match=r"e\.mcap: no /ground_truth messages \(sequence seq0009\)"):
        read_log_truth(log)


def test_two_logs_of_one_sequence(tmp_path: Path) -> None:
    a = make_log(tmp_path / "a.mcap", "seq1")
    b = make_log(tmp_path / "b.mcap", "seq0001")
    with pytest.raises(ResultsError, match=r"two logs hold sequence seq0001.*a\.mcap.*b\.mcap"):
        export_results([a, b], tmp_path / "r.csv")


def test_log_without_metadata(tmp_path: Path) -> None:
    log = make_log(tmp_path / "n.mcap", "", metadata=False)
    with pytest.raises(LogError, match=r"n\.mcap: no sequence name in its 'cldet.source'"):
        export_results([log], tmp_path / "r.csv")


def test_no_rows_at_all(tmp_path: Path) -> None:
    log = make_log(tmp_path / "e.mcap", "seq0009", estimates=line_estimates(0.0, 1.0))
    with pytest.raises(ResultsError, match="nothing to export"):
        export_results([log], tmp_path / "r.csv")
    assert not (tmp_path / "r.csv").exists()


def test_existing_output_is_kept(tmp_path: Path, logs: list[Path]) -> None:
    out = tmp_path / "r.csv"
    out.write_text("keep me")
    with pytest.raises(OutputExistsError, match="already exists"):
        export_results(logs, out)
    assert out.read_text() == "keep me"


def test_cli_export(tmp_path: Path, logs: list[Path]) -> None:
    query = tmp_path / "test_timestamps.csv"
    query.write_text(QUERY)
    out = tmp_path / "mmaud_results.csv"
    runner = CliRunner()
    args = ["export", *map(str, logs), "-t", str(query), "-o", str(out), "--class-id", "2"]
    refused = runner.invoke(app, args)
    assert refused.exit_code == 1 and not out.exists()
    assert "ERROR: no estimate for 2 query sequence(s)" in refused.stderr
    args.append("--allow-fallback")
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "7 rows in 3 sequences" in result.stdout
    assert "2 extrapolated" in result.stdout
    assert "WARNING: sequence seq0003: no log" in result.stderr
    assert {r.class_id for r in read_results(out)} == {2}

    again = runner.invoke(app, args)
    assert again.exit_code == 1
    assert "ERROR:" in again.stderr and "already exists" in again.stderr
    assert runner.invoke(app, [*args, "--overwrite"]).exit_code == 0


def test_cli_export_bad_query(tmp_path: Path, logs: list[Path]) -> None:
    query = tmp_path / "q.csv"
    query.write_text("Sequence,Timestamp\nseq1,noon\n")
    result = CliRunner().invoke(app, ["export", str(logs[0]), "-t", str(query), "-o", "x.csv"])
    assert result.exit_code == 1
    assert "ERROR: the query file (--timestamps) is not usable:" in result.stderr
    assert "q.csv:2: bad Timestamp 'noon'" in result.stderr


def test_every_row_at_the_fallback_is_flagged(tmp_path: Path) -> None:
    log = make_log(tmp_path / "raw.mcap", "seq0001", truth=[(T0, np.zeros(3))])
    report = export_results([log], tmp_path / "r.csv", allow_fallback=True)
    assert report.n_fallback_rows == report.n_rows == 1
    assert any("were the logs annotated" in w for w in report.warnings)


def test_cli_max_extrapolation(tmp_path: Path, logs: list[Path]) -> None:
    query = tmp_path / "q.csv"
    query.write_text("Sequence,Timestamp,Position,Classification\nseq0001,1713163004.500000,,\n")
    out = tmp_path / "r.csv"
    args = ["export", str(logs[0]), "-t", str(query), "-o", str(out)]
    result = CliRunner().invoke(app, [*args, "--max-extrapolation-s", "0.5"])
    assert result.exit_code == 0, result.output
    held = line([T0 + 3_500_000_000])[0]  # 0.5 s past the last estimate (T0 + 3 s), then held
    np.testing.assert_allclose(read_results(out)[0].position, held, atol=1e-6)


def test_a_log_never_annotated_or_missing_is_an_error(tmp_path: Path, logs: list[Path]) -> None:
    query = tmp_path / "q.csv"
    query.write_text(QUERY)
    out = tmp_path / "r.csv"
    with pytest.raises(
        ResultsError,
        match=(
            r"no estimate for 2 query sequence\(s\): seq0002 \(2 rows\): .*seq0002\.mcap was "
            r"never annotated \(no /cldet/estimate\); seq0003 \(1 rows\) has no log among those "
            r"given; annotate their logs \(`cldet annotate`\), or pass allow_fallback "
            r"\(--allow-fallback\)"
        ),
    ):
        export_results(logs, out, query)
    assert not out.exists()


def test_extrapolation_is_capped_by_default(tmp_path: Path, logs: list[Path]) -> None:
    query = tmp_path / "q.csv"
    query.write_text("Sequence,Timestamp,Position,Classification\nseq0001,1713163073.000000,,\n")
    export_results(logs[:1], tmp_path / "r.csv", query)  # 70 s after the last estimate
    held = line([T0 + 4_000_000_000])[0]  # 1 s past the last estimate (T0 + 3 s), then held
    np.testing.assert_allclose(read_results(tmp_path / "r.csv")[0].position, held, atol=1e-6)
    result = CliRunner().invoke(
        app,
        ["export", str(logs[0]), "-t", str(query), "-o", str(tmp_path / "u.csv")]
        + ["--max-extrapolation-s", "inf"],
    )
    assert result.exit_code == 0, result.output
    far = line([T0 + 73_000_000_000])[0]  # no limit: the line followed for 70 s
    np.testing.assert_allclose(read_results(tmp_path / "u.csv")[0].position, far, atol=1e-5)


def test_nothing_to_export_names_the_timestamps_option(tmp_path: Path) -> None:
    log = make_log(tmp_path / "e.mcap", "seq0009", estimates=line_estimates(0.0, 1.0))
    with pytest.raises(ResultsError, match=r"no query file \(--timestamps\) was given"):
        export_results([log], tmp_path / "r.csv")
    empty = tmp_path / "q.csv"
    empty.write_text("Sequence,Timestamp,Position,Classification\n")
    with pytest.raises(ResultsError, match=r"--timestamps"):
        export_results([log], tmp_path / "r.csv", empty)
