"""Tests of cldet.evaluate and ``cldet evaluate`` on a small hand-computed example."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

import cldet.cli  # noqa: F401  (registers the commands)
from cldet.commands._app import app
from cldet.errors import ResultsError
from cldet.evaluate import evaluate_results, truth_from_logs, write_errors_parquet
from cldet.io import LogWriter, topics
from cldet.results import read_truth

# Five truth rows in two sequences; the results answer four of them (one twice), plus one row
# of a sequence without truth.
TRUTH = """Sequence,Timestamp,x,y,z,class
seq0001,1706255621.600227,0,0,0,1
seq0001,1706255621.700227,1,1,1,1
seq0002,1706255622.000000,10,0,0,2
seq0002,1706255622.100000,0,5,0,2
seq0002,1706255622.200000,0,0,0,2
"""
RESULTS = """Sequence,Timestamp,Position,Classification
seq1,1706255621.600227,"[1, 2, 2]",1
seq0001,1706255621.700227,"[1.0, 1.0, 1.0]",0
seq0002,1706255622.0,"[10, 0, 4]",2
seq2,1706255622.1,"[2, 1, 4]",3
seq0001,1706255621.600227,"[100, 100, 100]",1
seq0003,1706255622.000000,"[0, 0, 0]",0
"""
# Matched rows: 3D errors 3, 0, 4, 6 m (squared 9, 0, 16, 36; sum 61); classes right, wrong,
# right, wrong. The repeated seq0001 row is a duplicate (the first one is scored), seq0003 is
# unmatched, seq0002 @ .200000 is missing.
MSD = 61 / 4  # mean squared 3D distance, m^2
MSE_COORD = 61 / 12  # sum of squared coordinate errors / 3N, m^2
RMSE = math.sqrt(61 / 4)
MEDIAN = 3.5  # of 0, 3, 4, 6
P95 = 5.7  # linear: 4 + 0.85 * (6 - 4)


@pytest.fixture
def files(tmp_path: Path) -> tuple[Path, Path]:
    truth = tmp_path / "val_truth.csv"
    truth.write_text(TRUTH)
    results = tmp_path / "mmaud_results.csv"
    results.write_text(RESULTS)
    return results, truth


def test_hand_computed_example(files: tuple[Path, Path]) -> None:
    results, truth = files
    ev = evaluate_results(results, read_truth(truth))
    assert (ev.n_truth, ev.n_results, ev.n_matched) == (5, 6, 4)
    assert (ev.n_missing, ev.n_duplicate, ev.n_unmatched) == (1, 1, 1)
    assert ev.mse_per_coordinate_m2 == pytest.approx(MSE_COORD)
    assert ev.mean_squared_distance_m2 == pytest.approx(MSD)
    assert ev.rmse_m == pytest.approx(RMSE)
    assert ev.median_error_m == pytest.approx(MEDIAN)
    assert ev.p95_error_m == pytest.approx(P95)
    assert ev.max_error_m == pytest.approx(6.0)
    assert ev.accuracy == pytest.approx(0.5)
    assert ev.n_classified == 4

    s1, s2 = ev.sequences
    assert (s1.sequence, s1.n_truth, s1.n_matched, s1.n_missing) == ("seq0001", 2, 2, 0)
    assert s1.mean_squared_distance_m2 == pytest.approx(4.5)
    assert s1.mse_per_coordinate_m2 == pytest.approx(1.5)
    assert s1.rmse_m == pytest.approx(math.sqrt(4.5))
    assert s1.max_error_m == pytest.approx(3.0)
    assert s1.accuracy == pytest.approx(0.5)
    assert (s2.sequence, s2.n_truth, s2.n_matched, s2.n_missing) == ("seq0002", 3, 2, 1)
    assert s2.mean_squared_distance_m2 == pytest.approx(26.0)
    assert s2.mse_per_coordinate_m2 == pytest.approx(26 / 3)
    assert s2.accuracy == pytest.approx(0.5)

    np.testing.assert_allclose(ev.rows.error_m, [3.0, 0.0, 4.0, 6.0])
    assert ev.rows.timestamp == (
        "1706255621.600227", "1706255621.700227", "1706255622.0", "1706255622.1"
    )  # fmt: skip
    assert ev.missing_examples == (("seq0002", 1_706_255_622_200_000_000),)
    assert ev.duplicate_examples == (("seq0001", 1_706_255_621_600_227_000),)
    assert ev.unmatched_examples == (("seq0003", 1_706_255_622_000_000_000),)
    warnings = "\n".join(ev.warnings)
    assert "1 truth rows have no result (missing): seq0002@1706255622.200000" in warnings
    assert "1 result rows repeat an earlier row (duplicate" in warnings
    assert "1 result rows match no truth row (unmatched" in warnings


def test_truth_without_class_gives_no_accuracy(tmp_path: Path) -> None:
    truth = tmp_path / "t.csv"
    truth.write_text("Sequence,Timestamp,x,y,z,class\nseq1,1.0,0,0,0,\n")
    results = tmp_path / "r.csv"
    results.write_text('Sequence,Timestamp,Position,Classification\nseq1,1.0,"[0, 0, 1]",0\n')
    ev = evaluate_results(results, read_truth(truth))
    assert ev.accuracy is None and ev.n_classified == 0
    assert ev.mse_per_coordinate_m2 == pytest.approx(1 / 3)
    assert ev.warnings == ()


def test_nothing_matches(tmp_path: Path, files: tuple[Path, Path]) -> None:
    _, truth = files
    results = tmp_path / "r.csv"
    results.write_text('Sequence,Timestamp,Position,Classification\nseq9,1.0,"[0, 0, 1]",0\n')
    with pytest.raises(ResultsError, match=r"r\.csv: none of its 1 rows matches the 5 truth rows"):
        evaluate_results(results, read_truth(truth))


def test_malformed_results_are_reported(tmp_path: Path, files: tuple[Path, Path]) -> None:
    _, truth = files
    results = tmp_path / "r.csv"
    results.write_text('Sequence,Timestamp,Position,Classification\nseq1,1.0,"[0, 0]",0\n')
    with pytest.raises(ResultsError, match=r"r\.csv:2: bad Position"):
        evaluate_results(results, read_truth(truth))


def test_errors_parquet_reads_back(tmp_path: Path, files: tuple[Path, Path]) -> None:
    results, truth = files
    ev = evaluate_results(results, read_truth(truth))
    path = tmp_path / "errors.parquet"
    write_errors_parquet(ev, path)
    table = pq.read_table(path)
    assert table.column_names == [
        "sequence", "timestamp", "timestamp_ns", "est_x", "est_y", "est_z",
        "true_x", "true_y", "true_z", "error_m", "class_pred", "class_true",
    ]  # fmt: skip
    data = table.to_pydict()
    assert data["sequence"] == ["seq0001", "seq0001", "seq0002", "seq0002"]
    assert data["timestamp"][3] == "1706255622.1"
    assert data["timestamp_ns"][3] == 1_706_255_622_100_000_000
    assert data["error_m"] == pytest.approx([3.0, 0.0, 4.0, 6.0])
    assert data["est_z"] == pytest.approx([2.0, 1.0, 4.0, 4.0])
    assert data["class_pred"] == [1, 0, 2, 3]
    assert data["class_true"] == [1, 1, 2, 2]
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "errors.parquet", "mmaud_results.csv", "val_truth.csv"
    ]  # fmt: skip


def test_cli_evaluate_text(files: tuple[Path, Path]) -> None:
    results, truth = files
    result = CliRunner().invoke(app, ["evaluate", str(results), "--truth", str(truth)])
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "MSE per coordinate (sum sq err / 3N)   5.0833 m^2" in out
    assert "mean squared 3D distance (sum sq / N)  15.2500 m^2" in out
    assert "RMSE 3D" in out and "3.9051 m" in out
    assert "95th percentile 3D error" in out and "5.7000 m" in out
    assert "0.500 (4 rows with a true class)" in out
    assert "missing 1, duplicate 1, unmatched 1" in out
    seq2 = next(line for line in out.splitlines() if line.startswith("seq0002"))
    assert seq2.split() == ["seq0002", "3", "2", "1", "8.6667", "26.0000", "5.0990", "6.0000",
                            "0.500"]  # fmt: skip
    assert "WARNING: 1 truth rows have no result (missing)" in result.stderr


def test_cli_evaluate_json_and_parquet(tmp_path: Path, files: tuple[Path, Path]) -> None:
    results, truth = files
    parquet = tmp_path / "e.parquet"
    args = ["evaluate", str(results), "--truth", str(truth), "--json"]
    result = CliRunner().invoke(app, [*args, "--errors-parquet", str(parquet)])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["mse_per_coordinate_m2"] == pytest.approx(MSE_COORD)
    assert data["mean_squared_distance_m2"] == pytest.approx(MSD)
    assert data["p95_error_m"] == pytest.approx(P95)
    assert data["accuracy"] == pytest.approx(0.5)
    assert data["counts"] == {
        "truth": 5, "results": 6, "matched": 4, "missing": 1, "duplicate": 1, "unmatched": 1,
        "classified": 4,
    }  # fmt: skip
    assert [s["sequence"] for s in data["sequences"]] == ["seq0001", "seq0002"]
    assert len(data["warnings"]) == 3
    assert pq.read_table(parquet).num_rows == 4


@pytest.mark.parametrize(
    ("extra", "match"),
    [([], "give the truth either as --truth"), (["--logs"], "give the truth either as --truth")],
)
def test_cli_evaluate_needs_one_truth(
    files: tuple[Path, Path], extra: list[str], match: str
) -> None:
    results, _ = files
    result = CliRunner().invoke(app, ["evaluate", str(results), *extra])
    assert result.exit_code == 1
    assert "ERROR:" in result.stderr and match in result.stderr


def test_cli_evaluate_bad_results(tmp_path: Path, files: tuple[Path, Path]) -> None:
    _, truth = files
    bad = tmp_path / "bad.csv"
    bad.write_text("Sequence,Timestamp,Position\n")
    result = CliRunner().invoke(app, ["evaluate", str(bad), "--truth", str(truth)])
    assert result.exit_code == 1
    assert "bad.csv:1: missing column(s) Classification" in result.stderr


def make_truth_log(
    path: Path, sequence: str, rows: list[tuple[int, list[float]]], cls: int
) -> Path:
    with open(path, "wb") as stream, LogWriter(stream) as writer:
        writer.write_metadata(topics.METADATA_SOURCE, {"split": "val", "sequence": sequence})
        for stamp, position in rows:
            writer.write_pose(topics.GROUND_TRUTH, stamp, position, topics.FRAME_MID360)
            writer.write_class(topics.CLASS, stamp, cls)
    return path


def test_truth_from_logs_and_cli(tmp_path: Path, files: tuple[Path, Path]) -> None:
    results, _ = files
    a = make_truth_log(
        tmp_path / "a.mcap",
        "seq0001",
        [(1_706_255_621_600_227_000, [0, 0, 0]), (1_706_255_621_700_227_000, [1, 1, 1])],
        1,
    )
    b = make_truth_log(
        tmp_path / "b.mcap",
        "seq2",
        [
            (1_706_255_622_000_000_000, [10, 0, 0]),
            (1_706_255_622_100_000_000, [0, 5, 0]),
            (1_706_255_622_200_000_000, [0, 0, 0]),
        ],
        2,
    )
    ev = evaluate_results(results, truth_from_logs([a, b]))
    assert ev.mean_squared_distance_m2 == pytest.approx(MSD)
    assert (ev.n_missing, ev.n_duplicate, ev.n_unmatched, ev.accuracy) == (1, 1, 1, 0.5)

    result = CliRunner().invoke(app, ["evaluate", str(results), "--logs", str(a), str(b), "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["mean_squared_distance_m2"] == pytest.approx(MSD)

    dup = make_truth_log(
        tmp_path / "dup.mcap", "seq0002", [(1_706_255_622_000_000_000, [0, 0, 0])], 2
    )
    with pytest.raises(ResultsError, match=r"b\.mcap: sequence seq0002 .* is also in .*dup\.mcap"):
        truth_from_logs([dup, b])


def test_cli_evaluate_keeps_an_existing_parquet(tmp_path: Path, files: tuple[Path, Path]) -> None:
    results, truth = files
    parquet = tmp_path / "e.parquet"
    parquet.write_bytes(b"keep")
    args = ["evaluate", str(results), "--truth", str(truth), "--errors-parquet", str(parquet)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 1
    assert "e.parquet already exists: pass --overwrite" in result.stderr
    assert parquet.read_bytes() == b"keep"
    result = CliRunner().invoke(app, [*args, "--overwrite"])
    assert result.exit_code == 0, result.output
    assert f"per-row errors written to {parquet}" in result.stdout
    assert pq.read_table(parquet).num_rows == 4
