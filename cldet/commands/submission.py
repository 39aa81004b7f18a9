"""``cldet export`` and ``cldet evaluate``: write a challenge submission, and score one."""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from cldet.commands._app import app, echo_err, expand_logs, handled

if TYPE_CHECKING:
    from cldet.evaluate import Evaluation


@app.command()
def export(
    logs: Annotated[
        list[Path],
        typer.Argument(
            metavar="LOGS",
            help="Annotated MCAP logs, one per sequence (one split); a folder stands for every"
            " .mcap under it.",
        ),
    ],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="The results CSV to write (mmaud_results.csv).")
    ],
    timestamps: Annotated[
        Path | None,
        typer.Option(
            "--timestamps",
            "-t",
            help="The query file (test_timestamps.csv). Without it: one row per /ground_truth "
            "stamp of each log.",
        ),
    ] = None,
    class_id: Annotated[
        int | None,
        typer.Option(
            "--class-id",
            help="Classification written on every row. Default: each log's drone type from "
            "`cldet annotate --model` (/cldet/class), else 0.",
        ),
    ] = None,
    max_extrapolation_s: Annotated[
        float,
        typer.Option(
            "--max-extrapolation-s",
            min=0.0,
            help="Follow the track's motion at most this many seconds beyond its first/last "
            "estimate, then hold the position reached. `inf`: no limit.",
        ),
    ] = 1.0,
    allow_fallback: Annotated[
        bool,
        typer.Option(
            "--allow-fallback",
            help="Write the training-set mean position for a query sequence without a log or "
            "whose log was never annotated (with a warning). Default: that is an error.",
        ),
    ] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
) -> None:
    """Write the challenge submission from annotated logs: one row per query row, in its order.

    Each sequence's /cldet/estimate trajectory is interpolated at the query stamps and
    extrapolated by the track's own motion beyond its ends (at most --max-extrapolation-s). A
    query sequence without a log or without any estimate is an error; with --allow-fallback it
    gets the training-set mean position (0.734, -9.739, 33.353) and a warning.
    """
    import math

    from cldet.export import export_results
    from cldet.progress import BarProgress

    limit_ns = None if math.isinf(max_extrapolation_s) else round(max_extrapolation_s * 1e9)
    with handled(), BarProgress() as bar:
        report = export_results(
            expand_logs(logs),
            out,
            timestamps,
            class_id,
            overwrite=overwrite,
            max_extrapolation_ns=limit_ns,
            allow_fallback=allow_fallback,
            progress=bar,
        )
    for warning in report.warnings:
        echo_err(f"WARNING: {warning}")
    typer.echo(report.describe())


@app.command()
def evaluate(
    results: Annotated[
        Path, typer.Argument(metavar="RESULTS", help="The results CSV (mmaud_results.csv).")
    ],
    logs: Annotated[
        list[Path] | None,
        typer.Argument(
            metavar="LOGS",
            help="Annotated MCAP logs holding the truth (/ground_truth, /class).",
        ),
    ] = None,
    truth: Annotated[
        Path | None,
        typer.Option("--truth", help="A truth CSV: Sequence,Timestamp,x,y,z,class."),
    ] = None,
    from_logs: Annotated[
        bool,
        typer.Option(
            "--logs",
            help="Read the truth from the LOGS given after RESULTS "
            "(`cldet evaluate r.csv --logs a.mcap b.mcap`).",
        ),
    ] = False,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print a machine-readable JSON summary only.")
    ] = False,
    errors_parquet: Annotated[
        Path | None,
        typer.Option("--errors-parquet", help="Write the per-row errors to this Parquet file."),
    ] = None,
    overwrite: Annotated[
        bool, typer.Option(help="Replace the --errors-parquet file if it exists.")
    ] = False,
) -> None:
    """Score a results CSV against ground truth (a truth CSV or annotated logs).

    Reports the MSE both ways, each labelled (per coordinate: sum of squared error / 3N; and
    the mean squared 3D distance), the RMSE, median and 95th percentile of the 3D error, the
    class accuracy per row, and a per-sequence table. Missing, duplicate and unmatched rows are
    counted and reported; the metrics cover the matched rows.
    """
    from cldet.errors import OutputExistsError, ResultsError
    from cldet.evaluate import evaluate_results, truth_from_logs, write_errors_parquet
    from cldet.progress import BarProgress
    from cldet.results import read_truth

    with handled():
        if (truth is None) == (not logs):
            raise ResultsError(
                "give the truth either as --truth TRUTH.csv or as annotated logs "
                "(--logs LOGS...), not both and not neither"
            )
        if from_logs and not logs:
            raise ResultsError("--logs needs at least one log after RESULTS")
        if errors_parquet is not None and errors_parquet.exists() and not overwrite:
            raise OutputExistsError(
                f"{errors_parquet} already exists: pass --overwrite to replace it"
            )
        if truth is not None:
            table = read_truth(truth)
        else:
            with BarProgress() as bar:
                table = truth_from_logs(logs or [], progress=bar)
        evaluation = evaluate_results(results, table)
        if errors_parquet is not None:
            write_errors_parquet(evaluation, errors_parquet, overwrite=overwrite)

    for warning in evaluation.warnings:
        echo_err(f"WARNING: {warning}")
    if as_json:
        typer.echo(json.dumps(evaluation.to_dict(), indent=2))
    else:
        _print_evaluation(evaluation)
    if errors_parquet is not None and not as_json:
        typer.echo(f"per-row errors written to {errors_parquet}")


def _fmt(value: float | None, digits: int = 4) -> str:
    if value is None or value != value:  # None or NaN
        return "-"
    return f"{value:.{digits}f}"


def _print_evaluation(ev: Evaluation) -> None:
    """Summary and per-sequence table: rich on a terminal, aligned plain text otherwise."""
    accuracy = (
        f"{_fmt(ev.accuracy, 3)} ({ev.n_classified} rows with a true class)"
        if ev.accuracy is not None
        else "- (the truth has no class)"
    )
    summary = [
        ("results", ev.results_path),
        ("truth", ev.truth_source),
        (
            "rows",
            f"{ev.n_matched} matched of {ev.n_truth} truth rows; {ev.n_results} result rows; "
            f"missing {ev.n_missing}, duplicate {ev.n_duplicate}, unmatched {ev.n_unmatched}",
        ),
        ("MSE per coordinate (sum sq err / 3N)", f"{_fmt(ev.mse_per_coordinate_m2)} m^2"),
        ("mean squared 3D distance (sum sq / N)", f"{_fmt(ev.mean_squared_distance_m2)} m^2"),
        ("RMSE 3D", f"{_fmt(ev.rmse_m)} m"),
        ("median 3D error", f"{_fmt(ev.median_error_m)} m"),
        ("95th percentile 3D error", f"{_fmt(ev.p95_error_m)} m"),
        ("max 3D error", f"{_fmt(ev.max_error_m)} m"),
        ("accuracy", accuracy),
    ]
    headers = ["sequence", "truth", "matched", "missing", "MSE/coord\nm^2", "MSD 3D\nm^2",
               "RMSE\nm", "max\nm", "acc."]  # fmt: skip
    table = [
        [
            s.sequence,
            str(s.n_truth),
            str(s.n_matched),
            str(s.n_missing),
            _fmt(s.mse_per_coordinate_m2),
            _fmt(s.mean_squared_distance_m2),
            _fmt(s.rmse_m),
            _fmt(s.max_error_m),
            _fmt(s.accuracy, 3),
        ]
        for s in ev.sequences
    ]
    if sys.stdout.isatty():
        from rich import box
        from rich.console import Console
        from rich.table import Table

        console = Console()
        head = Table(show_header=False, box=None)
        for key, value in summary:
            head.add_row(f"[bold]{key}[/bold]", value)
        console.print(head)
        per_seq = Table(
            title="per sequence", box=box.SIMPLE_HEAD, pad_edge=False, collapse_padding=True
        )
        for i, header in enumerate(headers):
            per_seq.add_column(header, no_wrap=True, justify="left" if i == 0 else "right")
        for row in table:
            per_seq.add_row(*row)
        console.print(per_seq)
    else:
        width = max(len(k) for k, _ in summary)
        for key, value in summary:
            typer.echo(f"{key:<{width}}  {value}")
        typer.echo("")
        typer.echo("per sequence:")
        _echo_columns([h.replace("\n", " ") for h in headers], table)
    confusion = ev.confusion()
    if confusion is not None:
        typer.echo("")
        typer.echo(
            "drone type confusion (rows: true class, columns: Classification; rows counted):"
        )
        typer.echo(confusion)


def _echo_columns(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> None:
    widths = [max([len(h), *(len(r[i]) for r in rows)]) for i, h in enumerate(headers)]
    typer.echo("  ".join(h.ljust(w) for h, w in zip(headers, widths, strict=True)).rstrip())
    for row in rows:
        typer.echo("  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip())
