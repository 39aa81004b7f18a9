"""Streaming reader of the MMAUD / UG2+ challenge layout: ``ROOT/{train,val,test}/seqNNNN/<modality>/``.

Every modality folder holds one file per instant, named ``<stamp>.npy`` (``Image``: ``<stamp>.png``),
where ``<stamp>`` is Unix seconds with 6 decimals (or fewer, when written by a float print).
Stamps are parsed from the name string to integer nanoseconds (:func:`cldet.stamps.parse_stamp`),
never through a float. Only file names are listed up front; data are loaded one frame at a time,
so a whole sequence (or split) is never held in memory.

Every error raised on purpose is a :class:`cldet.errors.DatasetError` whose message names the
file or folder at fault and says what was expected.
"""

from __future__ import annotations

import heapq
import os
import re
import stat
import warnings
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeAlias

import numpy as np
from numpy.typing import NDArray

from cldet.errors import DatasetError
from cldet.stamps import parse_stamp, row_times
from cldet.types import ClassSample, Cloud, ImageFrame, PositionSample

__all__ = [
    "CLOUD_MODALITIES",
    "MODALITIES",
    "PNG_SIGNATURE",
    "SPLITS",
    "Item",
    "SequenceProblem",
    "SequenceRef",
    "canonical_sequence_name",
    "count_frames",
    "find_sequences",
    "iter_classes",
    "iter_clouds",
    "iter_ground_truth",
    "iter_images",
    "iter_positions",
    "iter_sequence",
    "list_stamped_files",
    "load_cloud",
    "load_timed_cloud",
    "scan_sequences",
]

SPLITS = ("train", "val", "test")
CLOUD_MODALITIES = ("lidar_360", "livox_avia", "radar_enhance_pcl")
LIDAR_MODALITIES = ("lidar_360", "livox_avia")  # arrays of a scan's shots in firing order
MODALITIES = CLOUD_MODALITIES + ("ground_truth", "class", "Image")

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
NUM_CLASSES = 4  # class ids 0..3 (drone type)

Item: TypeAlias = Cloud | PositionSample | ClassSample | ImageFrame

_SEQ_RE = re.compile(r"seq(\d+)", re.ASCII)
_MAX_LISTED = 20  # names listed in an error message before abbreviating


@dataclass(frozen=True)
class SequenceRef:
    """One sequence folder of the challenge layout, as found on disk (names only, no data)."""

    split: str  # "train" | "val" | "test"
    name: str  # canonical "seq0001" (a folder "seq1" is reported as "seq0001")
    path: Path  # the sequence folder as found on disk
    modalities: tuple[str, ...]  # sub-folders present, in MODALITIES order


# --------------------------------------------------------------------------- names and folders


def canonical_sequence_name(name: str) -> str:
    """Return the canonical sequence name: ``"seq1"`` and ``"seq0001"`` both give ``"seq0001"``.

    Raises:
        DatasetError: ``name`` is not ``seq`` followed by digits.
    """
    canonical = _canonical_or_none(name)
    if canonical is None:
        raise DatasetError(
            f"{name!r} is not a sequence name: expected 'seq' and digits, like 'seq0001' or 'seq1'"
        )
    return canonical


def _canonical_or_none(name: str) -> str | None:
    match = _SEQ_RE.fullmatch(name)
    if match is None:
        return None
    return f"seq{int(match.group(1)):04d}"


def _sequence_number(name: str) -> int:
    return int(name[3:])


def _as_tuple(values: Sequence[str] | str) -> tuple[str, ...]:
    # A lone string is one value, not a sequence of characters.
    return (values,) if isinstance(values, str) else tuple(values)


def _listing(names: Iterable[str]) -> str:
    items = list(names)
    if not items:
        return "(none)"
    if len(items) > _MAX_LISTED:
        return ", ".join(items[:_MAX_LISTED]) + f", ... ({len(items)} in all)"
    return ", ".join(items)


def _visible_entries(folder: Path) -> list[os.DirEntry[str]]:
    """Non-hidden entries of ``folder``, sorted by name (names only, nothing is opened)."""
    try:
        with os.scandir(folder) as entries:
            return sorted((e for e in entries if not e.name.startswith(".")), key=lambda e: e.name)
    except OSError as err:
        raise DatasetError(f"cannot list folder {folder}: {err}") from err


def _has_visible_entry(folder: Path) -> bool:
    try:
        with os.scandir(folder) as entries:
            return any(not e.name.startswith(".") for e in entries)
    except OSError as err:
        raise DatasetError(f"cannot list folder {folder}: {err}") from err


def _is_regular_file(entry: os.DirEntry[str]) -> bool:
    try:
        return entry.is_file()  # follows a symbolic link to its target
    except OSError:
        return False


def _kind(path: Path) -> str:
    """What a non-regular directory entry is, in words (for messages)."""
    try:
        mode = path.stat().st_mode
    except OSError:
        return "a broken symbolic link" if path.is_symlink() else "unreadable"
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "not a file"


def _suffix(modality: str) -> str:
    return ".png" if modality == "Image" else ".npy"


def find_sequences(
    root: Path,
    splits: Sequence[str] | None = None,
    sequences: Sequence[str] | None = None,
) -> list[SequenceRef]:
    """Find the sequence folders of a challenge dataset root, sorted by split then name.

    Only folder names are read. Top-level folders other than ``train``/``val``/``test`` are ignored
    with a warning, as are folders in a split that are not named ``seq<digits>`` and folders in a
    sequence that are not modalities. :func:`scan_sequences` is the lenient form: it reports an
    unusable sequence folder instead of raising.

    Args:
        root: the dataset root, holding ``train/``, ``val/`` and/or ``test/``.
        splits: splits to search (default: every split present); each must exist.
        sequences: sequence names to keep, ``"seq1"`` or ``"seq0001"`` form (default: all);
            each must exist in at least one of the searched splits.

    Returns:
        One :class:`SequenceRef` per sequence folder.

    Raises:
        DatasetError: the root is missing or not a folder; a split is unknown or missing; no
            sequence is found; a requested sequence is not found; two folders name the same
            sequence; a sequence has no modality folder, or only empty ones ("empty sequence").
    """
    found, problems = scan_sequences(root, splits=splits, sequences=sequences)
    if problems:
        raise DatasetError(problems[0].message)
    return found


@dataclass(frozen=True)
class SequenceProblem:
    """A sequence folder that cannot be converted; the others still can."""

    split: str
    name: str  # canonical "seq0001"
    message: str  # names the folder(s) at fault


def scan_sequences(
    root: Path,
    splits: Sequence[str] | None = None,
    sequences: Sequence[str] | None = None,
) -> tuple[list[SequenceRef], list[SequenceProblem]]:
    """Find the sequence folders like :func:`find_sequences`, reporting unusable ones apart.

    An empty sequence (no modality folder, or only empty ones) and two folders naming one
    sequence (``seq2`` beside ``seq0002``) are returned as problems, so that one bad folder does
    not stop a whole dataset.

    Returns:
        (usable sequences sorted by split then name, problems in the same order).

    Raises:
        DatasetError: the root is missing or not a folder; a split is unknown or missing; no
            sequence folder is found; a requested sequence is not found.
    """
    root = Path(root)
    if not root.exists():
        raise DatasetError(
            f"dataset root {root} does not exist: expected a folder holding train/, val/ and/or test/"
        )
    if not root.is_dir():
        raise DatasetError(
            f"dataset root {root} is not a folder: expected a folder holding train/, val/ and/or test/"
        )

    top = [e.name for e in _visible_entries(root) if e.is_dir()]
    unknown = [name for name in top if name not in SPLITS]
    if unknown:
        warnings.warn(
            f"ignoring folders in {root} that are not a split (train, val, test): {_listing(unknown)}",
            stacklevel=2,
        )
    present = [s for s in SPLITS if s in top]
    if splits is None:
        wanted_splits = present
        if not wanted_splits:
            raise DatasetError(
                f"no split folder in dataset root {root}: expected train/, val/ and/or test/"
            )
    else:
        wanted_splits = []
        for split in _as_tuple(splits):
            if split not in SPLITS:
                raise DatasetError(f"unknown split {split!r}: expected one of {', '.join(SPLITS)}")
            if split not in present:
                raise DatasetError(
                    f"split folder {root / split} not found; splits present in {root}: {_listing(present)}"
                )
            if split not in wanted_splits:
                wanted_splits.append(split)

    folders: list[tuple[str, str, list[Path]]] = []  # (split, canonical name, its folders)
    for split in wanted_splits:
        split_dir = root / split
        by_name: dict[str, list[Path]] = {}
        others: list[str] = []
        for entry in _visible_entries(split_dir):
            if not entry.is_dir():
                continue  # e.g. test_timestamps.csv
            canonical = _canonical_or_none(entry.name)
            if canonical is None:
                others.append(entry.name)
                continue
            by_name.setdefault(canonical, []).append(Path(entry.path))
        if others:
            warnings.warn(
                f"ignoring folders in {split_dir} that are not sequences (seqNNNN): {_listing(others)}",
                stacklevel=2,
            )
        folders.extend((split, name, paths) for name, paths in by_name.items())

    where = f"{root} (split{'s' if len(wanted_splits) > 1 else ''} {', '.join(wanted_splits)})"
    if sequences is not None:
        wanted_names = {canonical_sequence_name(s) for s in _as_tuple(sequences)}
        existing = sorted({name for _, name, _ in folders}, key=_sequence_number)
        missing = sorted(wanted_names.difference(existing), key=_sequence_number)
        if missing:
            raise DatasetError(
                f"sequence{'s' if len(missing) > 1 else ''} {', '.join(missing)} not found in {where}; "
                f"sequences present: {_listing(existing)}"
            )
        folders = [item for item in folders if item[1] in wanted_names]
    if not folders:
        raise DatasetError(f"no sequence found in {where}: expected folders named seqNNNN")

    folders.sort(key=lambda item: (SPLITS.index(item[0]), _sequence_number(item[1])))
    found: list[SequenceRef] = []
    problems: list[SequenceProblem] = []
    for split, name, paths in folders:
        if len(paths) > 1:
            names = " and ".join(p.name for p in paths)
            message = f"two folders in {root / split} name sequence {name}: {names}"
            problems.append(SequenceProblem(split, name, message))
            continue
        try:
            modalities = _present_modalities(paths[0])
        except DatasetError as err:
            problems.append(SequenceProblem(split, name, str(err)))
            continue
        found.append(SequenceRef(split=split, name=name, path=paths[0], modalities=modalities))
    return found, problems


def _present_modalities(path: Path) -> tuple[str, ...]:
    entries = _visible_entries(path)
    others = [e.name for e in entries if e.is_dir() and e.name not in MODALITIES]
    if others:
        hints = []
        for name in others:
            close = [m for m in MODALITIES if m.casefold() == name.casefold()]
            hints.append(f"{name} (did you mean {close[0]}?)" if close else name)
        warnings.warn(
            f"ignoring folders in {path} that are not modalities ({', '.join(MODALITIES)}): "
            f"{_listing(hints)}",
            stacklevel=3,
        )
    modalities = tuple(m for m in MODALITIES if (path / m).is_dir())
    if not modalities:
        raise DatasetError(
            f"empty sequence {path}: no modality folder, expected at least one of {', '.join(MODALITIES)}"
        )
    if not any(_has_visible_entry(path / m) for m in modalities):
        raise DatasetError(
            f"empty sequence {path}: its modality folders ({', '.join(modalities)}) are all empty"
        )
    return modalities


def list_stamped_files(folder: Path, suffix: str = ".npy") -> list[tuple[int, Path]]:
    """List the ``<stamp><suffix>`` files of a folder, sorted by stamp (names only, no data loaded).

    Hidden files (``.``-prefixed) are ignored.

    Args:
        folder: a modality folder.
        suffix: the file extension, with its dot.

    Returns:
        ``(stamp_ns, path)`` pairs, stamps in integer nanoseconds, ascending.

    Raises:
        DatasetError: the folder is missing; an entry is not named ``<stamp><suffix>``; two files
            name the same instant (e.g. ``1706255621.71419.npy`` and ``1706255621.714190.npy``).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise DatasetError(f"folder {folder} not found: expected a folder of <stamp>{suffix} files")
    stamped: list[tuple[int, Path]] = []
    for entry in _visible_entries(folder):
        name = entry.name
        path = Path(entry.path)
        if not _is_regular_file(entry):
            raise DatasetError(
                f"{path} is {_kind(path)}, not a regular file: expected a <stamp>{suffix} file"
            )
        if not name.endswith(suffix) or len(name) == len(suffix):
            raise DatasetError(
                f"unexpected file {path}: expected a <stamp>{suffix} file, like 1706255621.600227{suffix}"
            )
        try:
            stamp_ns = parse_stamp(name[: -len(suffix)])
        except DatasetError as err:
            raise DatasetError(f"file name {path} is not a timestamp: {err}") from err
        stamped.append((stamp_ns, path))
    stamped.sort(key=lambda item: item[0])
    for (stamp_a, path_a), (stamp_b, path_b) in zip(stamped, stamped[1:], strict=False):
        if stamp_a == stamp_b:
            raise DatasetError(
                f"duplicate stamps in {folder}: {path_a.name} and {path_b.name} name the same instant "
                f"({stamp_a} ns)"
            )
    return stamped


# --------------------------------------------------------------------------- loading one file


def _load_array(path: Path) -> NDArray[Any]:
    """``np.load`` one ``.npy`` file (no pickles), every failure turned into a DatasetError."""
    try:
        # Our own handle: np.load leaks its file when a "PK" (zip) prefix turns out corrupt.
        with open(path, "rb") as stream:
            loaded = np.load(stream, allow_pickle=False)
    except OSError as err:
        raise DatasetError(f"cannot read {path}: {err}") from err
    except Exception as err:  # numpy raises ValueError, EOFError, BadZipFile, TokenError, ...
        raise DatasetError(
            f"cannot read {path}: truncated or corrupt .npy file ({type(err).__name__}: {err})"
        ) from err
    if not isinstance(loaded, np.ndarray):  # an .npz archive
        close = getattr(loaded, "close", None)
        if close is not None:
            close()
        raise DatasetError(f"cannot read {path}: expected a .npy array, found an .npz archive")
    return loaded


def _check_real(array: NDArray[Any], path: Path, expected: str) -> None:
    if array.dtype.kind not in "fiu":
        raise DatasetError(f"{path}: expected {expected}, got non-numeric dtype {array.dtype}")


def _check_finite(array: NDArray[Any], source: NDArray[Any], path: Path) -> None:
    """Raise when ``array`` (converted from ``source``) holds a NaN or an infinity."""
    if np.isfinite(array).all():
        return
    n_nan = int(np.isnan(source).sum()) if source.dtype.kind == "f" else 0
    n_inf = int(np.isinf(source).sum()) if source.dtype.kind == "f" else 0
    if n_nan or n_inf:
        raise DatasetError(
            f"{path}: expected finite coordinates, found {n_nan} NaN and {n_inf} infinite values"
        )
    raise DatasetError(
        f"{path}: expected finite coordinates, found values beyond the float32 range"
    )


def load_cloud(path: Path) -> NDArray[np.float32]:
    """Load one point-cloud file and keep its valid rows (``load_timed_cloud`` without times)."""
    return load_timed_cloud(path)[0]


def load_timed_cloud(path: Path) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Load one point-cloud file, keep its valid rows, and date them by their rows.

    Rows that are exactly zero, ``(0, 0, 0)`` in any sign of zero (the Mid-360's and the Avia's
    "no return"), are dropped. A 1-D array of shape ``(0,)`` (the radar's empty frame) is an
    empty cloud.

    Args:
        path: a ``<stamp>.npy`` file holding an ``(N, 3)`` real array, x, y, z metres.

    Returns:
        ``(M, 3)`` float32, C-contiguous, metres, M <= N; ``(0, 3)`` for an empty frame; and
        ``(M,)`` float32, each kept row's firing time after the file's stamp, seconds, were the
        rows a LiDAR's scan (``cldet.stamps.row_times``: row i of N at i / N of 100 ms).

    Raises:
        DatasetError: the file is unreadable, truncated or corrupt; the array is not ``(N, 3)``
            or has a non-numeric dtype; a coordinate is NaN or infinite.
    """
    path = Path(path)
    array = _load_array(path)
    expected = "an (N, 3) float array"
    _check_real(array, path, expected)
    if array.shape == (0,):  # the radar's empty frame
        return np.empty((0, 3), dtype=np.float32), np.empty(0, dtype=np.float32)
    if array.ndim != 2 or array.shape[1] != 3:
        raise DatasetError(f"{path}: expected {expected}, got shape {array.shape}")
    # Valid rows: any coordinate non-zero (-0.0 != 0 is False, so both zero forms are dropped).
    # Column-wise compares and take() measured faster than np.any(axis=1) and boolean indexing.
    valid = array[:, 0] != 0
    valid |= array[:, 1] != 0
    valid |= array[:, 2] != 0
    rows = np.flatnonzero(valid)
    with np.errstate(over="ignore"):  # beyond float32 range -> inf, reported just below
        points = array.take(rows, axis=0).astype(np.float32, copy=False)
    _check_finite(points, array, path)
    return np.ascontiguousarray(points), row_times(rows, len(array))


def _load_position(path: Path) -> NDArray[np.float64]:
    array = _load_array(path)
    expected = "a (3,) float array (x, y, z metres)"
    _check_real(array, path, expected)
    if array.shape != (3,):
        raise DatasetError(f"{path}: expected {expected}, got shape {array.shape}")
    position = np.ascontiguousarray(array, dtype=np.float64)
    _check_finite(position, array, path)
    return position


def _load_class(path: Path) -> int:
    array = _load_array(path)
    expected = f"a 1-D integer array whose element [0] is the class id 0..{NUM_CLASSES - 1}"
    if array.ndim != 1 or array.dtype.kind not in "iu" or array.size == 0:
        raise DatasetError(
            f"{path}: expected {expected}, got shape {array.shape} dtype {array.dtype}"
        )
    class_id = int(array[0])
    if not 0 <= class_id < NUM_CLASSES:
        raise DatasetError(f"{path}: expected {expected}, got class id {class_id}")
    return class_id


def _load_png(path: Path) -> bytes:
    try:
        data = path.read_bytes()
    except OSError as err:
        raise DatasetError(f"cannot read {path}: {err}") from err
    if not data.startswith(PNG_SIGNATURE):
        raise DatasetError(
            f"{path}: not a PNG file, bad signature {data[:8]!r} (expected {PNG_SIGNATURE!r})"
        )
    return data


# --------------------------------------------------------------------------- streaming


def _require(seq: SequenceRef, modality: str) -> Path:
    if modality not in MODALITIES:
        raise DatasetError(
            f"unknown modality {modality!r}: expected one of {', '.join(MODALITIES)}"
        )
    if modality not in seq.modalities:
        raise DatasetError(
            f"sequence {seq.split}/{seq.name} ({seq.path}) has no {modality} folder; "
            f"modalities present: {_listing(seq.modalities)}"
        )
    return seq.path / modality


def iter_clouds(seq: SequenceRef, modality: str) -> Iterator[Cloud]:
    """Stream one point-cloud modality of a sequence, one frame at a time, in time order.

    File names are listed (and checked) when this is called; each frame is loaded only when the
    iterator reaches it (see :func:`load_cloud`).

    Args:
        seq: the sequence.
        modality: one of :data:`CLOUD_MODALITIES`.

    Returns:
        An iterator of :class:`Cloud` (``stamp_ns`` in integer nanoseconds, valid points only).

    Raises:
        DatasetError: the modality is not a cloud modality or is absent from the sequence; a file
            name is bad; (while iterating) a file is bad.
    """
    if modality not in CLOUD_MODALITIES:
        raise DatasetError(
            f"{modality!r} is not a point-cloud modality: expected one of {', '.join(CLOUD_MODALITIES)}"
        )
    files = list_stamped_files(_require(seq, modality))
    if modality not in LIDAR_MODALITIES:  # the radar's rows are targets, not a scan's shots
        return (Cloud(stamp_ns=stamp_ns, points=load_cloud(path)) for stamp_ns, path in files)
    return (Cloud(stamp_ns, *load_timed_cloud(path)) for stamp_ns, path in files)


def iter_positions(folder: Path) -> Iterator[PositionSample]:
    """Stream a folder of ``<stamp>.npy`` positions, each a ``(3,)`` float array, in time order.

    Used for ``ground_truth/`` and for reference tracks (e.g. ``reference/seq0001``), whose names
    may be float-printed (``1706255621.71419.npy``).

    Returns:
        An iterator of :class:`PositionSample` (``stamp_ns`` in integer nanoseconds, float64 metres).

    Raises:
        DatasetError: the folder is missing; a file name is bad; (while iterating) a file is
            unreadable, not ``(3,)`` numeric, or not finite.
    """
    files = list_stamped_files(Path(folder))
    return (
        PositionSample(stamp_ns=stamp_ns, position=_load_position(path)) for stamp_ns, path in files
    )


def iter_ground_truth(seq: SequenceRef) -> Iterator[PositionSample]:
    """Stream a sequence's ground-truth positions (train only), in time order.

    Raises:
        DatasetError: the sequence has no ``ground_truth`` folder (check ``seq.modalities``);
            otherwise as :func:`iter_positions`.
    """
    return iter_positions(_require(seq, "ground_truth"))


def iter_classes(seq: SequenceRef) -> Iterator[ClassSample]:
    """Stream a sequence's class labels (train only), in time order.

    Each file is a 1-D integer array; element ``[0]`` is the drone type, 0..3.

    Raises:
        DatasetError: the sequence has no ``class`` folder; a file name is bad; (while iterating)
            a file is not a non-empty 1-D integer array or its class id is outside 0..3.
    """
    files = list_stamped_files(_require(seq, "class"))
    return (ClassSample(stamp_ns=stamp_ns, class_id=_load_class(path)) for stamp_ns, path in files)


def iter_images(seq: SequenceRef) -> Iterator[ImageFrame]:
    """Stream a sequence's camera images as PNG bytes (never decoded), in time order.

    Raises:
        DatasetError: the sequence has no ``Image`` folder; a file name is not ``<stamp>.png``;
            (while iterating) a file is unreadable or does not start with the PNG signature.
    """
    files = list_stamped_files(_require(seq, "Image"), suffix=".png")
    return (ImageFrame(stamp_ns=stamp_ns, png=_load_png(path)) for stamp_ns, path in files)


def _iter_modality(seq: SequenceRef, modality: str) -> Iterator[Item]:
    if modality in CLOUD_MODALITIES:
        return iter_clouds(seq, modality)
    if modality == "ground_truth":
        return iter_ground_truth(seq)
    if modality == "class":
        return iter_classes(seq)
    return iter_images(seq)


def _keyed(
    index: int, modality: str, items: Iterator[Item]
) -> Iterator[tuple[int, int, str, Item]]:
    for item in items:
        yield item.stamp_ns, index, modality, item


def _unkey(merged: Iterator[tuple[int, int, str, Item]]) -> Iterator[tuple[str, Item]]:
    for _, _, modality, item in merged:
        yield modality, item


def iter_sequence(
    seq: SequenceRef, modalities: Sequence[str] | None = None
) -> Iterator[tuple[str, Item]]:
    """Stream several modalities of a sequence merged in time order, one item at a time.

    Equal stamps come in :data:`MODALITIES` order. File names of every requested modality are
    listed (and checked) when this is called; data are loaded only as the iterator advances.

    Args:
        seq: the sequence.
        modalities: the modalities to merge (default: every modality present).

    Returns:
        An iterator of ``(modality, item)``; ``item`` is a :class:`Cloud`, :class:`PositionSample`
        (ground_truth), :class:`ClassSample` (class) or :class:`ImageFrame` (Image).

    Raises:
        DatasetError: a modality is unknown or absent from the sequence; as the per-modality readers.
    """
    wanted = seq.modalities if modalities is None else _as_tuple(modalities)
    for modality in wanted:
        _require(seq, modality)
    ordered = [m for m in MODALITIES if m in wanted]
    streams = [_keyed(MODALITIES.index(m), m, _iter_modality(seq, m)) for m in ordered]
    # (stamp_ns, modality index) is unique: stamps are unique within a modality.
    return _unkey(heapq.merge(*streams))


def count_frames(seq: SequenceRef) -> dict[str, int]:
    """Count the files of every modality present in a sequence (from file names only).

    Returns:
        ``{modality: number of files}`` in :data:`MODALITIES` order.

    Raises:
        DatasetError: as :func:`list_stamped_files`.
    """
    return {m: len(list_stamped_files(seq.path / m, suffix=_suffix(m))) for m in seq.modalities}
