"""Rewrite an MCAP log with extra channels: every source record is copied byte for byte.

MCAP has no in-place append, so results are added by streaming the source into a temporary file in
the target's folder (source schemas, channels, messages, metadata and attachments copied unchanged,
the new messages interleaved by log time) and renaming it over the target when complete. Channels
whose topic starts with a replaced prefix (``/cldet/``) and metadata records with a replaced name
are dropped, so annotating twice replaces the earlier results instead of adding duplicates.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cldet.io.mcap_read import LogReader, open_log
from cldet.io.mcap_write import Compression, LogWriter, atomic_output

Addition = Callable[[LogWriter], None]
"""Writes one new message, e.g. ``lambda w: w.write_pose(topic, stamp_ns, xyz, frame)``."""


@dataclass(frozen=True)
class RewriteStats:
    """What a rewrite copied and added."""

    copied_messages: int
    dropped_messages: int  # messages of replaced channels (an earlier annotation)
    added_messages: int


def rewrite_log(
    source: Path,
    target: Path,
    additions: Iterable[tuple[int, Addition]],
    *,
    metadata: dict[str, dict[str, str]] | None = None,
    replace_prefix: str = "/cldet/",
    replace_metadata: Sequence[str] = (),
) -> RewriteStats:
    """Copy ``source`` to ``target`` with new messages added; atomic, ``target`` may be ``source``.

    Args:
        source: the MCAP log to read; never modified.
        target: where the result goes; written to a temporary file in its folder first, then
            renamed over it (an existing ``target`` is replaced).
        additions: ``(log_time_ns, write)`` pairs in any order; each ``write`` adds one message
            through the :class:`LogWriter` (whose topics must start with ``replace_prefix``, so
            that a later rewrite replaces them). They are interleaved with the source by time.
        metadata: metadata records to add (name -> key/value strings).
        replace_prefix: source channels with this topic prefix are dropped.
        replace_metadata: source metadata records with these names are dropped.

    Raises:
        LogError: the source cannot be read; the message names the file.
    """
    added = sorted(additions, key=lambda a: a[0])
    copied = dropped = 0
    with open_log(source) as reader, atomic_output(target, overwrite=True) as out:
        compression = {"lz4": Compression.lz4, "": Compression.none}.get(
            reader.chunk_compression(), Compression.zstd
        )
        with LogWriter(out, compression=compression, profile=reader.header().profile) as writer:
            merged = heapq.merge(_source(reader), added, key=lambda item: item[0])
            for _, payload in merged:
                if callable(payload):
                    payload(writer)
                    continue
                schema, channel, message = payload
                if channel.topic.startswith(replace_prefix):
                    dropped += 1
                    continue
                writer.write_raw(
                    schema, channel, message.log_time, message.publish_time, message.data
                )
                copied += 1
            for name, values in reader.metadata_records():
                if name not in replace_metadata:
                    writer.write_metadata(name, values)
            for name, values in (metadata or {}).items():
                writer.write_metadata(name, values)
            for attachment in reader.attachments():
                writer.write_attachment(attachment)
    return RewriteStats(copied, dropped, len(added))


def _source(reader: LogReader) -> Iterator[tuple[int, Any]]:
    for schema, channel, message in reader.iter_messages():
        yield message.log_time, (schema, channel, message)
