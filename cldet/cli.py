"""The ``cldet`` command line: thin commands that parse options, call one library function each,
and turn a :class:`~cldet.errors.CldetError` into ``ERROR: ...`` and exit code 1.

Each command lives in a module of :mod:`cldet.commands`; heavy imports happen inside the commands
so that ``cldet --help`` is instant.
"""

from __future__ import annotations

import sys

from cldet.commands import (  # noqa: F401  (each module registers its commands)
    annotate,
    calibrate,
    convert,
    demo,
    simulate,
    submission,
    train,
)
from cldet.commands._app import app
from cldet.commands.annotate import expand_optional_port


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``cldet`` console script (SIGTERM is handled like Ctrl-C)."""
    from cldet.signals import raise_on_sigterm

    raise_on_sigterm()
    args = argv if argv is not None else sys.argv[1:]
    app(args=expand_optional_port(args), prog_name="cldet")
