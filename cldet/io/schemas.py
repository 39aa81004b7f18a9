"""Protobuf message types of cldet's logs: Foxglove's well-known schemas plus cldet's own.

cldet's own types (``cldet.ClassLabel``, ``cldet.Estimate``) are built at import time from a
``FileDescriptorProto`` written here in Python, so no ``protoc`` step and no generated code are
needed. Every channel stores a serialized ``FileDescriptorSet`` (the message's file and all its
dependencies) as its MCAP schema, which is what Foxglove, Rerun and
``mcap_protobuf.decoder.DecoderFactory`` expect.
"""

from __future__ import annotations

from functools import cache
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf import timestamp_pb2 as _timestamp_pb2  # registers timestamp.proto
from google.protobuf.descriptor import FileDescriptor

from cldet.io import topics

_FILE_NAME = "cldet/messages.proto"
_TIMESTAMP_FILE = _timestamp_pb2.DESCRIPTOR.name  # "google/protobuf/timestamp.proto"

_F = descriptor_pb2.FieldDescriptorProto


def _field(
    message: descriptor_pb2.DescriptorProto,
    name: str,
    number: int,
    kind: int,
    type_name: str = "",
    *,
    repeated: bool = False,
) -> None:
    field = message.field.add()
    field.name = name
    field.number = number
    field.label = _F.LABEL_REPEATED if repeated else _F.LABEL_OPTIONAL
    field.type = kind
    if type_name:
        field.type_name = type_name
    # no json_name: protobufjs (Foxglove's tools) would show it (``nPoints``) where Foxglove's
    # own decoder shows the field name (``n_points``)


def _file_descriptor_proto() -> descriptor_pb2.FileDescriptorProto:
    """The ``.proto`` file of cldet's own messages, as a descriptor (proto3, package ``cldet``)."""
    fdp = descriptor_pb2.FileDescriptorProto()
    fdp.name = _FILE_NAME
    fdp.package = "cldet"
    fdp.syntax = "proto3"
    fdp.dependency.append(_TIMESTAMP_FILE)

    label = fdp.message_type.add()
    label.name = "ClassLabel"  # the drone type of a sequence, on the ground-truth stamps
    _field(label, "timestamp", 1, _F.TYPE_MESSAGE, ".google.protobuf.Timestamp")
    _field(label, "class_id", 2, _F.TYPE_UINT32)  # 0..3

    est = fdp.message_type.add()
    est.name = "Estimate"  # the drone's estimated position at one instant
    source = est.enum_type.add()
    source.name = "Source"
    for name, number in (
        ("SOURCE_UNSPECIFIED", 0),
        ("DETECTED", 1),
        ("PREDICTED", 2),
        ("SMOOTHED", 3),
        ("FALLBACK", 4),
    ):
        value = source.value.add()
        value.name = name
        value.number = number
    _field(est, "timestamp", 1, _F.TYPE_MESSAGE, ".google.protobuf.Timestamp")
    _field(est, "x", 2, _F.TYPE_DOUBLE)  # metres, Mid-360 frame
    _field(est, "y", 3, _F.TYPE_DOUBLE)
    _field(est, "z", 4, _F.TYPE_DOUBLE)
    _field(est, "source", 5, _F.TYPE_ENUM, ".cldet.Estimate.Source")  # = cldet.types.Source
    _field(est, "n_points", 6, _F.TYPE_UINT32)  # points in the associated cluster
    _field(est, "sigma_m", 7, _F.TYPE_DOUBLE)  # 1-sigma position uncertainty, metres
    _field(est, "track_id", 8, _F.TYPE_UINT32)
    cls = fdp.message_type.add()
    cls.name = "ClassEstimate"  # the estimated drone type of a sequence, from the evidence so far
    _field(cls, "timestamp", 1, _F.TYPE_MESSAGE, ".google.protobuf.Timestamp")
    _field(cls, "class_id", 2, _F.TYPE_UINT32)  # the most probable class
    _field(cls, "class_ids", 3, _F.TYPE_UINT32, repeated=True)  # the classes the model knows
    _field(cls, "probabilities", 4, _F.TYPE_DOUBLE, repeated=True)  # one per class id
    return fdp


def _build() -> FileDescriptor:
    pool = descriptor_pool.Default()
    try:
        return pool.FindFileByName(_FILE_NAME)
    except KeyError:
        pass
    return pool.Add(_file_descriptor_proto())


_FILE = _build()

ClassLabel: Any = message_factory.GetMessageClass(_FILE.message_types_by_name["ClassLabel"])
"""``cldet.ClassLabel``: ``timestamp`` (google.protobuf.Timestamp), ``class_id`` (uint32, 0..3)."""

Estimate: Any = message_factory.GetMessageClass(_FILE.message_types_by_name["Estimate"])
"""``cldet.Estimate``: ``timestamp``, ``x``/``y``/``z`` (double, metres), ``source`` (enum
``Estimate.Source``: 1 detected, 2 predicted, 3 smoothed, 4 fallback, as :class:`cldet.types.Source`),
``n_points`` (uint32), ``sigma_m`` (double, metres), ``track_id`` (uint32)."""

ClassEstimateMessage: Any = message_factory.GetMessageClass(
    _FILE.message_types_by_name["ClassEstimate"]
)
"""``cldet.ClassEstimate``: ``timestamp``, ``class_id`` (uint32, the most probable),
``class_ids`` (repeated uint32) and ``probabilities`` (repeated double, one per class id)."""

assert ClassLabel.DESCRIPTOR.full_name == topics.SCHEMA_CLASS_LABEL
assert Estimate.DESCRIPTOR.full_name == topics.SCHEMA_ESTIMATE
assert ClassEstimateMessage.DESCRIPTOR.full_name == topics.SCHEMA_CLASS_ESTIMATE


@cache
def file_descriptor_set(message_class: Any) -> bytes:
    """The serialized ``FileDescriptorSet`` of a protobuf message type: its MCAP schema data.

    Holds the message's ``.proto`` file and, before it, every file it depends on (each once).
    Cached per type, so building a schema costs nothing after the first call.
    """
    fds = descriptor_pb2.FileDescriptorSet()
    seen: set[str] = set()

    def add(file: FileDescriptor) -> None:
        for dep in file.dependencies:
            if dep.name not in seen:
                add(dep)
        if file.name not in seen:
            seen.add(file.name)
            file.CopyToProto(fds.file.add())

    add(message_class.DESCRIPTOR.file)
    return fds.SerializeToString()
