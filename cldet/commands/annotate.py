"""``cldet annotate``: estimate the drone's track in MCAP logs and write the results back into them."""

from __future__ import annotations

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
    expand_logs,
    handled,
)


class Method(str, Enum):
    """Estimation methods."""

    track = "track"
    cl_det = "cl-det"


@app.command()
def annotate(
    logs: Annotated[
        list[Path],
        typer.Argument(
            help="MCAP logs written by `cldet convert`, or ROS 2 recordings in MCAP; a folder"
            " stands for every .mcap under it.",
            show_default=False,
        ),
    ],
    method: Annotated[
        Method | None,
        typer.Option(
            help="track (default: background + clustering + tracker + smoother) or cl-det (the report's baseline)."
        ),
    ] = None,
    config: Annotated[
        Path | None,
        typer.Option(
            "--config", help="YAML file overriding the defaults; a misspelt key is an error."
        ),
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option(
            "-o",
            "--output",
            help="Write the annotated log here instead of in place (one log only).",
        ),
    ] = None,
    rrd: Annotated[
        Path | None,
        typer.Option(
            help="Rerun recording path (one log only); default: LOG.rrd beside the output."
        ),
    ] = None,
    no_rrd: Annotated[
        bool, typer.Option("--no-rrd", help="Do not write the Rerun review recording.")
    ] = False,
    workers: Annotated[
        int,
        typer.Option(
            help="Logs annotated in parallel (default: all cores; with --executor ray: all of "
            "the Ray cluster's)."
        ),
    ] = 0,
    executor: ExecutorOption = ExecutorChoice.local,
    ray_address: RayAddressOption = None,
    force: Annotated[
        bool,
        typer.Option(
            "--force", help="Rewrite a read-only log (its mode is kept). Default: refuse."
        ),
    ] = False,
    lidar: Annotated[
        str | None,
        typer.Option(
            metavar="TOPIC",
            help="The LiDAR's point-cloud topic: foxglove.PointCloud, sensor_msgs/msg/PointCloud2 "
            "or Livox CustomMsg. Default: /lidar_360, else the log's only point-cloud topic.",
        ),
    ] = None,
    avia: Annotated[
        str | None,
        typer.Option(
            metavar="TOPIC",
            help="The Avia's point-cloud topic, fused with the LiDAR's (moved into its frame by "
            "the log's /tf_static when present). Default: /livox_avia with /lidar_360, else none.",
        ),
    ] = None,
    truth: Annotated[
        str | None,
        typer.Option(
            metavar="TOPIC",
            help="Ground-truth positions (PoseInFrame, PointStamped, PoseStamped) for the "
            "reported error. Default: /ground_truth when present.",
        ),
    ] = None,
    model: Annotated[
        Path | None,
        typer.Option(
            "--model",
            metavar="MODEL",
            help="A model from `cldet train`: its learned scorer re-weighs the drone's tracks "
            "(with the prior scorer learned on simulated worlds, config "
            "tracking.prior_scorer), its scan-time offset and bias replace the "
            "configuration's, and the drone type goes on /cldet/class. Default: the prior "
            "scorer alone, no type.",
        ),
    ] = None,
    live: Annotated[
        bool,
        typer.Option(
            "--live",
            help="Stream each frame (clouds, foreground, clusters, causal estimate) while it is "
            "processed, then the refined track, to a Rerun viewer (spawned, or --connect) and "
            "with --foxglove to Foxglove; print each frame's latency. One log only.",
        ),
    ] = False,
    realtime: Annotated[
        bool, typer.Option("--realtime", help="With --live: pace the frames at the sensor's rate.")
    ] = False,
    connect: Annotated[
        str | None,
        typer.Option(
            metavar="URL",
            help="With --live: stream to this Rerun viewer's gRPC URL (e.g. "
            "rerun+http://127.0.0.1:9876/proxy) instead of spawning one.",
        ),
    ] = None,
    no_rerun: Annotated[
        bool, typer.Option("--no-rerun", help="With --live: no Rerun viewer (Foxglove only).")
    ] = False,
    foxglove: Annotated[
        int | None,
        typer.Option(
            metavar="[PORT]",
            min=0,
            max=65535,
            help="With --live: serve Foxglove's WebSocket protocol on 127.0.0.1:PORT (default "
            "8765; 0: any free port); connect Foxglove to ws://127.0.0.1:PORT.",
        ),
    ] = None,
) -> None:
    """Estimate the drone's 3D position at every Mid-360 frame and add the results to each log.

    Each log is rewritten in place: its data is copied byte for byte into a temporary file (no
    decompression), the results are appended, and the file is renamed over the log when complete;
    an earlier annotation is replaced. New channels:
    /cldet/estimate, /cldet/pose, /cldet/trajectory, /cldet/clusters, /cldet/foreground,
    /cldet/causal (the per-frame estimate as a live run makes it), /cldet/class with --model
    (the drone type and its probabilities, updated every second), point-cloud copies Rerun
    draws too (/cldet/drone, /cldet/track, /cldet/truth_track, /cldet/centroids), a /tf frame
    tree when the log has none, and a `cldet.config` metadata record with the method and
    effective configuration.

    ROS 2 recordings (`ros2 bag record` writes MCAP) are read as they are: name the topics,
    e.g. `cldet annotate rec.mcap --lidar /livox/lidar --avia /livox/avia`. Each frame is dated
    by its header stamp (a Livox CustomMsg: its timebase), not by the time it was recorded.

    A Rerun recording (clouds, foreground, clusters, estimated and true trajectories, error over
    time, track events) is written beside each log: open it with `rerun LOG.rrd`.

    Many logs, or more cores than one machine has: --executor ray annotates each log in a Ray
    task, on a local Ray started for the run or on a running cluster (--ray-address auto, or
    HOST:PORT), with the same results, byte for byte; it needs `pip install "cldet\\[ray]"`, and on
    a cluster cldet on every node and the logs on a shared file system.

    A log being annotated is locked: a second run on it refuses. A symbolic link is annotated
    at its target (the link stays); a read-only log is refused unless --force. Ctrl-C and
    SIGTERM remove the temporary files.

    Examples: cldet annotate logs/val/*.mcap --method track;
    cldet annotate logs/*/*.mcap --no-rrd --executor ray --ray-address auto
    """
    from cldet.config import load_config
    from cldet.errors import CldetError
    from cldet.modelfile import load_model
    from cldet.pipeline import annotate_log_locked, annotate_logs
    from cldet.progress import BarProgress

    with handled():
        logs = expand_logs(logs)
        overrides = {"method": method.value} if method is not None else None
        cfg = load_config(config, overrides=overrides)
        learned = load_model(model) if model is not None else None
        if learned is not None and cfg.method != "track":
            raise CldetError(f"--model goes with the track method, not {cfg.method}")
        if (output is not None or rrd is not None) and len(logs) != 1:
            raise CldetError("-o/--output and --rrd go with exactly one log")
        check_executor(executor, ray_address)
        on_ray = executor is ExecutorChoice.ray
        if on_ray and (live or rrd is not None):
            raise CldetError("--live and --rrd go with --executor local")
        if not live and (realtime or connect or no_rerun or foxglove is not None):
            raise CldetError("--realtime, --connect, --no-rerun and --foxglove go with --live")
        if live:
            _annotate_live(
                logs,
                cfg,
                output=output,
                rrd=rrd,
                write_rrd=not no_rrd,
                force=force,
                lidar=lidar,
                avia=avia,
                truth=truth,
                model=learned,
                realtime=realtime,
                rerun=None if no_rerun else (connect or "spawn"),
                foxglove=foxglove,
            )
            return
        with BarProgress() as bar:
            if len(logs) == 1 and not on_ray:
                report = annotate_log_locked(
                    logs[0],
                    config=cfg,
                    output=output,
                    rrd=rrd,
                    write_rrd=not no_rrd,
                    force=force,
                    progress=bar,
                    lidar=lidar,
                    avia=avia,
                    truth=truth,
                    model=learned,
                )
                reports, failures = [report], list[tuple[Path, str]]()
            else:
                reports, failures = annotate_logs(
                    logs,
                    config=cfg,
                    outputs=[output] if output is not None else None,
                    write_rrd=not no_rrd,
                    workers=workers or None,  # None: every CPU, here or of the Ray cluster
                    force=force,
                    progress=bar,
                    lidar=lidar,
                    avia=avia,
                    truth=truth,
                    model=learned,
                    executor=executor.value,
                    ray_address=ray_address,
                )
        for report in reports:
            typer.echo(report.describe())
        if failures:
            for log, message in failures:
                echo_err(f"FAILED {log}: {message}")
            echo_err(f"ERROR: {len(failures)} of {len(logs)} logs failed")
            raise typer.Exit(1)


def _annotate_live(
    logs: list[Path],
    cfg: object,
    *,
    rerun: str | None,
    foxglove: int | None,
    realtime: bool,
    **options: object,
) -> None:
    """``--live``: one log, streamed frame by frame; the per-frame latency printed."""
    import sys

    from cldet.config import CldetConfig
    from cldet.errors import CldetError
    from cldet.live import LiveOutput
    from cldet.pipeline import annotate_log_locked

    if len(logs) != 1:
        raise CldetError("--live goes with exactly one log")
    if rerun is None and foxglove is None:
        raise CldetError("--live with --no-rerun needs --foxglove: there is nowhere to stream")
    assert isinstance(cfg, CldetConfig)

    def on_frame(stamp_ns: int, latency_s: float) -> None:
        typer.echo(f"frame {stamp_ns}: {latency_s * 1e3:.1f} ms")

    live = LiveOutput(rerun=rerun, foxglove_port=foxglove, realtime=realtime, on_frame=on_frame)
    try:
        if live.foxglove_port is not None:
            typer.echo(f"Foxglove: open a connection to ws://127.0.0.1:{live.foxglove_port}")
        report = annotate_log_locked(logs[0], config=cfg, live=live, **options)  # type: ignore[arg-type]
        typer.echo(live.latency_summary())
        typer.echo(report.describe())
        if live.foxglove_port is not None and sys.stdin.isatty():
            typer.echo("serving the results to Foxglove: press Enter to stop")
            sys.stdin.readline()
    finally:
        live.close()


def expand_optional_port(
    args: list[str], flag: str = "--foxglove", default: int = 8765
) -> list[str]:
    """``--foxglove`` without a port number gets the default one (Typer options need a value)."""
    out: list[str] = []
    for i, arg in enumerate(args):
        out.append(arg)
        if arg == flag and not (i + 1 < len(args) and args[i + 1].isdigit()):
            out.append(str(default))
    return out
