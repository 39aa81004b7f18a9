"""Reading cldet's MCAP logs back into plain data (``Cloud``, ``PositionSample``, ...).

``open_log(path)`` gives a :class:`LogReader` (a context manager) for several reads of one file;
the module-level ``iter_*``/``read_*``/``list_topics`` functions open, read and close in one
call. Every stamp is integer nanoseconds since the Unix epoch: the message's log time.

Point clouds are decoded without copying: the points are a read-only float32 view into the
message bytes. Every failure is a :class:`~cldet.errors.LogError` naming the file (and the topic,
listing the topics that exist when one is missing).
"""

from __future__ import annotations

import heapq
import os
import struct
import zlib
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import lz4.frame
import numpy as np
import zstandard
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from google.protobuf.message import DecodeError
from mcap.exceptions import McapError
from mcap.reader import SeekingReader, make_reader
from mcap.records import (
    Attachment,
    Channel,
    ChunkIndex,
    Header,
    Message,
    Metadata,
    Schema,
    Statistics,
)
from mcap.stream_reader import StreamReader
from mcap.summary import Summary
from numpy.typing import NDArray

from cldet.errors import CorruptMessageError, LogError
from cldet.io import topics
from cldet.io.schemas import ClassEstimateMessage, ClassLabel
from cldet.io.schemas import Estimate as EstimateMessage
from cldet.stamps import NS_PER_S, format_stamp
from cldet.types import ClassEstimate, ClassSample, Cloud, Estimate, PositionSample, Source

__all__ = [
    "CORRUPT_ERRORS",
    "LogReader",
    "decode_cloud",
    "decode_timed",
    "decode_xyz",
    "iter_classes",
    "iter_cloud_fields",
    "iter_clouds",
    "iter_estimates",
    "iter_positions",
    "list_topics",
    "open_log",
    "read_metadata",
]

_DATA_FIELD = 6  # foxglove.PointCloud.data

CORRUPT_ERRORS: tuple[type[BaseException], ...] = (
    McapError,
    DecodeError,
    ValueError,  # also UnicodeDecodeError, mcap's CRCValidationError
    IndexError,
    KeyError,
    OverflowError,  # a corrupt size handed to a decompressor
    struct.error,
    EOFError,
    zstandard.ZstdError,
    RuntimeError,
)
"""What corrupt bytes raise in the mcap library, protobuf, the decompressors and this module's
own parsers (lz4.frame raises RuntimeError on a bad frame); anything else is a bug, not caught.
Readers of other formats inside a log (:mod:`cldet.io.sources`) extend it."""

# ... and a seek before the start of a short file, a read that fails.
_UNREADABLE: tuple[type[BaseException], ...] = (*CORRUPT_ERRORS, OSError)


def _reason(err: BaseException) -> str:
    """The error's text, or its type's name when it has none (never an empty reason)."""
    return str(err).strip() or type(err).__name__


_FLOAT32 = PackedElementField.FLOAT32


def _read_varint(buf: bytes, pos: int) -> tuple[int, int]:
    result = shift = 0
    while True:
        byte = buf[pos]
        pos += 1
        result |= (byte & 0x7F) << shift
        if byte < 0x80:
            return result, pos
        shift += 7


def _split_data_field(buf: bytes) -> tuple[bytes, int, int]:
    """Split a serialized PointCloud into (everything but ``data``, data offset, data length).

    Walks the top-level protobuf fields only (a handful), so the points are never copied.
    """
    pos, n = 0, len(buf)
    data_start = data_len = 0
    header = bytearray()
    while pos < n:
        start = pos
        key, pos = _read_varint(buf, pos)
        wire = key & 7
        if wire == 0:
            _, pos = _read_varint(buf, pos)
        elif wire == 1:
            pos += 8
        elif wire == 5:
            pos += 4
        elif wire == 2:
            length, pos = _read_varint(buf, pos)
            if key >> 3 == _DATA_FIELD:
                data_start, data_len = pos, length
                pos += length
                continue
            pos += length
        else:
            raise ValueError(f"unsupported protobuf wire type {wire}")
        header += buf[start:pos]
    if pos != n:
        raise ValueError("truncated PointCloud message")
    return bytes(header), data_start, data_len


def decode_cloud(data: bytes) -> tuple[int, dict[str, NDArray[np.float32]]]:
    """Decode a serialized ``foxglove.PointCloud`` into its stamp and one column per field.

    Returns:
        ``(stamp_ns, {name: (N,) float32})`` from the message's own ``timestamp``; the columns
        are read-only views into ``data`` (no copy).

    Raises:
        ValueError: the message is malformed or has a field that is not FLOAT32.
    """
    header_bytes, start, length = _split_data_field(data)
    header = PointCloud.FromString(header_bytes)
    stride = header.point_stride
    if stride <= 0 or length % stride:
        raise ValueError(f"point_stride {stride} does not divide the {length} data bytes")
    n = length // stride
    names: list[str] = []
    offsets: list[int] = []
    for field in header.fields:
        if field.type != _FLOAT32:
            raise ValueError(f"field {field.name!r} is not FLOAT32")
        names.append(field.name)
        offsets.append(field.offset)
    dtype = np.dtype(
        {"names": names, "formats": ["<f4"] * len(names), "offsets": offsets, "itemsize": stride}
    )
    records = np.frombuffer(data, dtype=dtype, count=n, offset=start)
    stamp_ns = header.timestamp.seconds * NS_PER_S + header.timestamp.nanos
    return stamp_ns, {name: records[name] for name in names}


def decode_timed(data: bytes) -> tuple[int, str, NDArray[np.float32], NDArray[np.float32] | None]:
    """``decode_xyz`` and the points' times: the ``time`` field (FLOAT32 seconds after the stamp,
    ``topics.POINT_TIME_FIELD``), a read-only view like the points; None where the message has none."""
    header_bytes, start, length = _split_data_field(data)
    header = PointCloud.FromString(header_bytes)
    stamp_ns = header.timestamp.seconds * NS_PER_S + header.timestamp.nanos
    stride = header.point_stride
    layout = {f.name: (f.offset, f.type) for f in header.fields}
    if any(layout.get(c, (None, None))[1] != _FLOAT32 for c in "xyz"):
        raise ValueError("x, y, z are not all FLOAT32 fields")
    if stride <= 0 or length % stride:
        raise ValueError(f"point_stride {stride} does not divide the {length} data bytes")
    n = length // stride
    times = None
    if layout.get(topics.POINT_TIME_FIELD, (None, None))[1] == _FLOAT32:
        offset = layout[topics.POINT_TIME_FIELD][0]
        if offset + 4 > stride:
            raise ValueError(
                f"field {topics.POINT_TIME_FIELD!r} at offset {offset} lies beyond the stride"
            )
        dtype = np.dtype(
            {"names": ["t"], "formats": ["<f4"], "offsets": [offset], "itemsize": stride}
        )
        times = np.frombuffer(data, dtype=dtype, count=n, offset=start)["t"]
    if layout["x"][0] == 0 and layout["y"][0] == 4 and layout["z"][0] == 8 and stride % 4 == 0:
        flat = np.frombuffer(data, dtype="<f4", count=n * stride // 4, offset=start)
        return stamp_ns, header.frame_id, flat.reshape(n, stride // 4)[:, :3], times
    _, columns = decode_cloud(data)
    xyz = np.stack([columns["x"], columns["y"], columns["z"]], axis=1)
    return stamp_ns, header.frame_id, xyz, times


def decode_xyz(data: bytes) -> tuple[int, str, NDArray[np.float32]]:
    """``(stamp_ns, frame_id, (N, 3) x, y, z)`` of a serialized ``foxglove.PointCloud``.

    The stamp is the message's own ``timestamp``; the points are a read-only view into ``data``
    when x, y, z are packed first (a copy otherwise).

    Raises:
        ValueError: the message is malformed or x, y, z are not all FLOAT32 fields.
    """
    stamp_ns, frame_id, xyz, _ = decode_timed(data)
    return stamp_ns, frame_id, xyz


_DECOMPRESS: dict[str, Callable[[bytes, int], bytes]] = {
    "": lambda data, size: data,
    "zstd": lambda data, size: zstandard.ZstdDecompressor().decompress(data, max_output_size=size),
    "lz4": lambda data, size: lz4.frame.decompress(data),
}
_MESSAGE_OPCODE = 0x05
_MAX_RUNS = 4  # more interleaved chunk runs than this: the generic reader
_CHUNK_OPCODE = 0x06
# decompressed chunks a reader keeps: iterators over several topics of one reader that move
# through the log together (a LiDAR's and an Avia's frames) decompress each chunk once
_CHUNKS_KEPT = 4


def _chunk_data(record: bytes, offset: int) -> bytes:
    """The decompressed records of one MCAP Chunk record (opcode, length and body).

    The chunk's CRC is checked when the writer stored one.

    Raises:
        ValueError: the record is not a chunk, is truncated, or fails its CRC.
    """
    if len(record) < 9 or record[0] != _CHUNK_OPCODE:
        raise ValueError(f"no chunk record at byte {offset}")
    pos = 9
    _, _, size, crc, name_len = struct.unpack_from("<QQQII", record, pos)
    pos += 32
    compression = record[pos : pos + name_len].decode()
    pos += name_len
    (data_len,) = struct.unpack_from("<Q", record, pos)
    pos += 8
    if pos + data_len > len(record):
        raise ValueError(f"chunk at byte {offset} is truncated")
    data = _DECOMPRESS[compression](record[pos : pos + data_len], size)
    if len(data) != size:
        raise ValueError(f"chunk at byte {offset} decompressed to {len(data)} bytes, not {size}")
    if crc and zlib.crc32(data) != crc:
        raise ValueError(f"chunk at byte {offset} fails its CRC check")
    return data


def _chunk_messages(data: bytes, offset: int, ids: set[int] | None) -> list[Message]:
    """The messages of one chunk's decompressed records (:func:`_chunk_data`), in log-time order.

    Parses the records with ``struct.unpack_from``, skipping schema and channel records (the
    summary has them) and channels not in ``ids``.

    Raises:
        ValueError: a record is truncated.
    """
    view = memoryview(data)
    messages: list[Message] = []
    pos, end = 0, len(data)
    unpack = struct.unpack_from
    while pos < end:
        opcode = data[pos]
        (length,) = unpack("<Q", data, pos + 1)
        body = pos + 9
        pos = body + length
        if pos > end:
            raise ValueError(f"chunk at byte {offset} holds a truncated record")
        if opcode != _MESSAGE_OPCODE:
            continue
        channel_id, sequence, log_time, publish_time = unpack("<HIQQ", data, body)
        if ids is not None and channel_id not in ids:
            continue
        messages.append(
            Message(channel_id, log_time, bytes(view[body + 22 : pos]), publish_time, sequence)
        )
    if any(a.log_time > b.log_time for a, b in zip(messages, messages[1:], strict=False)):
        messages.sort(key=lambda m: m.log_time)
    return messages


def _scan_summary(path: Path) -> Summary:
    """The summary of a log written without one, from reading every record (chunks expanded).

    Schemas, channels and statistics (message counts per channel, time range); no chunk index,
    so messages are then read by the generic reader, front to back.
    """
    summary = Summary()
    counts: dict[int, int] = {}
    start = end = None
    n_metadata = n_attachments = 0
    with open(path, "rb") as f:
        for record in StreamReader(f, validate_crcs=True).records:
            if isinstance(record, Schema):
                summary.schemas[record.id] = record
            elif isinstance(record, Channel):
                summary.channels[record.id] = record
            elif isinstance(record, Message):
                counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
                start = record.log_time if start is None else min(start, record.log_time)
                end = record.log_time if end is None else max(end, record.log_time)
            elif isinstance(record, Metadata):
                n_metadata += 1
            elif isinstance(record, Attachment):
                n_attachments += 1
    summary.statistics = Statistics(
        message_count=sum(counts.values()),
        schema_count=len(summary.schemas),
        channel_count=len(summary.channels),
        attachment_count=n_attachments,
        metadata_count=n_metadata,
        chunk_count=0,  # no chunk index: the generic reader reads them in file order
        message_start_time=start or 0,
        message_end_time=end or 0,
        channel_message_counts=counts,
    )
    return summary


class LogReader:
    """An open MCAP log: topics, metadata and typed iterators over its channels.

    Open with :func:`open_log`; use as a context manager (or call :meth:`close`).

    Raises:
        LogError: the file is missing, not MCAP, truncated or corrupt.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        try:
            self._file: IO[bytes] = open(self.path, "rb")  # noqa: SIM115 - closed in close()
        except OSError as err:
            raise LogError(f"cannot open MCAP log {self.path}: {err.strerror or err}") from err
        try:
            reader = make_reader(self._file, validate_crcs=True)  # catches corrupt chunks
            reader.get_header()  # annotate copies it unparsed: it must be readable
            summary = reader.get_summary()
        except _UNREADABLE as err:
            self._file.close()
            raise LogError(
                f"{self.path} is not a readable MCAP log (truncated or corrupt): {_reason(err)}"
            ) from err
        if not isinstance(reader, SeekingReader):
            self._file.close()
            raise LogError(f"{self.path} is not a seekable file: expected an MCAP log on disk")
        if summary is None:  # the summary is optional in MCAP: learn the same from a scan
            try:
                summary = _scan_summary(self.path)
            except OSError as err:
                self._file.close()
                raise LogError(f"cannot read {self.path}: {err.strerror or err}") from err
            except CORRUPT_ERRORS as err:
                self._file.close()
                raise LogError(
                    f"{self.path} has no summary section and cannot be read through "
                    f"(truncated or corrupt): {_reason(err)}"
                ) from err
        self._reader = reader
        self._summary: Summary = summary
        self._chunks: OrderedDict[int, bytes] = OrderedDict()  # offset -> decompressed records

    def __enter__(self) -> LogReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Close the file."""
        self._file.close()

    # --- what is in the log ------------------------------------------------------------------
    def list_topics(self) -> dict[str, int]:
        """Message count per topic (topics in channel order)."""
        counts: dict[int, int] = {}
        if self._summary.statistics is not None:
            counts = dict(self._summary.statistics.channel_message_counts)
        out: dict[str, int] = {}
        for channel_id, channel in self._summary.channels.items():
            out[channel.topic] = out.get(channel.topic, 0) + counts.get(channel_id, 0)
        return out

    def schema_name(self, topic: str) -> str:
        """The schema name of ``topic`` (e.g. ``foxglove.PointCloud``).

        Raises:
            LogError: the topic is not in the log (the message lists those that are).
        """
        for channel in self._summary.channels.values():
            if channel.topic == topic:
                schema = self._summary.schemas.get(channel.schema_id)
                return schema.name if schema is not None else ""
        raise self._missing(topic)

    def topic_types(self) -> dict[str, str]:
        """The schema name of every topic (``""`` for schemaless channels), in channel order."""
        out: dict[str, str] = {}
        for channel in self._summary.channels.values():
            schema = self._summary.schemas.get(channel.schema_id)
            out.setdefault(channel.topic, schema.name if schema is not None else "")
        return out

    def time_range(self) -> tuple[int, int]:
        """First and last message log times, integer ns (0, 0 for an empty log)."""
        stats = self._summary.statistics
        if stats is None or stats.message_count == 0:
            return 0, 0
        return stats.message_start_time, stats.message_end_time

    def metadata(self) -> dict[str, dict[str, str]]:
        """Every metadata record, by name (a later record of the same name wins)."""
        return dict(self.metadata_records())

    def source(self) -> tuple[str, str]:
        """(sequence, split) from the log's ``cldet.source`` metadata (split "" when not said).

        Raises:
            LogError: the metadata names no sequence (the log was not written by
                ``cldet convert``).
        """
        source = self.metadata().get(topics.METADATA_SOURCE, {})
        sequence = source.get("sequence", "").strip()
        if not sequence:
            raise LogError(
                f"{self.path}: no sequence name in its {topics.METADATA_SOURCE!r} metadata: "
                "expected a log written by `cldet convert` (and `cldet annotate`)"
            )
        return sequence, source.get("split", "").strip()

    def header(self) -> Header:
        """The log's header record (profile and writing library)."""
        try:
            return self._reader.get_header()
        except _UNREADABLE as err:
            raise LogError(
                f"cannot read the header of {self.path} (corrupt): {_reason(err)}"
            ) from err

    def chunk_compression(self) -> str:
        """The compression of the log's first chunk ("zstd", "lz4" or "" for none)."""
        chunks = self._summary.chunk_indexes
        return chunks[0].compression if chunks else ""

    def metadata_records(self) -> list[tuple[str, dict[str, str]]]:
        """Every metadata record in file order, as (name, key/value strings)."""
        try:
            return [(m.name, dict(m.metadata)) for m in self._reader.iter_metadata()]
        except _UNREADABLE as err:
            raise LogError(
                f"cannot read metadata of {self.path} (corrupt): {_reason(err)}"
            ) from err

    def attachments(self) -> Iterator[Attachment]:
        """Every attachment record of the log."""
        try:
            yield from self._reader.iter_attachments()
        except _UNREADABLE as err:
            raise LogError(
                f"cannot read attachments of {self.path} (corrupt): {_reason(err)}"
            ) from err

    def _missing(self, topic: str) -> LogError:
        existing = self.list_topics()
        listing = ", ".join(f"{t} ({n})" for t, n in existing.items()) or "none"
        return LogError(f"{self.path} has no topic {topic}; topics in the file: {listing}")

    def _require(self, topic: str, schemas: Iterable[str]) -> None:
        wanted = tuple(schemas)
        name = self.schema_name(topic)
        if name not in wanted:
            raise LogError(
                f"{self.path}: topic {topic} carries {name or 'schemaless messages'}, "
                f"expected {' or '.join(wanted)}"
            )

    def records(self) -> Iterator[Any]:
        """Every record of the file in file order, chunks expanded (``mcap.records`` objects).

        Unlike the indexed readers this sees everything, messages outside chunks included.
        """
        try:
            with open(self.path, "rb") as f:
                yield from StreamReader(f, validate_crcs=True).records
        except OSError as err:
            raise LogError(f"cannot read {self.path}: {err.strerror or err}") from err
        except CORRUPT_ERRORS as err:
            raise LogError(
                f"cannot read {self.path} record by record (corrupt): {_reason(err)}"
            ) from err

    # --- the raw file (cldet.io.rewrite continues it) ----------------------------------------
    @property
    def summary(self) -> Summary:
        """The log's summary (from its summary section, or a scan when it has none)."""
        return self._summary

    @property
    def stream(self) -> IO[bytes]:
        """The open log file (binary, seekable), to copy its bytes; closed by :meth:`close`."""
        return self._file

    # --- messages ----------------------------------------------------------------------------
    def iter_messages(
        self,
        topic_names: Iterable[str] | None = None,
        *,
        start_ns: int | None = None,
        end_ns: int | None = None,
    ) -> Iterator[tuple[Schema | None, Channel, Message]]:
        """Raw messages in log-time order, optionally of some topics within ``[start_ns, end_ns)``.

        Raises:
            LogError: a chunk cannot be read (corrupt or truncated file).
        """
        if isinstance(topic_names, str):
            topic_names = [topic_names]
        wanted = None if topic_names is None else list(topic_names)
        try:
            ids = self._wanted_ids(wanted)
            runs = self._chunk_runs(ids)
            if runs is None:
                yield from self._reader.iter_messages(
                    topics=wanted, starting_at=start_ns, ending_before=end_ns
                )
            elif len(runs) == 1:
                yield from self._iter_chunks(runs[0], ids, start_ns, end_ns)
            else:  # e.g. the sources, then the results appended by `cldet annotate`
                yield from heapq.merge(
                    *(self._iter_chunks(run, ids, start_ns, end_ns) for run in runs),
                    key=lambda item: item[2].log_time,
                )
        except OSError as err:
            raise LogError(f"cannot read {self.path}: {err.strerror or err}") from err
        except CORRUPT_ERRORS as err:
            what = f"topics {', '.join(wanted)}" if wanted else "messages"
            raise LogError(
                f"cannot read {what} from {self.path} (corrupt): {_reason(err)}"
            ) from err

    def _wanted_ids(self, wanted: list[str] | None) -> set[int] | None:
        if wanted is None:
            return None
        names = set(wanted)
        return {cid for cid, ch in self._summary.channels.items() if ch.topic in names}

    def _chunk_runs(self, ids: set[int] | None) -> list[list[ChunkIndex]] | None:
        """The chunks holding channels ``ids`` (None: all), as runs that do not overlap in time.

        Each run can be read chunk after chunk with :func:`_chunk_messages`, far faster than the
        generic reader (which parses every record field by field); the runs are merged by time.
        A log written by cldet has one run per writer (the sources, the appended results).
        None when the log has no chunk index, a compression is unknown, or the chunks
        interleave too much: then the generic reader is used. It does not see messages
        written outside chunks (a chunked writer writes none).
        """
        stats = self._summary.statistics
        chunks = self._summary.chunk_indexes
        if not chunks or stats is None or stats.chunk_count != len(chunks):
            return None
        if any(c.compression not in _DECOMPRESS for c in chunks):
            return None
        relevant = sorted(
            (
                c
                for c in chunks
                if ids is None
                or not c.message_index_offsets
                or not ids.isdisjoint(c.message_index_offsets)
            ),
            key=lambda c: (c.message_start_time, c.message_end_time),
        )
        runs: list[list[ChunkIndex]] = []
        for chunk in relevant:
            run = next(
                (r for r in runs if r[-1].message_end_time <= chunk.message_start_time), None
            )
            if run is None:
                if len(runs) == _MAX_RUNS:
                    return None
                runs.append([chunk])
            else:
                run.append(chunk)
        return runs or [[]]

    def _iter_chunks(
        self,
        run: list[ChunkIndex],
        ids: set[int] | None,
        start_ns: int | None,
        end_ns: int | None,
    ) -> Iterator[tuple[Schema | None, Channel, Message]]:
        channels = self._summary.channels
        schemas = self._summary.schemas
        if ids is not None and not ids:
            return
        for index in run:
            if start_ns is not None and index.message_end_time < start_ns:
                continue
            if end_ns is not None and index.message_start_time >= end_ns:
                break
            offset = index.chunk_start_offset
            data = self._chunks.get(offset)
            if data is None:
                self._file.seek(offset)
                data = _chunk_data(self._file.read(index.chunk_length), offset)
                self._chunks[offset] = data
                if len(self._chunks) > _CHUNKS_KEPT:
                    self._chunks.popitem(last=False)
            else:
                self._chunks.move_to_end(offset)
            for message in _chunk_messages(data, offset, ids):
                if start_ns is not None and message.log_time < start_ns:
                    continue
                if end_ns is not None and message.log_time >= end_ns:
                    continue
                channel = channels[message.channel_id]
                yield schemas.get(channel.schema_id), channel, message

    def _decoded(
        self, topic: str, schemas: tuple[str, ...], start_ns: int | None, end_ns: int | None
    ) -> Iterator[tuple[Message, Any]]:
        """(raw message, decoded payload) pairs; decoding errors become LogError."""
        self._require(topic, schemas)
        for schema, _channel, message in self.iter_messages(
            [topic], start_ns=start_ns, end_ns=end_ns
        ):
            yield message, schema.name if schema is not None else ""

    def iter_clouds(
        self, topic: str, *, start_ns: int | None = None, end_ns: int | None = None
    ) -> Iterator[Cloud]:
        """The clouds of a ``foxglove.PointCloud`` topic: (N, 3) float32 read-only views (and the
        points' times where the messages have a ``time`` field).

        Raises:
            LogError: the topic is missing, is not a point cloud topic, or a message is corrupt.
        """
        for message, _ in self._decoded(topic, (topics.SCHEMA_POINT_CLOUD,), start_ns, end_ns):
            try:
                _, _, points, times = decode_timed(message.data)
            except CORRUPT_ERRORS as err:
                raise self.message_error(topic, message, err) from err
            yield Cloud(stamp_ns=message.log_time, points=points, times=times)

    def iter_cloud_fields(
        self, topic: str, *, start_ns: int | None = None, end_ns: int | None = None
    ) -> Iterator[tuple[int, dict[str, NDArray[np.float32]]]]:
        """``(stamp_ns, {field: (N,) float32})`` per cloud, extra fields (``cluster_id``) included."""
        for message, _ in self._decoded(topic, (topics.SCHEMA_POINT_CLOUD,), start_ns, end_ns):
            try:
                _, columns = decode_cloud(message.data)
            except CORRUPT_ERRORS as err:
                raise self.message_error(topic, message, err) from err
            yield message.log_time, columns

    def iter_positions(
        self, topic: str, *, start_ns: int | None = None, end_ns: int | None = None
    ) -> Iterator[PositionSample]:
        """Positions of a ``foxglove.PoseInFrame`` or ``cldet.Estimate`` topic, (3,) float64."""
        allowed = (topics.SCHEMA_POSE_IN_FRAME, topics.SCHEMA_ESTIMATE)
        for message, schema in self._decoded(topic, allowed, start_ns, end_ns):
            try:
                if schema == topics.SCHEMA_ESTIMATE:
                    est = EstimateMessage.FromString(message.data)
                    xyz = (est.x, est.y, est.z)
                else:
                    p = PoseInFrame.FromString(message.data).pose.position
                    xyz = (p.x, p.y, p.z)
            except CORRUPT_ERRORS as err:
                raise self.message_error(topic, message, err) from err
            yield PositionSample(stamp_ns=message.log_time, position=np.array(xyz, np.float64))

    def iter_classes(
        self, topic: str = topics.CLASS, *, start_ns: int | None = None, end_ns: int | None = None
    ) -> Iterator[ClassSample]:
        """Labels of a ``cldet.ClassLabel`` topic."""
        for message, _ in self._decoded(topic, (topics.SCHEMA_CLASS_LABEL,), start_ns, end_ns):
            try:
                label = ClassLabel.FromString(message.data)
            except CORRUPT_ERRORS as err:
                raise self.message_error(topic, message, err) from err
            yield ClassSample(stamp_ns=message.log_time, class_id=int(label.class_id))

    def iter_class_estimates(self, topic: str = topics.CLASS_ESTIMATE) -> Iterator[ClassEstimate]:
        """The drone-type estimates of a ``cldet.ClassEstimate`` topic, in log order."""
        for message, _ in self._decoded(topic, (topics.SCHEMA_CLASS_ESTIMATE,), None, None):
            try:
                msg = ClassEstimateMessage.FromString(message.data)
            except CORRUPT_ERRORS as err:
                raise self.message_error(topic, message, err) from err
            ids, probs = tuple(int(c) for c in msg.class_ids), tuple(msg.probabilities)
            if len(ids) != len(probs) or int(msg.class_id) not in ids:
                raise self.message_error(
                    topic, message, ValueError("class ids and probabilities do not match")
                )
            yield ClassEstimate(message.log_time, int(msg.class_id), ids, probs)

    def iter_estimates(
        self,
        topic: str = topics.ESTIMATE,
        *,
        start_ns: int | None = None,
        end_ns: int | None = None,
    ) -> Iterator[tuple[Estimate, int]]:
        """``(estimate, track_id)`` pairs of a ``cldet.Estimate`` topic."""
        for message, _ in self._decoded(topic, (topics.SCHEMA_ESTIMATE,), start_ns, end_ns):
            try:
                est = EstimateMessage.FromString(message.data)
                source = Source(est.source)
            except CORRUPT_ERRORS as err:
                raise self.message_error(topic, message, err) from err
            yield (
                Estimate(
                    stamp_ns=message.log_time,
                    position=np.array((est.x, est.y, est.z), np.float64),
                    source=source,
                    n_points=int(est.n_points),
                    sigma_m=float(est.sigma_m),
                ),
                int(est.track_id),
            )

    def message_error(
        self, topic: str, message: Message, err: BaseException
    ) -> CorruptMessageError:
        """The error for a message of ``topic`` that cannot be decoded (names log, topic, stamp)."""
        stamp = message.log_time
        return CorruptMessageError(
            f"{self.path}: corrupt message on {topic} stamped {format_stamp(max(stamp, 0))} "
            f"({stamp} ns): {_reason(err)}",
            log=self.path,
            topic=topic,
            stamp_ns=stamp,
        )


def open_log(path: str | os.PathLike[str]) -> LogReader:
    """Open an MCAP log for reading (use as a context manager).

    Raises:
        LogError: the file is missing, not MCAP, truncated or corrupt.
    """
    return LogReader(path)


def iter_clouds(
    path: str | os.PathLike[str],
    topic: str,
    *,
    start_ns: int | None = None,
    end_ns: int | None = None,
) -> Iterator[Cloud]:
    """The clouds of one point-cloud topic of the log at ``path``, in time order (see
    :meth:`LogReader.iter_clouds`)."""
    with open_log(path) as log:
        yield from log.iter_clouds(topic, start_ns=start_ns, end_ns=end_ns)


def iter_cloud_fields(
    path: str | os.PathLike[str], topic: str
) -> Iterator[tuple[int, dict[str, NDArray[np.float32]]]]:
    """``(stamp_ns, columns)`` per cloud of one topic (see :meth:`LogReader.iter_cloud_fields`)."""
    with open_log(path) as log:
        yield from log.iter_cloud_fields(topic)


def iter_positions(path: str | os.PathLike[str], topic: str) -> Iterator[PositionSample]:
    """The positions of one pose or estimate topic (see :meth:`LogReader.iter_positions`)."""
    with open_log(path) as log:
        yield from log.iter_positions(topic)


def iter_classes(path: str | os.PathLike[str], topic: str = topics.CLASS) -> Iterator[ClassSample]:
    """The class labels of one ``cldet.ClassLabel`` topic."""
    with open_log(path) as log:
        yield from log.iter_classes(topic)


def iter_estimates(
    path: str | os.PathLike[str], topic: str = topics.ESTIMATE
) -> Iterator[tuple[Estimate, int]]:
    """``(estimate, track_id)`` pairs of one ``cldet.Estimate`` topic."""
    with open_log(path) as log:
        yield from log.iter_estimates(topic)


def read_metadata(path: str | os.PathLike[str]) -> dict[str, dict[str, str]]:
    """Every metadata record of the log at ``path``, by name."""
    with open_log(path) as log:
        return log.metadata()


def list_topics(path: str | os.PathLike[str]) -> dict[str, int]:
    """Message count per topic of the log at ``path``."""
    with open_log(path) as log:
        return log.list_topics()
