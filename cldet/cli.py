"""The ``cldet`` command line: thin commands that parse options, call one library function each,
and turn a :class:`~cldet.errors.CldetError` into ``ERROR: ...`` and exit code 1.

Heavy imports happen inside the commands so that ``cldet --help`` is instant.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from enum import Enum
from pathlib import Path
from typing import Annotated, TypeVar

import typer

from cldet import __version__
from cldet.errors import CldetError

app = typer.Typer(
    name="cldet",
    help=(
        "Drone detection from LiDAR for the MMAUD anti-UAV challenge.\n\n"
        "Typical flow: `cldet simulate data` (or use the real dataset) -> `cldet convert data -o logs` "
        "-> `cldet annotate logs/val/*.mcap` -> `cldet export` -> `cldet evaluate`. "
        "`cldet demo` runs it all on a small generated dataset."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

T = TypeVar("T")


def _err(message: str) -> None:
    typer.echo(message, err=True)


@contextmanager
def _handled() -> Iterator[None]:
    """Map cldet's own errors to ``ERROR: ...`` and exit code 1; Ctrl-C to exit code 130."""
    try:
        yield
    except CldetError as err:
        _err(f"ERROR: {err}")
        raise typer.Exit(1) from err
    except KeyboardInterrupt as err:
        _err("interrupted")
        raise typer.Exit(130) from err


def _version(value: bool) -> None:
    if value:
        typer.echo(f"cldet {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version.")
    ] = False,
) -> None:
    """Drone detection from LiDAR for the MMAUD anti-UAV challenge."""


class Preset(str, Enum):
    """Sizes of a simulated dataset."""

    small = "small"
    full = "full"


@app.command()
def simulate(
    out: Annotated[Path, typer.Argument(help="Folder to create; gets train/, val/, test/ and the CSVs.")],
    preset: Annotated[Preset, typer.Option(help="small: seconds to generate; full: the benchmark set.")] = Preset.small,
    seed: Annotated[int, typer.Option(help="Random seed; the same seed gives the same bytes.")] = 0,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
) -> None:
    """Generate a synthetic dataset in exactly the challenge layout, with ground truth.

    The scenes have uneven ground, buildings, poles and swaying vegetation; one drone per
    sequence (size by class) with close passes, climbs into the Avia cone and high hovers;
    distractors (a walking person, a bird, speckle); and the real data's gaps.
    """
    from cldet.progress import BarProgress
    from cldet.simulate import simulate_dataset

    with _handled(), BarProgress() as bar:
        summary = simulate_dataset(out, preset=preset.value, seed=seed, overwrite=overwrite, progress=bar)
    typer.echo(summary.describe())


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``cldet`` console script."""
    app(args=argv if argv is not None else sys.argv[1:], prog_name="cldet")
