"""Tests of cldet.results: the query, results and truth CSVs (round trips and broken inputs)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cldet.errors import OutputExistsError, ResultsError
from cldet.results import (
    ResultRow,
    format_position,
    normalise_sequence,
    parse_position,
    read_results,
    read_timestamps,
    read_truth,
    write_results,
)


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("seq0001", "seq0001"),
        ("seq1", "seq0001"),
        ("SEQ12", "seq0012"),
        (" seq0102 ", "seq0102"),
        ("other", "other"),
    ],
)
def test_normalise_sequence(name: str, expected: str) -> None:
    assert normalise_sequence(name) == expected


def test_position_format_and_parse() -> None:
    assert format_position([1, -2.5, 33.3534567]) == "[1.000000, -2.500000, 33.353457]"
    assert parse_position("[1.0, -2.5, 3e1]") == (1.0, -2.5, 30.0)
    assert parse_position(" [1 2   3] ") == (1.0, 2.0, 3.0)  # numpy-style spacing


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("1, 2, 3", "square brackets"),
        ("[1, 2]", "3 numbers"),
        ("[1, a, 3]", "numbers"),
        ("[1, nan, 3]", "finite"),
        ("[1, 2, 3, 4]", "3 numbers"),
    ],
)
def test_parse_position_rejects(text: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        parse_position(text)


def test_read_timestamps_keeps_strings_and_order(tmp_path: Path) -> None:
    path = write(
        tmp_path / "test_timestamps.csv",
        "Sequence,Timestamp,Position,Classification\n"
        "seq1,1713163000.12,,\n"
        "seq0001,1713163000.000001,,\n"
        "\n"
        "seq0002,1713163005.500000,,\n",
    )
    rows = read_timestamps(path)
    assert [(r.sequence, r.timestamp, r.line) for r in rows] == [
        ("seq1", "1713163000.12", 2),
        ("seq0001", "1713163000.000001", 3),
        ("seq0002", "1713163005.500000", 5),
    ]
    assert rows[0].stamp_ns == 1_713_163_000_120_000_000
    assert rows[0].key == ("seq0001", 1_713_163_000_120_000_000)


def test_results_round_trip(tmp_path: Path) -> None:
    rows = [
        ResultRow("seq1", "1713163000.12", 1_713_163_000_120_000_000, (1.0, -2.0, 33.5), 2),
        ResultRow("seq0002", "1713163001.000000", 1_713_163_001_000_000_000, (0.1, 0.2, 0.3), 0),
    ]
    path = tmp_path / "mmaud_results.csv"
    write_results(path, rows)
    assert path.read_text() == (
        "Sequence,Timestamp,Position,Classification\n"
        'seq1,1713163000.12,"[1.000000, -2.000000, 33.500000]",2\n'
        'seq0002,1713163001.000000,"[0.100000, 0.200000, 0.300000]",0\n'
    )
    back = read_results(path)
    assert [(r.sequence, r.timestamp, r.stamp_ns, r.position, r.class_id) for r in back] == [
        (r.sequence, r.timestamp, r.stamp_ns, r.position, r.class_id) for r in rows
    ]
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_write_results_never_overwrites_by_accident(tmp_path: Path) -> None:
    path = write(tmp_path / "mmaud_results.csv", "precious\n")
    row = ResultRow("seq1", "1.0", 1_000_000_000, (0.0, 0.0, 0.0), 0)
    with pytest.raises(OutputExistsError, match="already exists"):
        write_results(path, [row])
    assert path.read_text() == "precious\n"
    write_results(path, [row], overwrite=True)
    assert path.read_text().startswith("Sequence,")


def test_write_results_rejects_nan_and_keeps_no_file(tmp_path: Path) -> None:
    path = tmp_path / "out.csv"
    with pytest.raises(ResultsError, match=r"seq1 at 1\.0.*finite"):
        write_results(path, [ResultRow("seq1", "1.0", 10**9, (float("nan"), 0.0, 0.0), 0)])
    assert list(tmp_path.iterdir()) == []


def test_read_truth(tmp_path: Path) -> None:
    path = write(
        tmp_path / "val_truth.csv",
        "Sequence,Timestamp,x,y,z,class\nseq0001,1706255621.600227,1.5,-2,30,3\n"
        "seq0001,1706255621.650227,1.6,-2,30,\n",
    )
    truth = read_truth(path)
    assert truth.source == str(path)
    assert truth.rows[0].position == (1.5, -2.0, 30.0)
    assert truth.rows[0].class_id == 3
    assert truth.rows[1].class_id is None
    assert truth.positions().shape == (2, 3)


HEADER = "Sequence,Timestamp,Position,Classification\n"


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", r"empty file: expected a results file with the header Sequence,Timestamp"),
        ("\n\n", r"empty file"),
        (
            'Sequence,Timestamp,Position\nseq1,1.0,"[1, 2, 3]"\n',
            r"results\.csv:1: missing column\(s\) Classification",
        ),
        (HEADER, r"results\.csv:1: no data rows"),
        (HEADER + 'seq1,1.0,"[1, 2]",0\n', r"results\.csv:2: bad Position '\[1, 2\]'.*3 numbers"),
        (HEADER + 'seq1,1.0,"1, 2, 3",0\n', r"results\.csv:2: bad Position.*square brackets"),
        (HEADER + 'seq1,1.0,"[1, nan, 3]",0\n', r"results\.csv:2: bad Position.*finite"),
        (HEADER + 'seq1,1.0,"[1, inf, 3]",0\n', r"results\.csv:2: bad Position.*finite"),
        (HEADER + "seq1,1.0,[1, 2, 3],0\n", r"results\.csv:2: 6 fields, expected 4.*quote"),
        (
            HEADER + 'seq1,1.0,"[1, 2, 3]",0\nseq1,2.0,"[1, 2, 3]",x\n',
            r"results\.csv:3: bad Classification 'x': expected an integer",
        ),
        (
            HEADER + 'seq1,1713163000.1234567,"[1, 2, 3]",0\n',
            r"results\.csv:2: bad Timestamp '1713163000\.1234567': expected Unix seconds",
        ),
        (HEADER + 'seq1,yesterday,"[1, 2, 3]",0\n', r"results\.csv:2: bad Timestamp 'yesterday'"),
        (HEADER + ',1.0,"[1, 2, 3]",0\n', r"results\.csv:2: empty Sequence"),
        (
            HEADER + 'seq1,1.5,"[1, 2, 3]",0\nseq0001,1.500000,"[1, 2, 3]",0\n',
            r"results\.csv:3: duplicate row for sequence seq0001 at 1\.500000 \(first on line 2\)",
        ),
    ],
)
def test_malformed_results(tmp_path: Path, text: str, match: str) -> None:
    path = write(tmp_path / "results.csv", text)
    with pytest.raises(ResultsError, match=match):
        read_results(path)


def test_results_duplicates_allowed_when_asked(tmp_path: Path) -> None:
    path = write(tmp_path / "r.csv", HEADER + 'seq1,1.5,"[1, 2, 3]",0\nseq1,1.5,"[4, 5, 6]",1\n')
    assert len(read_results(path, allow_duplicates=True)) == 2


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("Sequence,Time\nseq1,1.0\n", r"t\.csv:1: missing column\(s\) Timestamp"),
        (
            "Sequence,Timestamp,Position,Classification\nseq1,1.0.0,,\n",
            r"t\.csv:2: bad Timestamp '1\.0\.0'",
        ),
        (
            "Sequence,Timestamp,Position,Classification\nseq1,1.0,,\nseq01,1.000,,\n",
            r"t\.csv:3: duplicate row for sequence seq0001",
        ),
    ],
)
def test_malformed_timestamps(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(ResultsError, match=match):
        read_timestamps(write(tmp_path / "t.csv", text))


@pytest.mark.parametrize(
    ("body", "match"),
    [
        ("seq1,1.0,1,2,nan,0\n", r"truth\.csv:2: bad z 'nan': expected a finite number"),
        ("seq1,1.0,1,inf,3,0\n", r"truth\.csv:2: bad y 'inf': expected a finite number"),
        ("seq1,1.0,one,2,3,0\n", r"truth\.csv:2: bad x 'one': expected a number"),
        ("seq1,1.0,1,2,3,1.5\n", r"truth\.csv:2: bad class '1\.5': expected an integer"),
        ("seq1,1.0,1,2,3,0\nseq1,1.0,1,2,3,0\n", r"truth\.csv:3: duplicate row"),
    ],
)
def test_malformed_truth(tmp_path: Path, body: str, match: str) -> None:
    path = write(tmp_path / "truth.csv", "Sequence,Timestamp,x,y,z,class\n" + body)
    with pytest.raises(ResultsError, match=match):
        read_truth(path)


def test_truth_missing_column(tmp_path: Path) -> None:
    path = write(tmp_path / "truth.csv", "Sequence,Timestamp,x,y,z\nseq1,1.0,1,2,3\n")
    with pytest.raises(ResultsError, match=r"truth\.csv:1: missing column\(s\) class"):
        read_truth(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ResultsError, match=r"nope\.csv: cannot read the query file"):
        read_timestamps(tmp_path / "nope.csv")
