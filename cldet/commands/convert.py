"""``cldet convert``: the challenge dataset (numpy folders) -> one MCAP log per sequence."""

from __future__ import annotations

import warnings
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from cldet.commands._app import (
    ExecutorChoice,
    ExecutorOption,
    RayAddressOption,
    app,
    check_executor,
    echo_err,
    handled,
)


class CompressionChoice(str, Enum):
    """Chunk compression of the logs (mirrors cldet.io.Compression; kept here for a fast --help)."""

    zstd = "zstd"
    lz4 = "lz4"
    none = "none"


_HELP = (
    "Convert the challenge dataset to MCAP logs, one per sequence, for Foxglove and Rerun."
    "\n\n"
    "Each OUT/<split>/<seqNNNN>.mcap has a channel per modality found: /lidar_360 and "
    "/livox_avia (foxglove.PointCloud in frame mid360, valid points only, float32), "
    "/radar_enhance_pcl (frame radar, empty frames kept), /ground_truth (foxglove.PoseInFrame) "
    "and /class (cldet.ClassLabel) on train, /image (PNG) with /image/calibration. Every "
    "message is stamped with its file's stamp in nanoseconds, exactly; a metadata record "
    "cldet.source holds the split, sequence, source folder and frame counts; /tf "
    "(foxglove.FrameTransforms) connects every frame under a z-up world frame."
    "\n\n"
    "Each log is written to a temporary file and renamed when complete, so an interrupted run "
    "never leaves half a log. Existing logs are skipped unless --overwrite. A sequence that "
    "fails (a corrupt .npy, an empty folder, a FIFO named like a frame) is reported with the "
    "file or folder at fault, the others are still "
    "converted, and the exit code is 1."
    "\n\n"
    "ROOT may also be a ROS bag: a ROS 1 .bag file or a ROS 2 bag folder (.db3 or .mcap), read "
    "through rosbags (no ROS installation). It becomes OUT/<name>.mcap with the same channels, "
    "every message at its header stamp; --lidar-topic, --avia-topic, --radar-topic and "
    "--truth-topic choose the bag topics (defaults: the MMAUD raw recordings' topics; a truth "
    "topic ending in / is a prefix; an empty value leaves a channel out)."
    "\n\n"
    "Many sequences, or more cores than one machine has: --executor ray converts each sequence "
    "in a Ray task, on a local Ray or on a cluster (--ray-address); the logs are the same, byte "
    'for byte. It needs the ray extra: pip install "cldet\\[ray]".'
    "\n\n"
    "Examples: `cldet convert data -o logs`; `cldet convert seq1.bag -o logs`; "
    "`cldet convert data -o logs --split val --sequence seq0001 --no-images`; "
    "`cldet convert data -o logs --executor ray --ray-address auto`. "
    "Then open a log with `rerun logs/val/seq0001.mcap` or in Foxglove."
)


@app.command(help=_HELP)
def convert(
    root: Annotated[
        Path,
        typer.Argument(
            metavar="ROOT",
            help="Dataset root holding train/, val/ and/or test/ with seqNNNN folders "
            "(the challenge layout, or the output of `cldet simulate`).",
        ),
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            metavar="OUT",
            help="Output folder; gets OUT/<split>/<seqNNNN>.mcap (created as needed).",
        ),
    ],
    split: Annotated[
        list[str] | None,
        typer.Option(
            "--split",
            metavar="NAME",
            help="Only this split: train, val or test. Repeat for several. Default: all.",
        ),
    ] = None,
    sequence: Annotated[
        list[str] | None,
        typer.Option(
            "--sequence",
            metavar="NAME",
            help="Only this sequence, e.g. seq0001 (or seq1). Repeat for several. Default: all.",
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            "--workers",
            metavar="N",
            min=1,
            help="Sequences converted in parallel. Default: number of CPUs (with --executor "
            "ray: of the Ray cluster).",
        ),
    ] = None,
    executor: ExecutorOption = ExecutorChoice.local,
    ray_address: RayAddressOption = None,
    compression: Annotated[
        CompressionChoice,
        typer.Option(
            help="Chunk compression: zstd is smallest (~0.7 of none for clouds), lz4 reads and "
            "writes faster, none is fastest and largest."
        ),
    ] = CompressionChoice.zstd,
    images: Annotated[
        bool,
        typer.Option(
            "--images/--no-images",
            help="Convert the camera images too. They are most of the bytes; --no-images "
            "gives small, LiDAR-only logs.",
        ),
    ] = True,
    overwrite: Annotated[
        bool,
        typer.Option("--overwrite", help="Replace existing logs. Default: skip (and report) them."),
    ] = False,
    lidar_topic: Annotated[
        str,
        typer.Option(metavar="TOPIC", help="ROS bags: the Mid-360's point clouds (/lidar_360)."),
    ] = "/livox_mid360/lidar",
    avia_topic: Annotated[
        str,
        typer.Option(metavar="TOPIC", help="ROS bags: the Avia's point clouds (/livox_avia)."),
    ] = "/livox_avia/lidar",
    radar_topic: Annotated[
        str,
        typer.Option(metavar="TOPIC", help="ROS bags: the radar's clouds (/radar_enhance_pcl)."),
    ] = "/radar_enhance_pcl",
    truth_topic: Annotated[
        str,
        typer.Option(
            metavar="TOPIC",
            help="ROS bags: PointStamped or PoseStamped truth (/ground_truth); a trailing / "
            "takes the first topic under it.",
        ),
    ] = "/leica/point/",
) -> None:
    """Convert the challenge dataset to MCAP logs, one per sequence (see --help)."""
    from cldet.progress import BarProgress
    from converters.mcap_convert import convert_dataset
    from converters.rosbag import BagTopics, convert_bag_file, is_bag

    with handled():
        check_executor(executor, ray_address)
    if is_bag(root):
        if executor is ExecutorChoice.ray:
            echo_err("ERROR: --executor ray converts dataset folders; a bag is one file")
            raise typer.Exit(1)
        chosen = BagTopics(
            lidar=lidar_topic,
            avia=avia_topic or None,
            radar=radar_topic or None,
            truth=truth_topic or None,
        )
        target = out / f"{root.stem}.mcap"
        if target.exists() and not overwrite:  # as for the numpy folders: skipped, reported
            typer.echo(f"skipped existing log {target} (use --overwrite to replace it)")
            return
        with handled(), BarProgress() as bar:
            counts = convert_bag_file(
                root,
                target,
                bag_topics=chosen,
                compression=compression.value,
                overwrite=overwrite,
                progress=bar,
            )
        typer.echo(
            f"converted {root} -> {target}: "
            + ", ".join(f"{n} on {topic}" for topic, n in counts.items())
        )
        return

    with handled(), BarProgress() as bar, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        report = convert_dataset(
            root,
            out,
            splits=split or None,
            sequences=sequence or None,
            workers=workers,
            compression=compression.value,
            images=images,
            overwrite=overwrite,
            progress=bar,
            executor=executor.value,
            ray_address=ray_address,
        )
    for warning in caught:
        echo_err(f"WARNING: {warning.message}")
    if report.ok:
        typer.echo(report.describe())
        return
    echo_err(report.describe())
    echo_err(f"ERROR: {len(report.failed)} sequence(s) failed to convert (see above)")
    raise typer.Exit(1)
