"""Command line: ``relaxgrip COMMAND``.

Every command lives in its own module and registers itself on
:data:`relaxgrip.cli._app.app`.  Bad input raises
:class:`relaxgrip.errors.InputError`; :func:`main` turns it into one line on
standard error and exit code 2.
"""

from __future__ import annotations

import sys

from relaxgrip.cli import (  # noqa: F401  (registers commands)
    bench,
    characterize,
    dashboard,
    experiments,
    fit,
    hardware,
    hold,
    learning,
    perceive,
    recording,
)
from relaxgrip.cli._app import app, err_console
from relaxgrip.errors import InputError

__all__ = ["app", "main"]


def main() -> None:
    """Entry point of the ``relaxgrip`` command."""
    try:
        app()
    except InputError as exc:
        err_console.print(f"error: {exc}", markup=False, highlight=False, soft_wrap=True)
        sys.exit(2)
