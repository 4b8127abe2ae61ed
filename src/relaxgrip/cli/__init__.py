"""Command line: ``relaxgrip COMMAND``.

Every command lives in its own module and registers itself on
:data:`relaxgrip.cli._app.app`.  Bad input raises
:class:`relaxgrip.errors.InputError`; :func:`main` turns it into one line on
standard error and exit code 2, and likewise an ``OSError`` the file system
raises (no space left, a read-only or missing folder) and a flag typer cannot
parse (an unknown option, ``--target-n abc``).  ``kill`` (SIGTERM) and a closed
terminal (SIGHUP) stop a command as Ctrl-C does, so that its clean-up runs: a
recording gets its footer, temporary files go, the loop's heaters go off.
"""

from __future__ import annotations

import sys
from typing import NoReturn

from typer import Abort

try:  # recent typer carries its own copy of click
    from typer._click.exceptions import ClickException, NoArgsIsHelpError
except ImportError:  # pragma: no cover - older typer on click itself
    from click.exceptions import ClickException, NoArgsIsHelpError  # type: ignore[assignment]

from relaxgrip.cli import (  # noqa: F401  (registers commands)
    bench,
    bringup,
    camera,
    characterize,
    dashboard,
    experiments,
    fit,
    hardware,
    hold,
    learning,
    material,
    perceive,
    recording,
)
from relaxgrip.cli._app import app, err_console
from relaxgrip.errors import InputError
from relaxgrip.fileio import one_line
from relaxgrip.interrupts import stop_signals

__all__ = ["app", "main"]


def main() -> None:
    """Entry point of the ``relaxgrip`` command."""
    try:
        with stop_signals():
            code = app(standalone_mode=False)
    except NoArgsIsHelpError:  # bare ``relaxgrip`` (or a group): typer has shown its help
        sys.exit(2)
    except ClickException as exc:  # a flag typer could not parse: one line, like ours
        ctx = getattr(exc, "ctx", None)
        hint = f" (see {ctx.command_path} --help)" if ctx is not None else ""
        _error(" ".join(exc.format_message().split()) + hint)
    except Abort:  # typer's own abort (input ended while it prompted)
        err_console.print("aborted", markup=False, highlight=False)
        sys.exit(1)
    except InputError as exc:
        _error(str(exc))
    except OSError as exc:  # a path the system refused (no space, read-only, a directory)
        where = f"{exc.filename}: " if exc.filename else ""
        _error(f"{where}{exc.strerror or one_line(exc)}")
    sys.exit(code if isinstance(code, int) else 0)


def _error(message: str) -> NoReturn:
    err_console.print(f"error: {message}", markup=False, highlight=False, soft_wrap=True)
    sys.exit(2)
