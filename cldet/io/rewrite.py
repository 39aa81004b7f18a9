"""Add channels to an MCAP log: every source record is kept byte for byte.

MCAP has no in-place append, so results go into a temporary file in the target's folder, renamed
over the target when complete. The fast path (:mod:`cldet.io.mcap_append`) copies the source's
data section verbatim (no decompression, no recompression: image chunks cost a file copy) and
appends the new channels' chunks, metadata and a new summary. Channels whose topic starts with a
replaced prefix (``/cldet/``) and metadata records with a replaced name, which an earlier run
appended at the end, are cut off first, so annotating twice replaces the earlier results instead
of adding duplicates.

A log the fast path cannot continue (no chunk index, or results interleaved with the sources, as
other tools may write them) is first copied message by message without the replaced channels,
then continued: the next run on it takes the fast path.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from mcap.records import Attachment, Channel, Message, Metadata, Schema

from cldet.errors import LogError
from cldet.io.files import atomic_output, resolve_link, temporary_path
from cldet.io.mcap_append import AppendPlan, copy_prefix, is_replaced_channel, plan_append
from cldet.io.mcap_read import LogReader, open_log
from cldet.io.mcap_write import Compression, LogWriter

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
            that a later rewrite replaces them). They are written in time order, after the
            source's records.
        metadata: metadata records to add (name -> key/value strings).
        replace_prefix: source channels with this topic prefix are dropped.
        replace_metadata: source metadata records with these names are dropped.

    Raises:
        LogError: the source cannot be read; the message names the file.
    """
    added = sorted(additions, key=lambda a: a[0])
    with open_log(source) as reader:
        plan = _plan_append(reader, replace_prefix, replace_metadata)
        if plan is not None:
            return _append(reader, plan, target, added, metadata or {})
    clean = temporary_path(resolve_link(target), "clean")
    try:
        with open_log(source) as reader, atomic_output(clean, overwrite=True) as out:
            copied, dropped = _copy_without(reader, out, replace_prefix, replace_metadata)
        with open_log(clean) as reader:
            plan = _plan_append(reader, replace_prefix, replace_metadata)
            if plan is None:  # cannot happen for a log LogWriter wrote; never silently
                raise LogError(f"{clean}: a clean copy of {source} cannot be continued")
            stats = _append(reader, plan, target, added, metadata or {})
    finally:
        with contextlib.suppress(FileNotFoundError):
            clean.unlink()
    return RewriteStats(copied, dropped, stats.added_messages)


def _plan_append(
    reader: LogReader, replace_prefix: str, replace_metadata: Sequence[str]
) -> AppendPlan | None:
    """Where the log can be cut to append records (None: it must be rewritten in full)."""
    try:
        return plan_append(
            reader.stream,
            reader.summary,
            replace_prefix=replace_prefix,
            replace_metadata=replace_metadata,
        )
    except OSError as err:
        raise LogError(f"cannot read {reader.path}: {err}") from err


def _append(
    reader: LogReader,
    plan: AppendPlan,
    target: Path,
    added: list[tuple[int, Addition]],
    metadata: dict[str, dict[str, str]],
) -> RewriteStats:
    """Copy the log up to ``plan.cut`` into ``target`` (atomically) and append the additions."""
    with atomic_output(target, overwrite=True) as out:
        try:
            copy_prefix(reader.stream, out, plan.cut)
        except OSError as err:
            raise LogError(f"cannot copy {reader.path}: {err}") from err
        with LogWriter(out, continues=plan) as writer:
            for _, write in added:
                write(writer)
            for name, values in metadata.items():
                writer.write_metadata(name, values)
    copied = sum(plan.channel_message_counts.values())
    return RewriteStats(copied, plan.dropped_messages, len(added))


def _copy_without(
    reader: LogReader, out: IO[bytes], replace_prefix: str, replace_metadata: Sequence[str]
) -> tuple[int, int]:
    """Copy every message, metadata record and attachment except the replaced ones.

    Record by record in file order (not through the chunk index), so that nothing a writer put
    outside chunks or indexes is lost.
    """
    copied = dropped = 0
    compression = {"lz4": Compression.lz4, "": Compression.none}.get(
        reader.chunk_compression(), Compression.zstd
    )
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    with LogWriter(out, compression=compression, profile=reader.header().profile) as writer:
        for record in reader.records():
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                channel = channels.get(record.channel_id)
                if channel is None:
                    raise LogError(
                        f"{reader.path}: a message at {record.log_time} ns on channel "
                        f"{record.channel_id}, which no earlier channel record defines"
                    )
                if is_replaced_channel(channel, replace_prefix):
                    dropped += 1
                    continue
                writer.write_raw(
                    schemas.get(channel.schema_id),
                    channel,
                    record.log_time,
                    record.publish_time,
                    record.data,
                )
                copied += 1
            elif isinstance(record, Metadata):
                if record.name not in replace_metadata:
                    writer.write_metadata(record.name, dict(record.metadata))
            elif isinstance(record, Attachment):
                writer.write_attachment(record)
    return copied, dropped
