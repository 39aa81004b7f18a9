"""``cldet calibrate``: fit the centroid bias correction on annotated training logs."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from cldet.commands._app import app, expand_logs, handled


@app.command()
def calibrate(
    logs: Annotated[
        list[Path],
        typer.Argument(
            help="Training logs annotated with zero bias (they hold /ground_truth); a folder"
            " stands for every .mcap under it."
        ),
    ],
    out: Annotated[
        Path, typer.Option("-o", "--out", help="YAML configuration to write (the `bias:` section).")
    ] = Path("bias.yaml"),
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
) -> None:
    """Fit only the bias correction (along the sensor ray, and in z) from training ground truth.

    `cldet train` fits the same correction and more (timing, track scorer, drone type) by
    running the estimator itself; calibrate is the light way when the training logs are already
    annotated, or for the cl-det method: no re-run, no scikit-learn model, a YAML file.

    The LiDAR sees only the near face of the drone and the truth is a prism above it, so
    detected centroids sit nearer the sensor and lower than the truth. This fits the two offsets
    by least squares over the detected estimates of annotated training logs and writes them as a
    configuration for the other splits:

        cldet annotate logs/train/*.mcap --no-rrd
        cldet calibrate logs/train/*.mcap -o bias.yaml
        cldet annotate logs/test/*.mcap --config bias.yaml
    """
    from cldet.calibrate import calibrate_logs, write_bias_config

    with handled():
        calibration = calibrate_logs(expand_logs(logs))
        write_bias_config(calibration, out, overwrite=overwrite)
    typer.echo(calibration.describe())
    typer.echo(f"wrote {out}: use it with `cldet annotate --config {out}`")
