"""``cldet simulate``: a synthetic dataset in the challenge layout."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from cldet.commands._app import app, handled


class Preset(str, Enum):
    """Sizes of a simulated dataset."""

    small = "small"
    full = "full"


@app.command()
def simulate(
    out: Annotated[
        Path, typer.Argument(help="Folder to create; gets train/, val/, test/ and the CSVs.")
    ],
    preset: Annotated[
        Preset, typer.Option(help="small: seconds to generate; full: the benchmark set.")
    ] = Preset.small,
    seed: Annotated[int, typer.Option(help="Random seed; the same seed gives the same bytes.")] = 0,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
    randomize: Annotated[
        bool, typer.Option(help="Randomised worlds: sequence k is world SEED+k.")
    ] = False,
) -> None:
    """Generate a synthetic dataset in exactly the challenge layout, with ground truth.

    The scenes have uneven ground, buildings, poles and swaying vegetation; one drone per
    sequence (size by class) with close passes, climbs into the Avia cone and high hovers;
    distractors (a walking person, a bird, speckle); and the real data's gaps.
    """
    from cldet.progress import BarProgress
    from cldet.simulate import simulate_dataset

    with handled(), BarProgress() as bar:
        summary = simulate_dataset(
            out,
            preset=preset.value,
            seed=seed,
            overwrite=overwrite,
            progress=bar,
            randomize=randomize,
        )
    typer.echo(summary.describe())
