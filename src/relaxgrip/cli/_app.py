"""The typer application shared by every command module."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from typing import Any

import typer
from rich.console import Console

from relaxgrip.serialize import json_safe
from relaxgrip.validate import parse_integer, parse_number

app = typer.Typer(
    name="relaxgrip",
    help="Variable-stiffness soft gripper with relaxation-aware force sensing.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
# No emoji codes: paths and values the user typed (``push:abc:1``) are printed as typed.
console = Console(emoji=False)
err_console = Console(stderr=True, emoji=False)


def _print_version(value: bool) -> None:
    if value:
        from relaxgrip import __version__

        sys.stdout.write(f"relaxgrip {__version__}\n")
        raise typer.Exit()


@app.callback()
def main(
    version: bool = typer.Option(False, "--version", callback=_print_version, is_eager=True,
                                 help="Print relaxgrip's version and exit."),
) -> None:
    """Variable-stiffness soft gripper with relaxation-aware force sensing."""


def emit_json(obj: dict[str, Any]) -> None:
    """Print exactly one JSON object on standard output."""
    sys.stdout.write(json.dumps(json_safe(obj), allow_nan=False) + "\n")
    sys.stdout.flush()


def _strictly(parse: Callable[[str], Any], kind: type) -> Callable[[Any], Any]:
    """A typer parser: ``parse`` on the text, its ValueError a bad parameter (one line)."""

    def convert(value: Any) -> Any:
        if isinstance(value, kind) and not isinstance(value, bool):  # a default
            return value
        try:
            return parse(str(value))
        except ValueError as exc:
            raise typer.BadParameter(str(exc)) from None

    return convert


def float_option(*decls: str, **kwargs: Any) -> Any:
    """``typer.Option`` for a number: typer's own float() would take ``0_5`` as 5."""
    kwargs.setdefault("metavar", "<float>")
    return typer.Option(*decls, parser=_strictly(parse_number, float), **kwargs)


def int_option(*decls: str, **kwargs: Any) -> Any:
    """``typer.Option`` for an integer: typer's own int() would take ``1_0`` as 10."""
    kwargs.setdefault("metavar", "<int>")
    return typer.Option(*decls, parser=_strictly(parse_integer, int), **kwargs)
