"""The Typer application shared by every command module, and the error mapping they all use."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
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


class ExecutorChoice(str, Enum):
    """Where the files are processed (mirrors cldet.executors.EXECUTORS; kept here for a fast
    --help)."""

    local = "local"
    ray = "ray"


# help texts are rich markup: "\\[" keeps a bracket ("cldet[ray]") from being read as a style
EXECUTOR_HELP = (
    "local: worker processes on this machine. ray: one Ray task per file, for more cores than "
    "one machine has: on a local Ray started for the run, or on the cluster at --ray-address. "
    'Ray is an optional extra: pip install "cldet\\[ray]". The outputs are the same, byte for byte.'
)
RAY_ADDRESS_HELP = (
    "With --executor ray: join this running Ray cluster instead of starting a local one, e.g. "
    "auto (the cluster `ray start --head` runs on this machine), HOST:6379 or ray://HOST:10001. "
    "Default: $RAY_ADDRESS when set (`ray job submit` sets it). Every node needs cldet "
    "installed and the files at the same paths (a shared file system): tasks get paths, not data."
)


ExecutorOption = Annotated[ExecutorChoice, typer.Option("--executor", help=EXECUTOR_HELP)]
"""``--executor``, as convert, annotate and train take it (default ``ExecutorChoice.local``)."""
RayAddressOption = Annotated[
    str | None, typer.Option("--ray-address", metavar="ADDR", help=RAY_ADDRESS_HELP)
]
"""``--ray-address ADDR`` (default None)."""


def check_executor(executor: ExecutorChoice, ray_address: str | None) -> None:
    """``--ray-address`` goes with ``--executor ray``."""
    if ray_address is not None and executor is not ExecutorChoice.ray:
        raise CldetError("--ray-address goes with --executor ray")


def expand_logs(paths: Sequence[Path]) -> list[Path]:
    """The logs named: a file as it is; a folder as every ``*.mcap`` under it, sorted (hidden
    names, such as a run's temporary files, left out).

    Raises:
        CldetError: a folder holds no MCAP log.
    """
    logs: list[Path] = []
    for path in paths:
        if not path.is_dir():
            logs.append(path)  # a missing file is reported by whoever opens it
            continue
        found = sorted(
            p
            for p in path.rglob("*.mcap")
            if p.is_file() and not any(part.startswith(".") for part in p.relative_to(path).parts)
        )
        if not found:
            raise CldetError(f"{path} is a folder with no MCAP log (*.mcap) in it")
        logs.extend(found)
    return logs


def echo_err(message: str) -> None:
    typer.echo(message, err=True)


def describe_os_error(err: OSError) -> str:
    """One line for an ``OSError``: the file(s) it names and the system's reason."""
    reason = err.strerror or str(err) or type(err).__name__
    names = [str(n) for n in (err.filename, err.filename2) if n is not None]
    return f"{' -> '.join(names)}: {reason}" if names else reason


@contextmanager
def handled() -> Iterator[None]:
    """Map cldet's own errors to ``ERROR: ...`` and exit code 1; Ctrl-C to exit code 130.

    An ``OSError`` that reaches here (a disk that fills up, a file that vanished) is an
    environment failure, not a bug: it also becomes one line naming the file, and exit code 1.
    """
    try:
        yield
    except CldetError as err:
        echo_err(f"ERROR: {err}")
        raise typer.Exit(1) from err
    except OSError as err:
        echo_err(f"ERROR: {describe_os_error(err)}")
        raise typer.Exit(1) from err
    except KeyboardInterrupt as err:
        from cldet.signals import Terminated

        if isinstance(err, Terminated):
            echo_err("terminated (SIGTERM); temporary files removed")
            raise typer.Exit(143) from err
        echo_err("interrupted")
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
