"""The challenge's CSV files: query stamps, results (the submission) and ground truth.

Three formats, all with a header line:

- ``test_timestamps.csv`` (the query rows): ``Sequence,Timestamp,Position,Classification``, the
  last two empty. Read by :func:`read_timestamps`.
- ``mmaud_results.csv`` (the submission): exactly ``Sequence,Timestamp,Position,Classification``,
  one row per query row in the query file's order, ``Sequence`` and ``Timestamp`` exactly as
  given, ``Position`` the string ``"[x, y, z]"`` (metres, :data:`POSITION_DECIMALS` decimals,
  quoted because of its commas), ``Classification`` an int. Read by :func:`read_results`,
  written by :func:`write_results`.
- ``*_truth.csv`` (written by ``cldet simulate``): ``Sequence,Timestamp,x,y,z,class``. Read by
  :func:`read_truth`; the same rows come from a log's ``/ground_truth`` by
  :func:`read_log_truth`.

Rows are matched by :func:`row_key`: the normalised sequence name (``seq1`` and ``seq0001`` are
the same sequence) and the stamp in integer nanoseconds (``1713163000.12`` and
``1713163000.120000`` are the same instant). The strings themselves are kept and written back
exactly as read. Every malformed input raises :class:`~cldet.errors.ResultsError` naming the
file, the line and what was expected.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from cldet.errors import CldetError, LogError, ResultsError
from cldet.io import topics
from cldet.io.files import atomic_path, resolve_link
from cldet.io.mcap_read import open_log
from cldet.stamps import format_stamp, parse_stamp

RESULTS_COLUMNS: tuple[str, ...] = ("Sequence", "Timestamp", "Position", "Classification")
"""The submission's columns, in order."""
QUERY_COLUMNS: tuple[str, ...] = ("Sequence", "Timestamp")
"""The columns a query file must have (``Position`` and ``Classification`` are ignored)."""
TRUTH_COLUMNS: tuple[str, ...] = ("Sequence", "Timestamp", "x", "y", "z", "class")
"""The ground-truth CSV's columns."""
POSITION_DECIMALS = 6
"""Decimals of each coordinate in a written ``Position`` (micrometres)."""

RowKey = tuple[str, int]
"""(normalised sequence name, stamp in integer ns): how rows of different files are matched."""

_SEQ_RE = re.compile(r"^seq0*(\d+)$", re.IGNORECASE)
_POSITION_RE = re.compile(r"^\[(.*)\]$", re.DOTALL)


# --- rows ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class QueryRow:
    """One query row: a sequence and an instant at which a position is asked for."""

    sequence: str  # exactly as written in the file
    timestamp: str  # exactly as written in the file, e.g. "1713163000.123456"
    stamp_ns: int  # the timestamp in integer ns since the Unix epoch
    line: int = 0  # line number in the file it was read from (header = 1); 0 when built in code

    @property
    def key(self) -> RowKey:
        """The matching key: (normalised sequence, stamp ns)."""
        return row_key(self.sequence, self.stamp_ns)


@dataclass(frozen=True)
class ResultRow:
    """One submission row: a position estimate and a class at one query instant."""

    sequence: str  # exactly as in the query file
    timestamp: str  # exactly as in the query file
    stamp_ns: int
    position: tuple[float, float, float]  # x, y, z metres, Mid-360 frame
    class_id: int
    line: int = 0  # line number in the file it was read from; 0 when built in code

    @property
    def key(self) -> RowKey:
        """The matching key: (normalised sequence, stamp ns)."""
        return row_key(self.sequence, self.stamp_ns)


@dataclass(frozen=True)
class TruthRow:
    """One ground-truth row: the drone's true position (and type, when known) at one instant."""

    sequence: str
    timestamp: str
    stamp_ns: int
    position: tuple[float, float, float]  # x, y, z metres, Mid-360 frame
    class_id: int | None  # 0..3; None when the truth has no class
    line: int = 0

    @property
    def key(self) -> RowKey:
        """The matching key: (normalised sequence, stamp ns)."""
        return row_key(self.sequence, self.stamp_ns)


@dataclass(frozen=True)
class TruthTable:
    """Ground truth to score against, from a truth CSV or from annotated logs."""

    source: str  # where it came from (a file, or a description of the logs), for reports
    rows: tuple[TruthRow, ...]  # unique keys

    def positions(self) -> NDArray[np.float64]:
        """(N, 3) metres, in row order."""
        return np.array([r.position for r in self.rows], dtype=np.float64).reshape(-1, 3)


# --- names and keys --------------------------------------------------------------------------
def normalise_sequence(name: str) -> str:
    """The canonical name of a sequence: ``seq1``, ``SEQ01`` and ``seq0001`` all give ``seq0001``.

    Names not of the form ``seq<digits>`` are returned stripped, otherwise unchanged.
    """
    text = name.strip()
    match = _SEQ_RE.match(text)
    if match is None:
        return text
    return f"seq{int(match.group(1)):04d}"


def row_key(sequence: str, stamp_ns: int) -> RowKey:
    """The key rows are matched by: (normalised sequence name, stamp in integer ns)."""
    return (normalise_sequence(sequence), int(stamp_ns))


def format_position(position: Iterable[float], decimals: int = POSITION_DECIMALS) -> str:
    """Format a position as the challenge writes it: ``[x, y, z]`` with a fixed decimal count."""
    values = [float(v) for v in position]
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"a position is three finite numbers, got {values}")
    return "[" + ", ".join(f"{v:.{decimals}f}" for v in values) + "]"


def parse_position(text: str) -> tuple[float, float, float]:
    """Parse a ``Position`` string ``[x, y, z]`` (commas and/or spaces between the numbers).

    Raises:
        ValueError: not three finite numbers between brackets.
    """
    match = _POSITION_RE.match(text.strip())
    if match is None:
        raise ValueError("expected '[x, y, z]' between square brackets")
    parts = [p for p in re.split(r"[,\s]+", match.group(1).strip()) if p]
    if len(parts) != 3:
        raise ValueError(f"expected 3 numbers in '[x, y, z]', found {len(parts)}")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError as err:
        raise ValueError(f"expected numbers in '[x, y, z]': {err}") from err
    if not all(math.isfinite(v) for v in values):
        raise ValueError("expected finite numbers in '[x, y, z]' (found NaN or inf)")
    return (values[0], values[1], values[2])


# --- reading -----------------------------------------------------------------------------------
class _Table:
    """Rows of a CSV file as dicts, with the line number of each and errors naming the place."""

    def __init__(self, path: Path, required: Sequence[str], kind: str) -> None:
        self.path = path
        self.kind = kind
        self.required = tuple(required)
        self.columns: tuple[str, ...] = ()

    def error(self, line: int, message: str) -> ResultsError:
        return ResultsError(f"{self.path}:{line}: {message}")

    def rows(self) -> Iterator[tuple[int, dict[str, str]]]:
        """Yield (line number, {column: stripped text}) for every non-blank data row."""
        try:
            with open(self.path, newline="", encoding="utf-8-sig") as handle:
                reader = csv.reader(handle)
                header = next(reader, None)
                while header is not None and not any(cell.strip() for cell in header):
                    header = next(reader, None)
                if header is None:
                    raise ResultsError(
                        f"{self.path}: empty file: expected a {self.kind} with the header "
                        f"{','.join(self.required)}"
                    )
                self.columns = tuple(cell.strip() for cell in header)
                missing = [c for c in self.required if c not in self.columns]
                if missing:
                    raise self.error(
                        reader.line_num,
                        f"missing column(s) {', '.join(missing)} in the header: expected a "
                        f"{self.kind} with the columns {','.join(self.required)}, found "
                        f"{','.join(self.columns)}",
                    )
                n_rows = 0
                for cells in reader:
                    if not any(cell.strip() for cell in cells):
                        continue  # blank line
                    if len(cells) != len(self.columns):
                        raise self.error(
                            reader.line_num,
                            f"{len(cells)} fields, expected {len(self.columns)} "
                            f'({",".join(self.columns)}); quote a Position as "[x, y, z]"',
                        )
                    n_rows += 1
                    yield (
                        reader.line_num,
                        {c: cell.strip() for c, cell in zip(self.columns, cells, strict=True)},
                    )
                if n_rows == 0:
                    raise self.error(
                        reader.line_num, f"no data rows: a {self.kind} needs at least one row"
                    )
        except OSError as err:
            raise ResultsError(f"{self.path}: cannot read the {self.kind}: {err}") from err
        except (UnicodeDecodeError, csv.Error) as err:
            raise ResultsError(f"{self.path}: not a CSV text file: {err}") from err

    def sequence(self, line: int, row: dict[str, str]) -> str:
        text = row["Sequence"]
        if not text:
            raise self.error(line, "empty Sequence: expected a name like 'seq0001'")
        return text

    def stamp(self, line: int, row: dict[str, str]) -> tuple[str, int]:
        text = row["Timestamp"]
        try:
            return text, parse_stamp(text)
        except CldetError as err:
            raise self.error(
                line,
                f"bad Timestamp {text!r}: expected Unix seconds with 1-6 decimals, "
                "like '1713163000.123456'",
            ) from err

    def number(self, line: int, row: dict[str, str], column: str) -> float:
        text = row[column]
        try:
            value = float(text)
        except ValueError as err:
            raise self.error(line, f"bad {column} {text!r}: expected a number") from err
        if not math.isfinite(value):
            raise self.error(line, f"bad {column} {text!r}: expected a finite number")
        return value

    def integer(self, line: int, row: dict[str, str], column: str) -> int:
        text = row[column]
        try:
            value = float(text)
        except ValueError as err:
            raise self.error(line, f"bad {column} {text!r}: expected an integer") from err
        if not math.isfinite(value) or value != int(value):
            raise self.error(line, f"bad {column} {text!r}: expected an integer")
        return int(value)

    def check_unique(self, seen: dict[RowKey, int], key: RowKey, line: int, timestamp: str) -> None:
        if key in seen:
            raise self.error(
                line,
                f"duplicate row for sequence {key[0]} at {timestamp} (first on line "
                f"{seen[key]}): expected one row per (Sequence, Timestamp)",
            )
        seen[key] = line


def read_timestamps(path: Path | str) -> tuple[QueryRow, ...]:
    """Read a query file (``test_timestamps.csv``): the rows a submission must answer, in order.

    Only ``Sequence`` and ``Timestamp`` are read; other columns are ignored.

    Raises:
        ResultsError: empty or unreadable file, a missing column, an empty Sequence, an unparsable
            Timestamp, or two rows with the same (sequence, stamp).
    """
    table = _Table(Path(path), QUERY_COLUMNS, "query file")
    rows: list[QueryRow] = []
    seen: dict[RowKey, int] = {}
    for line, row in table.rows():
        sequence = table.sequence(line, row)
        timestamp, stamp_ns = table.stamp(line, row)
        query = QueryRow(sequence, timestamp, stamp_ns, line)
        table.check_unique(seen, query.key, line, timestamp)
        rows.append(query)
    return tuple(rows)


def read_results(path: Path | str, *, allow_duplicates: bool = False) -> tuple[ResultRow, ...]:
    """Read a results file (``mmaud_results.csv``), rows in file order.

    Args:
        path: the CSV.
        allow_duplicates: keep rows repeating an earlier (sequence, stamp) instead of raising
            (the scorer counts them).

    Raises:
        ResultsError: empty or unreadable file, a missing column, an empty Sequence, a bad
            Timestamp, Position (not ``[x, y, z]`` with three finite numbers) or Classification
            (not an integer), or a duplicate row when not allowed.
    """
    table = _Table(Path(path), RESULTS_COLUMNS, "results file")
    rows: list[ResultRow] = []
    seen: dict[RowKey, int] = {}
    for line, row in table.rows():
        sequence = table.sequence(line, row)
        timestamp, stamp_ns = table.stamp(line, row)
        try:
            position = parse_position(row["Position"])
        except ValueError as err:
            raise table.error(line, f"bad Position {row['Position']!r}: {err}") from err
        class_id = table.integer(line, row, "Classification")
        result = ResultRow(sequence, timestamp, stamp_ns, position, class_id, line)
        if not allow_duplicates:
            table.check_unique(seen, result.key, line, timestamp)
        rows.append(result)
    return tuple(rows)


def read_truth(path: Path | str) -> TruthTable:
    """Read a ground-truth CSV (``Sequence,Timestamp,x,y,z,class``); an empty ``class`` is unknown.

    Raises:
        ResultsError: empty or unreadable file, a missing column, a bad Timestamp, a coordinate
            that is not a finite number, a bad class, or a duplicate (sequence, stamp).
    """
    table = _Table(Path(path), TRUTH_COLUMNS, "truth file")
    rows: list[TruthRow] = []
    seen: dict[RowKey, int] = {}
    for line, row in table.rows():
        sequence = table.sequence(line, row)
        timestamp, stamp_ns = table.stamp(line, row)
        x, y, z = (table.number(line, row, c) for c in ("x", "y", "z"))
        class_id = table.integer(line, row, "class") if row["class"] else None
        truth = TruthRow(sequence, timestamp, stamp_ns, (x, y, z), class_id, line)
        table.check_unique(seen, truth.key, line, timestamp)
        rows.append(truth)
    return TruthTable(source=str(path), rows=tuple(rows))


def read_log_truth(path: Path | str) -> list[TruthRow]:
    """The ground-truth rows of one log: ``/ground_truth`` positions, with ``/class`` if present.

    Each row's class is the label at or before its stamp (the first label for earlier stamps);
    ``None`` when the log has no ``/class`` channel. Timestamps are formatted with 6 decimals.

    Raises:
        LogError: the log cannot be read, has no sequence name or no ``/ground_truth`` messages.
    """
    with open_log(path) as log:
        sequence, _split = log.source()
        counts = log.list_topics()
        if counts.get(topics.GROUND_TRUTH, 0) == 0:
            listing = ", ".join(f"{t} ({n})" for t, n in counts.items()) or "none"
            raise LogError(
                f"{log.path}: no {topics.GROUND_TRUTH} messages (sequence {sequence}); "
                f"topics in the file: {listing}"
            )
        truth = list(log.iter_positions(topics.GROUND_TRUTH))
        labels = list(log.iter_classes(topics.CLASS)) if counts.get(topics.CLASS, 0) > 0 else []
    label_ns = np.array([c.stamp_ns for c in labels], dtype=np.int64)
    label_id = [c.class_id for c in labels]
    rows = []
    for sample in truth:
        class_id = None
        if label_id:
            i = int(np.searchsorted(label_ns, sample.stamp_ns, side="right")) - 1
            class_id = label_id[max(i, 0)]
        x, y, z = (float(v) for v in sample.position)
        rows.append(
            TruthRow(sequence, format_stamp(sample.stamp_ns), sample.stamp_ns, (x, y, z), class_id)
        )
    return rows


# --- writing -----------------------------------------------------------------------------------
def write_atomic(path: Path | str, write: Callable[[Path], None], *, overwrite: bool) -> None:
    """Create ``path`` through a temporary file in the same folder, renamed into place at the end.

    :func:`cldet.io.files.atomic_path` for a ``write(tmp)`` callback, with the CSV layer's errors:
    a crash or error never leaves a partial file and never damages an existing one (mode from
    the umask, fsync, stale temporaries removed).

    Args:
        path: the output file; its folder must exist.
        write: writes the complete content to the temporary path it is given.
        overwrite: replace an existing ``path``.

    Raises:
        OutputExistsError: ``path`` exists and ``overwrite`` is false.
        ResultsError: the folder is missing or not writable.
    """
    target = Path(path)
    if not resolve_link(target).parent.is_dir():
        raise ResultsError(f"{target}: the folder {target.parent} does not exist")
    try:
        with atomic_path(target, overwrite=overwrite) as tmp:
            write(tmp)
    except OSError as err:
        raise ResultsError(f"{target}: cannot write: {err.strerror or err}") from err


def write_results(path: Path | str, rows: Iterable[ResultRow], *, overwrite: bool = False) -> None:
    """Write a submission in exactly the challenge format, atomically.

    Columns ``Sequence,Timestamp,Position,Classification``; the rows in the order given, Sequence
    and Timestamp exactly as given, Position ``"[x, y, z]"`` with :data:`POSITION_DECIMALS`
    decimals (quoted), Classification an int; ``\\n`` line endings.

    Raises:
        OutputExistsError: ``path`` exists and ``overwrite`` is false.
        ResultsError: a non-finite position, or the file cannot be written.
    """
    lines: list[list[str]] = []
    for row in rows:
        try:
            position = format_position(row.position)
        except ValueError as err:
            raise ResultsError(
                f"{path}: cannot write the row for {row.sequence} at {row.timestamp}: {err}"
            ) from err
        lines.append([row.sequence, row.timestamp, position, str(int(row.class_id))])

    def write(tmp: Path) -> None:
        with open(tmp, "w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(RESULTS_COLUMNS)
            writer.writerows(lines)

    write_atomic(path, write, overwrite=overwrite)
