"""``cldet train``: learn timing, bias, the drone-vs-clutter scorer and the drone type from labelled logs."""

from __future__ import annotations

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


@app.command()
def train(
    logs: Annotated[
        list[Path],
        typer.Argument(
            help="MCAP logs with /ground_truth (and /class for the drone type): `cldet convert`"
            " of a train split, or your own labelled flights; a folder stands for every .mcap"
            " under it.",
            show_default=False,
        ),
    ],
    out: Annotated[Path, typer.Option("-o", "--out", help="The model file to write.")] = Path(
        "cldet-model.zip"
    ),
    config: Annotated[
        Path | None,
        typer.Option(
            "--config", help="YAML configuration of the pass the model learns for (as annotate)."
        ),
    ] = None,
    cross_validation: Annotated[
        bool,
        typer.Option(
            "--cv/--no-cv",
            help="Leave-one-sequence-out cross-validation report (fits one model per log).",
        ),
    ] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
    workers: Annotated[
        int,
        typer.Option(
            help="Logs run through the estimator in parallel, the bulk of the work (default: all"
            " cores; with --executor ray: all of the Ray cluster's). The model is the same."
        ),
    ] = 0,
    executor: ExecutorOption = ExecutorChoice.local,
    ray_address: RayAddressOption = None,
) -> None:
    """Learn from labelled logs what the default estimator only assumes, and write a model.

    Every log is run through the estimator once; its candidate tracks are matched to the truth
    (the drone's: median distance under 1 m; clutter: over 3 m). From them it fits:

    - the scan-time offset (when, inside the 100 ms scan, the drone's points were taken) and
      the centroid bias (along the ray and in z: what `cldet calibrate` fits);

    - a drone-vs-clutter scorer (gradient-boosted trees over each track's height above the
      ground, size, cross-section, speed, jitter, duration, sensors, ...) that re-weighs the
      hand-set track factors (by 0.3 + 0.7 p) when choosing the drone's tracks, on top of
      the prior scorer learned on simulated worlds that annotate uses without a model;

    - a drone-type classifier (when the logs carry /class with two classes or more), voted over
      the chosen tracks; `annotate --model` writes it on /cldet/class and `export` fills the
      Classification column from it.

    It prints a leave-one-sequence-out cross-validation: position error with the learned scorer
    against the default and against the learned timing and bias alone, type accuracy and the
    confusion matrix. The scorer is kept only where the held-out logs were clearly better with
    it (fewer off by over 1 m; or as many, and a 5 % lower MSE); otherwise the report says it
    is dropped.
    The model file holds no pickle (JSON and skops); a model from another version is refused.

    Example:

        cldet train logs/train/*.mcap -o model.zip
        cldet annotate logs/test/*.mcap --model model.zip
        cldet export logs/test/*.mcap -o mmaud_results.csv
    """
    from cldet.config import load_config
    from cldet.progress import BarProgress
    from cldet.train import train_logs

    with handled():
        logs = expand_logs(logs)
        check_executor(executor, ray_address)
        cfg = load_config(config)
        with BarProgress() as bar:
            report = train_logs(
                logs,
                out,
                config=cfg,
                cross_validation=cross_validation,
                overwrite=overwrite,
                progress_factory=lambda: bar,
                warn=lambda m: echo_err(f"WARNING: {m}"),
                workers=workers or None,  # None: every CPU, here or of the Ray cluster
                executor=executor.value,
                ray_address=ray_address,
            )
    typer.echo(report.describe())
    typer.echo(f"wrote {out}: use it with `cldet annotate LOGS --model {out}`")
