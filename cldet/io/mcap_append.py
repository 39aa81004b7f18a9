"""Continue a finished MCAP log: keep its data section byte for byte, add records, new summary.

An MCAP file is ``magic | header | data section | DataEnd | summary | summary offsets | footer |
magic``; readers find chunks through the summary's chunk indexes, whose offsets point into the
data section. A copy of the data section therefore stays valid as it is: results are added by
copying the source up to a cut offset (the end of its data section, or where an earlier run's
appended records begin), appending new schema, channel, chunk, message index and metadata
records, and writing a summary that lists the source's records and the new ones.

Nothing is decompressed or recompressed: for a log holding full-size camera images this is the
difference between copying bytes and re-encoding every chunk.

:func:`plan_append` decides whether a log can be continued this way and where to cut it;
:class:`AppendWriter` is a stand-in for ``mcap.writer.Writer`` (the methods ``LogWriter`` calls)
that writes the appended records and the new summary.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import IO

import lz4.frame
import zstandard
from mcap.records import (
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    McapRecord,
    Message,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Opcode,
    RecordBuilder,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.summary import Summary

from cldet.io.topics import RESULT_CHANNEL_KEY

__all__ = ["AppendPlan", "AppendWriter", "copy_prefix", "is_replaced_channel", "plan_append"]

MAGIC = b"\x89MCAP0\r\n"
_FOOTER_LEN = 1 + 8 + 8 + 8 + 4  # opcode, length, summary_start, summary_offset_start, crc
_DATA_END_LEN = 1 + 8 + 4  # opcode, length, data_section_crc

_COMPRESS: dict[str, Callable[[bytes], bytes]] = {
    "": lambda data: data,
    "zstd": lambda data: zstandard.ZstdCompressor().compress(data),
    "lz4": lambda data: lz4.frame.compress(data),
}


@dataclass(frozen=True)
class AppendPlan:
    """How to continue one log: copy ``cut`` bytes, keep these summary records, add the rest."""

    cut: int  # bytes of the source copied verbatim (header and kept data records)
    compression: str  # the source's chunk compression, used for the appended chunks
    schemas: dict[int, Schema]
    channels: dict[int, Channel]
    chunk_indexes: list[ChunkIndex]
    attachment_indexes: list[AttachmentIndex]
    metadata_indexes: list[MetadataIndex]
    channel_message_counts: dict[int, int]
    dropped_messages: int  # messages of replaced channels beyond the cut
    next_schema_id: int  # first id for new schemas (above every id the log defines)
    next_channel_id: int  # first id for new channels


def _footer_summary_start(stream: IO[bytes]) -> int | None:
    """The footer's summary_start (None when the file does not end in a footer and magic)."""
    size = stream.seek(0, os.SEEK_END)
    if size < len(MAGIC) * 2 + _FOOTER_LEN:
        return None
    stream.seek(size - len(MAGIC) - _FOOTER_LEN)
    tail = stream.read(_FOOTER_LEN + len(MAGIC))
    if tail[-len(MAGIC) :] != MAGIC or tail[0] != Opcode.FOOTER:
        return None
    (summary_start,) = struct.unpack_from("<Q", tail, 9)
    return int(summary_start)


def _tail_is_replaceable(
    stream: IO[bytes],
    cut: int,
    data_end: int,
    chunk_offsets: set[int],
    replace_metadata: Sequence[str],
) -> bool:
    """True when every record from ``cut`` to DataEnd is one a new append replaces.

    That is: chunks listed in ``chunk_offsets`` (whose channels the caller checked are all
    replaced), their message indexes, schema and channel records, and metadata records named in
    ``replace_metadata``. Anything else (a message outside a chunk, an attachment, other
    metadata, an unindexed chunk, an unknown record) would be lost by cutting there.
    """
    stream.seek(cut)
    tail = stream.read(data_end - cut)
    if len(tail) != data_end - cut:
        return False
    pos = 0
    while pos < len(tail):
        if pos + 9 > len(tail):
            return False
        opcode = tail[pos]
        (length,) = struct.unpack_from("<Q", tail, pos + 1)
        body = pos + 9
        if body + length > len(tail):
            return False
        if opcode == Opcode.CHUNK:
            if cut + pos not in chunk_offsets:
                return False
        elif opcode == Opcode.METADATA:
            if length < 4:
                return False
            (name_len,) = struct.unpack_from("<I", tail, body)
            name = tail[body + 4 : body + 4 + name_len].decode("utf-8", "replace")
            if name not in replace_metadata:
                return False
        elif opcode not in (Opcode.MESSAGE_INDEX, Opcode.SCHEMA, Opcode.CHANNEL):
            return False
        pos = body + length
    return True


def plan_append(
    stream: IO[bytes],
    summary: Summary,
    *,
    replace_prefix: str,
    replace_metadata: Sequence[str],
) -> AppendPlan | None:
    """Where to cut ``stream`` (an MCAP log with ``summary``) so that records can be appended.

    The cut is the end of the data section, or, when the log holds records to replace (channels
    whose topic starts with ``replace_prefix``, metadata named in ``replace_metadata``), the
    offset of the first of them: everything from there to the end of the data section must then
    be such records (as an earlier append leaves them; the bytes are checked record by record).
    Returns None when the log cannot be continued this way (no statistics, statistics that do
    not account for every message, metadata record or attachment by channel or index, messages
    without a chunk index, results interleaved with the sources, anything else after the
    results); the caller then rewrites it in full.
    """
    stats = summary.statistics
    chunks = summary.chunk_indexes
    if stats is None or stats.chunk_count != len(chunks):
        return None
    if not chunks and stats.message_count:
        return None  # messages outside chunks
    counts = dict(stats.channel_message_counts)
    if sum(counts.values()) != stats.message_count or not set(counts) <= set(summary.channels):
        return None  # per-channel counts missing: the new statistics could not be right
    if stats.metadata_count != len(summary.metadata_indexes):
        return None
    if stats.attachment_count != len(summary.attachment_indexes):
        return None
    if any(not c.message_index_offsets or c.compression not in _COMPRESS for c in chunks):
        return None
    summary_start = _footer_summary_start(stream)
    if not summary_start:
        return None
    data_end = summary_start - _DATA_END_LEN
    stream.seek(data_end)
    if stream.read(1) != bytes([Opcode.DATA_END]):
        return None
    replaced = {
        cid for cid, c in summary.channels.items() if is_replaced_channel(c, replace_prefix)
    }
    old_chunks = [c for c in chunks if replaced.intersection(c.message_index_offsets)]
    old_meta = [m for m in summary.metadata_indexes if m.name in replace_metadata]
    cut = min(
        [c.chunk_start_offset for c in old_chunks] + [m.offset for m in old_meta] + [data_end]
    )
    kept_chunks = [c for c in chunks if c.chunk_start_offset < cut]
    tail_chunks = [c for c in chunks if c.chunk_start_offset >= cut]
    if any(replaced.intersection(c.message_index_offsets) for c in kept_chunks):
        return None  # results interleaved with the sources
    if any(not replaced.issuperset(c.message_index_offsets) for c in tail_chunks):
        return None  # source messages after the results
    if any(m.offset >= cut and m.name not in replace_metadata for m in summary.metadata_indexes):
        return None
    if any(a.offset >= cut for a in summary.attachment_indexes):
        return None
    offsets = {c.chunk_start_offset for c in tail_chunks}
    if not _tail_is_replaceable(stream, cut, data_end, offsets, replace_metadata):
        return None
    channels = {cid: c for cid, c in summary.channels.items() if cid not in replaced}
    used_schemas = {c.schema_id for c in channels.values()}
    return AppendPlan(
        cut=cut,
        compression=chunks[0].compression if chunks else "zstd",
        schemas={sid: s for sid, s in summary.schemas.items() if sid in used_schemas},
        channels=channels,
        chunk_indexes=kept_chunks,
        attachment_indexes=list(summary.attachment_indexes),
        metadata_indexes=[m for m in summary.metadata_indexes if m.offset < cut],
        channel_message_counts={cid: counts.get(cid, 0) for cid in channels},
        dropped_messages=sum(counts.get(cid, 0) for cid in replaced),
        # new ids above every id the log defines, dropped ones included: a replaced channel
        # that never published keeps its records before the cut
        next_schema_id=max(summary.schemas, default=0) + 1,
        next_channel_id=max(summary.channels, default=-1) + 1,
    )


def is_replaced_channel(channel: Channel, replace_prefix: str) -> bool:
    """True for a result channel a new append replaces: its topic starts with ``replace_prefix``,
    or its metadata marks it as a result (``cldet.result``), e.g. a ``/tf`` annotate added."""
    return channel.topic.startswith(replace_prefix) or RESULT_CHANNEL_KEY in channel.metadata


def copy_prefix(source: IO[bytes], target: IO[bytes], length: int) -> None:
    """Copy the first ``length`` bytes of ``source`` to ``target`` (kernel copy when possible)."""
    target.flush()
    src_fd, dst_fd = source.fileno(), target.fileno()
    offset = 0
    try:
        while offset < length:
            n = os.copy_file_range(src_fd, dst_fd, length - offset, offset)
            if n == 0:
                raise OSError(f"source ended after {offset} of {length} bytes")
            offset += n
    except (AttributeError, OSError):  # no copy_file_range here (other OS, filesystem)
        source.seek(offset)
        target.seek(offset)
        while offset < length:
            block = source.read(min(1 << 24, length - offset))
            if not block:
                raise OSError(f"source ended after {offset} of {length} bytes") from None
            target.write(block)
            offset += len(block)
    target.seek(length)


@dataclass
class _OpenChunk:
    builder: RecordBuilder = field(default_factory=RecordBuilder)
    index: dict[int, list[tuple[int, int]]] = field(default_factory=dict)
    start: int = 0
    end: int = 0


class AppendWriter:
    """Appends records after a copied data section (see :func:`plan_append`) and finishes the log.

    Offers the methods of ``mcap.writer.Writer`` that ``cldet.io.mcap_write.LogWriter`` uses, so
    a ``LogWriter`` can write through it; ``start`` writes nothing (the header is in the copy).
    """

    def __init__(self, stream: IO[bytes], plan: AppendPlan, *, chunk_size: int) -> None:
        self._stream = stream
        self._plan = plan
        self._offset = plan.cut
        self._chunk_size = chunk_size
        self._schemas = dict(plan.schemas)
        self._channels = dict(plan.channels)
        self._counts = dict(plan.channel_message_counts)
        self._chunk_indexes = list(plan.chunk_indexes)
        self._metadata_indexes = list(plan.metadata_indexes)
        self._chunk = _OpenChunk()
        self._next_schema = plan.next_schema_id
        self._next_channel = plan.next_channel_id
        self._compress = _COMPRESS[plan.compression]

    def _write(self, *records: McapRecord) -> int:
        """Write records to the file; returns the offset of the first."""
        builder = RecordBuilder()
        for record in records:
            record.write(builder)
        data = builder.end()
        start = self._offset
        self._stream.write(data)
        self._offset += len(data)
        return start

    # --- the mcap.writer.Writer interface used by LogWriter ------------------------------------
    def start(self, profile: str = "", library: str = "") -> None:
        """Nothing to write: the header is part of the copied prefix."""

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Add a schema record (a new id, after the source's) to the open chunk."""
        schema = Schema(id=self._next_schema, name=name, encoding=encoding, data=data)
        self._next_schema += 1
        self._schemas[schema.id] = schema
        schema.write(self._chunk.builder)  # in the chunk: a later cut drops it with the chunk
        return schema.id

    def register_channel(
        self,
        topic: str,
        message_encoding: str,
        schema_id: int,
        metadata: dict[str, str] | None = None,
    ) -> int:
        """Add a channel record (a new id, after the source's) to the open chunk."""
        channel = Channel(
            id=self._next_channel,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=dict(metadata or {}),
        )
        self._next_channel += 1
        self._channels[channel.id] = channel
        self._counts[channel.id] = 0
        channel.write(self._chunk.builder)
        return channel.id

    def add_message(
        self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0
    ) -> None:
        """Add a message to the open chunk (written once it holds ``chunk_size`` bytes)."""
        chunk = self._chunk
        if not chunk.index:
            chunk.start = chunk.end = log_time
        chunk.index.setdefault(channel_id, []).append((log_time, chunk.builder.count))
        Message(
            channel_id=channel_id,
            log_time=log_time,
            data=data,
            publish_time=publish_time,
            sequence=sequence,
        ).write(chunk.builder)
        chunk.start, chunk.end = min(chunk.start, log_time), max(chunk.end, log_time)
        self._counts[channel_id] = self._counts.get(channel_id, 0) + 1
        if chunk.builder.count >= self._chunk_size:
            self._flush_chunk()

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Add a metadata record (after the open chunk)."""
        self._flush_chunk()
        record = Metadata(name=name, metadata=dict(data))
        start = self._write(record)
        self._metadata_indexes.append(
            MetadataIndex(offset=start, length=self._offset - start, name=name)
        )

    def add_attachment(self, **_: object) -> None:
        """Attachments of the source are in the copied prefix; new ones are not supported."""
        raise NotImplementedError("AppendWriter does not add attachments")

    def _flush_chunk(self) -> None:
        chunk = self._chunk
        if not chunk.builder.count:
            return
        self._chunk = _OpenChunk()
        raw = chunk.builder.end()
        record = Chunk(
            message_start_time=chunk.start,
            message_end_time=chunk.end,
            uncompressed_size=len(raw),
            uncompressed_crc=zlib.crc32(raw),
            compression=self._plan.compression,
            data=self._compress(raw),
        )
        chunk_start = self._write(record)
        chunk_length = self._offset - chunk_start
        offsets: dict[int, int] = {}
        for channel_id in sorted(chunk.index):
            offsets[channel_id] = self._write(
                MessageIndex(channel_id=channel_id, records=chunk.index[channel_id])
            )
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=chunk.start,
                message_end_time=chunk.end,
                chunk_start_offset=chunk_start,
                chunk_length=chunk_length,
                message_index_offsets=offsets,
                message_index_length=self._offset - chunk_start - chunk_length,
                compression=self._plan.compression,
                compressed_size=len(record.data),
                uncompressed_size=len(raw),
            )
        )

    def finish(self) -> None:
        """Write the last chunk, DataEnd, the summary, the summary offsets and the footer."""
        self._flush_chunk()
        self._write(DataEnd(data_section_crc=0))  # 0: not computed (the prefix is not re-read)
        summary_start = self._offset
        groups: list[tuple[Opcode, list[McapRecord]]] = [
            (Opcode.SCHEMA, list(self._schemas.values())),
            (Opcode.CHANNEL, list(self._channels.values())),
            (Opcode.STATISTICS, [self._statistics()]),
            (Opcode.CHUNK_INDEX, list(self._chunk_indexes)),
            (Opcode.ATTACHMENT_INDEX, list(self._plan.attachment_indexes)),
            (Opcode.METADATA_INDEX, list(self._metadata_indexes)),
        ]
        builder = RecordBuilder()
        offsets: list[SummaryOffset] = []
        for opcode, records in groups:
            if not records:
                continue
            start = summary_start + builder.count
            for record in records:
                record.write(builder)
            offsets.append(
                SummaryOffset(
                    group_opcode=opcode,
                    group_start=start,
                    group_length=summary_start + builder.count - start,
                )
            )
        summary_offset_start = summary_start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = builder.end()
        # the footer by hand: its CRC covers the summary and the footer's own first fields
        footer_head = struct.pack(
            "<BQQQ", Opcode.FOOTER, _FOOTER_LEN - 9, summary_start, summary_offset_start
        )
        crc = zlib.crc32(summary + footer_head)
        self._stream.write(summary + footer_head + struct.pack("<I", crc) + MAGIC)
        self._offset += len(summary) + _FOOTER_LEN + len(MAGIC)

    def _statistics(self) -> Statistics:
        counts = {cid: n for cid, n in self._counts.items() if cid in self._channels}
        chunks = self._chunk_indexes
        return Statistics(
            message_count=sum(counts.values()),
            schema_count=len(self._schemas),
            channel_count=len(self._channels),
            attachment_count=len(self._plan.attachment_indexes),
            metadata_count=len(self._metadata_indexes),
            chunk_count=len(chunks),
            message_start_time=min((c.message_start_time for c in chunks), default=0),
            message_end_time=max((c.message_end_time for c in chunks), default=0),
            channel_message_counts=counts,
        )
