"""``cldet demo``: simulate, convert, annotate with both methods, export and score, side by side."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer

from cldet.commands._app import app, handled


@app.command()
def demo(
    root: Annotated[
        Path, typer.Argument(help="Working folder (created; a dataset already there is reused).")
    ] = Path("cldet-demo"),
    seed: Annotated[int, typer.Option(help="Seed of the simulated dataset.")] = 0,
    workers: Annotated[
        int, typer.Option(help="Processes for convert and annotate (default: all cores).")
    ] = 0,
) -> None:
    """Run the whole job on a small simulated dataset and print both methods' scores.

    Steps: `cldet simulate ROOT/data --preset small`, `cldet convert` of its train and test
    splits, `cldet annotate` + `cldet calibrate` on train (the bias correction), `cldet annotate`
    of test with the `track` method (calibrated) and with the `cl-det` baseline, `cldet export` of
    each to a challenge mmaud_results.csv, and `cldet evaluate` against the simulator's truth.
    Ends with the path of a Rerun recording to open with `rerun`.
    """
    from cldet.demo import comparison_rows, run_demo
    from cldet.progress import BarProgress

    with handled(), BarProgress() as bar:
        report = run_demo(root, workers=workers or os.cpu_count() or 1, progress=bar)
    rows = comparison_rows(report)
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    typer.echo(f"\ntrack's {report.calibration.describe()}")
    typer.echo(f"\nScores on the simulated test split ({report.data}):\n")
    for k, row in enumerate(rows):
        typer.echo(
            "  ".join(
                cell.ljust(w) if i == 0 else cell.rjust(w)
                for i, (cell, w) in enumerate(zip(row, widths, strict=True))
            )
        )
        if k == 0:
            typer.echo("  ".join("-" * w for w in widths))
    for run in report.runs:
        typer.echo(f"\n{run.method}: {run.results_csv}")
    recordings = [rrd for run in report.runs for rrd in run.rrd]
    if recordings:
        typer.echo(f"\nReview a sequence in Rerun:  rerun {recordings[0]}")
