"""Command line: ``relaxgrip COMMAND``.

Every command lives in its own module and registers itself on
:data:`relaxgrip.cli._app.app`.  Bad input raises
:class:`relaxgrip.errors.InputError`; :func:`main` turns it into one line on
standard error and exit code 2, and an ``OSError`` the file system raises
(no space left, a read-only or missing folder) likewise.
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
from relaxgrip.fileio import one_line

__all__ = ["app", "main"]


def main() -> None:
    """Entry point of the ``relaxgrip`` command."""
    try:
        app()
    except InputError as exc:
        err_console.print(f"error: {exc}", markup=False, highlight=False, soft_wrap=True)
        sys.exit(2)
    except OSError as exc:  # a path the system refused (no space, read-only, a directory)
        where = f"{exc.filename}: " if exc.filename else ""
        err_console.print(f"error: {where}{exc.strerror or one_line(exc)}", markup=False,
                          highlight=False, soft_wrap=True)
        sys.exit(2)
