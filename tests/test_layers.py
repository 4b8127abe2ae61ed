"""Imports flow one way: no module imports a layer above its own (DESIGN.md's layers)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "relaxgrip"

#: Each top-level module or subpackage of relaxgrip and its layer, lowest first.
LAYERS: dict[str, int] = {
    **dict.fromkeys(("__init__", "errors", "validate", "rig", "board", "clock", "backend",
                     "serialize", "fileio", "metrics", "interrupts", "limits"), 0),
    "physics": 1,
    "twin": 2,
    "hardware": 3,
    "perception": 4,
    "learning": 5,
    "control": 6,
    "recording": 7,
    "experiments": 8,
    "plots": 9,
    **dict.fromkeys(("reproduce", "bench", "dashboard", "bringup"), 10),
    **dict.fromkeys(("cli", "__main__"), 11),
}


def _unit(path: Path) -> str:
    parts = path.relative_to(PACKAGE).parts
    return parts[0].removesuffix(".py")


def _imported_units(tree: ast.AST) -> set[str]:
    units = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            parts = node.module.split(".")
            if parts[0] != "relaxgrip":
                continue
            units |= {parts[1]} if len(parts) > 1 else {"__init__"}
        elif isinstance(node, ast.Import):
            units |= {a.name.split(".")[1] for a in node.names if a.name.startswith("relaxgrip.")}
    return units


MODULES = sorted(PACKAGE.rglob("*.py"))


def test_every_module_has_a_layer() -> None:
    missing = {_unit(p) for p in MODULES} - LAYERS.keys()
    assert not missing, f"give these a layer in tests/test_layers.py: {sorted(missing)}"


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_import_reaches_a_higher_layer(path: Path) -> None:
    own = _unit(path)
    upward = sorted(u for u in _imported_units(ast.parse(path.read_text()))
                    if LAYERS.get(u, -1) > LAYERS[own])
    assert not upward, f"{own} (layer {LAYERS[own]}) imports higher layers: {upward}"
