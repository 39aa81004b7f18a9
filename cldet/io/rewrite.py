"""Rewrite an MCAP log with extra channels: every source record is copied byte for byte.

MCAP has no in-place append, so results are added by streaming the source into a temporary file in
the target's folder (source schemas, channels, messages, metadata and attachments copied unchanged,
the new messages interleaved by log time) and renaming it over the target when complete. Channels
whose topic starts with a replaced prefix (``/cldet/``) and metadata records with a replaced name
are dropped, so annotating twice replaces the earlier results instead of adding duplicates.
"""

from __future__ import annotations

import heapq
import struct
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import make_reader

from cldet.errors import LogError
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
    with open(source, "rb") as src, atomic_output(target, overwrite=True) as out:
        return _copy(src, out, source, added, metadata or {}, replace_prefix, set(replace_metadata))


def _copy(
    src: Any,
    out: Any,
    source: Path,
    added: list[tuple[int, Addition]],
    metadata: dict[str, dict[str, str]],
    replace_prefix: str,
    replace_metadata: set[str],
) -> RewriteStats:
    try:
        reader = make_reader(src)
        header = reader.get_header()
        summary = reader.get_summary()
    except Exception as err:  # the mcap reader raises struct.error, EOFError, McapError...
        raise LogError(f"{source}: not a readable MCAP file ({err})") from err
    if summary is None:
        raise LogError(f"{source}: the MCAP file has no summary section (was it truncated?)")
    compression = Compression.zstd
    if summary.chunk_indexes:
        compression = {"lz4": Compression.lz4, "": Compression.none}.get(
            next(iter(summary.chunk_indexes)).compression, Compression.zstd
        )
    copied = dropped = 0
    with LogWriter(out, compression=compression, profile=header.profile) as writer:
        try:
            merged = heapq.merge(_source_messages(reader), _added(added), key=lambda item: item[0])
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
            for record in reader.iter_metadata():
                if record.name not in replace_metadata:
                    writer.write_metadata(record.name, dict(record.metadata))
            for name, values in metadata.items():
                writer.write_metadata(name, values)
            for attachment in reader.iter_attachments():
                writer.write_attachment(attachment)
        except (McapError, EOFError, struct.error) as err:
            raise LogError(f"{source}: the MCAP file is corrupt or truncated ({err})") from err
    return RewriteStats(copied, dropped, len(added))


def _source_messages(reader: Any) -> Iterator[tuple[int, Any]]:
    for schema, channel, message in reader.iter_messages(log_time_order=True):
        yield message.log_time, (schema, channel, message)


def _added(added: list[tuple[int, Addition]]) -> Iterator[tuple[int, Addition]]:
    yield from added
