"""Convert the challenge dataset (folders of .npy/.png per sequence) to one MCAP log per sequence.

``OUT/<split>/<seqNNNN>.mcap`` holds one channel per modality found (see :mod:`cldet.io.topics`):
point clouds with their valid points only (float32), ground truth as poses, class labels, images
as PNG plus a camera calibration, the static frame tree on ``/tf`` (see
:mod:`cldet.io.transforms`) and a ``cldet.source`` metadata record. Every message's log
time, publish time and own timestamp are the source file's stamp in integer nanoseconds.

Conversion streams frame by frame (memory stays flat whatever the sequence length), runs
sequences in parallel (worker processes here, or Ray tasks: :mod:`cldet.executors`), writes each log to a temporary file in the output folder
and renames it into place only when complete. A bad sequence is reported and the others still
convert.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path

from cldet import __version__
from cldet.errors import CldetError, DatasetError, LogError
from cldet.executors import iter_outcomes
from cldet.io import topics
from cldet.io.files import atomic_output
from cldet.io.mcap_write import Compression, LogWriter
from cldet.io.transforms import sensor_tree
from cldet.progress import NullProgress, Progress
from cldet.stamps import format_stamp
from cldet.types import ClassSample, Cloud, ImageFrame, PositionSample
from converters import mmaud

__all__ = ["ConvertFailure", "ConvertReport", "convert_dataset", "convert_sequence"]


@dataclass(frozen=True)
class ConvertFailure:
    """A sequence that could not be converted."""

    sequence: str  # "<split>/<seqNNNN>"
    message: str  # names the file at fault


@dataclass(frozen=True)
class ConvertReport:
    """What :func:`convert_dataset` did."""

    converted: tuple[Path, ...]  # logs written
    skipped: tuple[Path, ...]  # logs that already existed (not overwritten)
    failed: tuple[ConvertFailure, ...]
    frames: int  # messages written from source files (clouds, poses, labels, images)
    bytes_in: int  # size of the source files converted
    bytes_out: int  # size of the logs written
    seconds: float  # wall time
    cpu_seconds: float = 0.0  # CPU time spent converting, summed over the worker processes

    @property
    def ok(self) -> bool:
        """True when no sequence failed."""
        return not self.failed

    def describe(self) -> str:
        """A few human-readable lines summing up the run."""
        mb_in, mb_out = self.bytes_in / 1e6, self.bytes_out / 1e6
        rate = mb_in / self.seconds if self.seconds > 0 else 0.0
        lines = [
            f"converted {len(self.converted)} sequence(s), {self.frames} frames, "
            f"{mb_in:.1f} MB -> {mb_out:.1f} MB in {self.seconds:.1f} s ({rate:.0f} MB/s)"
        ]
        if self.skipped:
            lines.append(
                f"skipped {len(self.skipped)} existing log(s) (use --overwrite to replace): "
                + ", ".join(str(p) for p in self.skipped)
            )
        if self.failed:
            lines.append(f"FAILED {len(self.failed)} sequence(s):")
            lines.extend(f"  {f.sequence}: {f.message}" for f in self.failed)
        return "\n".join(lines)


def _source_metadata(
    seq: mmaud.SequenceRef, counts: dict[str, int], modalities: Sequence[str]
) -> dict[str, str]:
    meta = {
        "split": seq.split,
        "sequence": seq.name,
        "source": str(seq.path.resolve()),
        "modalities": ",".join(modalities),
        "cldet_version": __version__,
    }
    meta.update({f"count.{m}": str(counts.get(m, 0)) for m in modalities})
    meta["frames"] = str(sum(counts.values()))
    return meta


def _modalities(seq: mmaud.SequenceRef, images: bool) -> tuple[str, ...]:
    return tuple(m for m in seq.modalities if images or m != "Image")


def convert_sequence(
    seq: mmaud.SequenceRef,
    writer: LogWriter,
    *,
    images: bool = True,
    progress: Progress | None = None,
) -> dict[str, int]:
    """Write one sequence into an open :class:`LogWriter`, frame by frame in time order.

    Clouds keep their valid rows (float32, as :func:`converters.mmaud.iter_clouds` gives them);
    each message is stamped with its file's stamp (integer ns) as log and publish time. A
    ``cldet.source`` metadata record (split, sequence, source path, counts, cldet version) is
    written last. The writer is not finished here: the caller owns it.

    Args:
        seq: the sequence, from :func:`converters.mmaud.find_sequences`.
        writer: where the messages go (e.g. over a ``BytesIO`` in tests).
        images: also convert the ``Image`` folder.
        progress: advanced by one per frame written.

    Returns:
        Frames written per modality (folder name).

    Raises:
        DatasetError: a source file is unreadable or malformed; the message names it.
    """
    bar = progress if progress is not None else NullProgress()
    modalities = _modalities(seq, images)
    counts = dict.fromkeys(modalities, 0)
    tree_written = False
    for modality, item in mmaud.iter_sequence(seq, modalities):
        topic = topics.MODALITY_TOPICS[modality]
        if not tree_written:  # the static frame tree, at the first stamp (cldet.io.transforms)
            writer.write_transforms(topics.TF, item.stamp_ns, sensor_tree())
            tree_written = True
        if isinstance(item, Cloud):
            frame = topics.MODALITY_FRAMES[modality]
            writer.write_timed_cloud(topic, item.stamp_ns, item.points, item.times, frame)
        elif isinstance(item, PositionSample):
            writer.write_pose(topic, item.stamp_ns, item.position, topics.FRAME_MID360)
        elif isinstance(item, ClassSample):
            writer.write_class(topic, item.stamp_ns, item.class_id)
        elif isinstance(item, ImageFrame):
            try:
                writer.write_image(topic, item.stamp_ns, item.png, topics.FRAME_CAMERA)
            except LogError as err:
                raise DatasetError(
                    f"{seq.path / modality}: the image stamped {format_stamp(item.stamp_ns)} "
                    f"is not a valid PNG ({err})"
                ) from err
        counts[modality] += 1
        bar.advance(1)
    writer.write_metadata(topics.METADATA_SOURCE, _source_metadata(seq, counts, modalities))
    return counts


# --- one sequence to one file (runs in a worker) ---------------------------------------------
@dataclass(frozen=True)
class _Job:
    seq: mmaud.SequenceRef
    target: Path
    compression: Compression
    images: bool
    overwrite: bool


@dataclass(frozen=True)
class _Outcome:
    job: _Job
    frames: int = 0
    bytes_in: int = 0
    bytes_out: int = 0
    error: str | None = None
    cpu_seconds: float = 0.0


def _source_bytes(seq: mmaud.SequenceRef, modalities: Sequence[str]) -> int:
    total = 0
    for modality in modalities:
        with os.scandir(seq.path / modality) as entries:
            total += sum(e.stat().st_size for e in entries if e.is_file())
    return total


def _run_job(job: _Job, progress: Progress) -> _Outcome:
    """Convert one sequence into ``job.target`` atomically; a DatasetError becomes a failure."""
    cpu_started = time.process_time()
    try:
        with (
            atomic_output(job.target, overwrite=job.overwrite) as stream,
            LogWriter(stream, compression=job.compression) as writer,
        ):
            counts = convert_sequence(job.seq, writer, images=job.images, progress=progress)
        bytes_in = _source_bytes(job.seq, _modalities(job.seq, job.images))
        return _Outcome(
            job,
            frames=sum(counts.values()),
            bytes_in=bytes_in,
            bytes_out=job.target.stat().st_size,
            cpu_seconds=time.process_time() - cpu_started,
        )
    except CldetError as err:
        return _Outcome(job, error=str(err))
    except OSError as err:  # disk full, permissions: name the file
        return _Outcome(job, error=f"{err.filename or job.target}: {err.strerror or err}")


# --- the whole dataset -----------------------------------------------------------------------
@dataclass
class _Tally:
    converted: list[Path] = field(default_factory=list)
    skipped: list[Path] = field(default_factory=list)
    failed: list[ConvertFailure] = field(default_factory=list)
    frames: int = 0
    bytes_in: int = 0
    bytes_out: int = 0
    cpu_seconds: float = 0.0

    def add(self, outcome: _Outcome) -> None:
        self.cpu_seconds += outcome.cpu_seconds
        if outcome.error is not None:
            seq = outcome.job.seq
            self.failed.append(ConvertFailure(f"{seq.split}/{seq.name}", outcome.error))
            return
        self.converted.append(outcome.job.target)
        self.frames += outcome.frames
        self.bytes_in += outcome.bytes_in
        self.bytes_out += outcome.bytes_out


def convert_dataset(
    root: Path,
    out: Path,
    *,
    splits: Sequence[str] | None = None,
    sequences: Sequence[str] | None = None,
    workers: int | None = None,
    compression: Compression | str = Compression.zstd,
    images: bool = True,
    overwrite: bool = False,
    progress: Progress | None = None,
    executor: str = "local",
    ray_address: str | None = None,
) -> ConvertReport:
    """Convert every selected sequence of a challenge dataset to ``out/<split>/<seqNNNN>.mcap``.

    Args:
        root: the dataset root (``train/``, ``val/``, ``test/`` of ``seqNNNN`` folders).
        out: the output folder (created as needed).
        splits: splits to convert (default: all present).
        sequences: sequence names to convert, ``seq0001`` or ``seq1`` (default: all).
        workers: sequences converted in parallel (default: the number of CPUs, or of the Ray
            cluster's); 1 converts in this process (with the ``local`` executor).
        compression: chunk compression of the logs, ``zstd``, ``lz4`` or ``none``.
        images: also convert the camera images (the bulk of the data).
        overwrite: replace existing logs (otherwise they are skipped and reported).
        progress: told the total number of frames, then advanced per frame.
        executor: ``local`` (worker processes here) or ``ray`` (a Ray task per sequence; see
            :mod:`cldet.executors`). The logs are the same, byte for byte.
        ray_address: with ``ray``, the cluster to join (default: a local Ray for the run).

    Returns:
        A :class:`ConvertReport`; a sequence that fails (a corrupt ``.npy``, a file that is not a
        regular file, an empty sequence folder, two folders naming one sequence) is listed in
        ``failed`` with a message naming the file or folder, and the others are still converted.

    Raises:
        DatasetError: the root, a split or a requested sequence is missing.
        LogError: ``compression`` is unknown.
        CldetError: the output folder cannot be created.
        ExecutorError: an unknown executor, Ray missing or unreachable, a worker process died.
    """
    started = time.perf_counter()
    bar = progress if progress is not None else NullProgress()
    try:
        codec = Compression(compression)
    except ValueError as err:
        choices = ", ".join(c.value for c in Compression)
        raise LogError(f"unknown compression {compression!r}: expected one of {choices}") from err
    found, problems = mmaud.scan_sequences(Path(root), splits=splits, sequences=sequences)
    out = Path(out)
    tally = _Tally()
    for problem in problems:  # an empty folder, two folders for one sequence: the others go on
        tally.failed.append(ConvertFailure(f"{problem.split}/{problem.name}", problem.message))
    jobs: list[_Job] = []
    costs: list[float] = []
    total = 0
    for seq in found:
        target = out / seq.split / f"{seq.name}.mcap"
        if target.exists() and not overwrite:
            tally.skipped.append(target)
            continue
        try:
            counts = mmaud.count_frames(seq)
        except DatasetError as err:
            tally.failed.append(ConvertFailure(f"{seq.split}/{seq.name}", str(err)))
            continue
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise CldetError(f"cannot create output folder {target.parent}: {err}") from err
        frames = sum(n for m, n in counts.items() if images or m != "Image")
        total += frames
        costs.append(frames)
        jobs.append(_Job(seq, target, codec, images, overwrite))

    bar.start(total, "converting")
    outcomes = iter_outcomes(
        _run_job,
        jobs,
        workers=workers,
        executor=executor,
        ray_address=ray_address,
        progress=bar,
        costs=costs,  # the longest sequences first
    )
    with closing(outcomes):
        for outcome in outcomes:
            if outcome.result is None:  # not a DatasetError or OSError: a crash, as in one process
                outcome.raise_error()
            tally.add(outcome.result)

    return ConvertReport(
        converted=tuple(sorted(tally.converted)),
        skipped=tuple(tally.skipped),
        failed=tuple(sorted(tally.failed, key=lambda f: f.sequence)),
        frames=tally.frames,
        bytes_in=tally.bytes_in,
        bytes_out=tally.bytes_out,
        seconds=time.perf_counter() - started,
        cpu_seconds=tally.cpu_seconds,
    )
