"""Timestamps: the challenge's file names <-> integer nanoseconds, without ever passing through a float."""

from __future__ import annotations

import re

import numpy as np
from numpy.typing import NDArray

from cldet.errors import DatasetError

# ASCII digits only, whole string (``$`` would also accept a trailing newline).
_STAMP_RE = re.compile(r"(\d{1,12})\.(\d{1,6})", re.ASCII)

NS_PER_S = 1_000_000_000


def parse_stamp(text: str) -> int:
    """Parse a stamp such as ``1706255621.600227`` (or the float-printed ``1706255621.71419``) to ns.

    The fraction has 1 to 6 digits (microseconds; trailing zeros may have been dropped by a float
    print), so ``1706255621.71419`` is 1706255621.714190 s.

    Args:
        text: the stamp, without any file extension.

    Returns:
        Integer nanoseconds since the Unix epoch.

    Raises:
        DatasetError: ``text`` is not of the form ``<seconds>.<1-6 digits>``.
    """
    match = _STAMP_RE.fullmatch(text)
    if match is None:
        raise DatasetError(
            f"{text!r} is not a timestamp: expected Unix seconds with 1-6 decimals, "
            "like '1706255621.600227'"
        )
    seconds, fraction = match.groups()
    return int(seconds) * NS_PER_S + int(fraction.ljust(6, "0")) * 1_000


def format_stamp(stamp_ns: int) -> str:
    """Format integer nanoseconds as the challenge writes stamps: seconds with exactly 6 decimals.

    Sub-microsecond digits are truncated (the challenge's stamps are whole microseconds).
    """
    if stamp_ns < 0:
        raise ValueError(f"stamp must be non-negative, got {stamp_ns} ns")
    seconds, rest = divmod(stamp_ns, NS_PER_S)
    return f"{seconds}.{rest // 1_000:06d}"


SCAN_PERIOD_S = 0.1
"""A Livox scan (Mid-360 and Avia at 10 Hz) lasts 100 ms from its stamp."""


def row_times(
    rows: NDArray[np.integer], n_rows: int, scan_s: float = SCAN_PERIOD_S
) -> NDArray[np.float32]:
    """Firing time after the stamp, seconds, of the rows ``rows`` of a scan array of ``n_rows``.

    A Livox driver's array holds its scan's rows in firing order, a row for every shot (the
    MMAUD files keep the no-return rows as zeros, in 96-row packets), at an even rate over the
    scan: row i of n fired ``i / n * scan_s`` after the stamp. A drone at 16 m/s moves 1.6 m in a
    scan, so a point dated at the scan's middle is off by up to 0.8 m along its path.
    """
    if n_rows <= 0:
        return np.zeros(0, dtype=np.float32)
    return (np.asarray(rows, dtype=np.float64) * (scan_s / n_rows)).astype(np.float32)
