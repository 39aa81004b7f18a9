"""cldet's MCAP layer: topic names and schemas, a log writer and typed readers.

Times are integer nanoseconds since the Unix epoch everywhere; in every log written here a
message's log time, publish time and own ``timestamp`` are the same number.
"""

from __future__ import annotations

from cldet.io.files import atomic_output
from cldet.io.mcap_read import (
    LogReader,
    decode_cloud,
    iter_classes,
    iter_cloud_fields,
    iter_clouds,
    iter_estimates,
    iter_positions,
    list_topics,
    open_log,
    read_metadata,
)
from cldet.io.mcap_write import Compression, LogWriter, png_size

__all__ = [
    "Compression",
    "LogReader",
    "LogWriter",
    "atomic_output",
    "decode_cloud",
    "iter_classes",
    "iter_cloud_fields",
    "iter_clouds",
    "iter_estimates",
    "iter_positions",
    "list_topics",
    "open_log",
    "png_size",
    "read_metadata",
]
