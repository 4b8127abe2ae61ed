"""The typer application shared by every command module."""

from __future__ import annotations

import json
import sys
from typing import Any

import typer
from rich.console import Console

from relaxgrip.serialize import json_safe

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


def emit_json(obj: dict[str, Any]) -> None:
    """Print exactly one JSON object on standard output."""
    sys.stdout.write(json.dumps(json_safe(obj), allow_nan=False) + "\n")
    sys.stdout.flush()
