"""Running ``relaxgrip`` from tests: as a subprocess, or in-process through :func:`main`.

Both paths take the same route from :class:`relaxgrip.errors.InputError` to one
``error:`` line on standard error and exit code 2.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from relaxgrip.cli import main

# The repository is cloned with the shared folder beside it: <repo>/../shared.
SHARED_DIR = Path(__file__).resolve().parents[2] / "shared"


def run_cli(*args: str | Path, timeout_s: float = 300.0) -> subprocess.CompletedProcess[str]:
    """``python -m relaxgrip ARGS`` in a fresh interpreter."""
    return subprocess.run(
        [sys.executable, "-m", "relaxgrip", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        check=False,
    )


def run_main(
    args: list[str | Path], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> tuple[int, str, str]:
    """``relaxgrip ARGS`` in-process: exit code, stdout, stderr."""
    monkeypatch.setattr(sys, "argv", ["relaxgrip", *map(str, args)])
    code: int | str | None = 0
    try:
        main()
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return (code if isinstance(code, int) else 1), out, err


def assert_one_error_line(code: int, out: str, err: str, expected: str) -> None:
    """Exit code 2, nothing on stdout, one ``error:`` line naming ``expected``, no traceback."""
    assert code == 2, (code, err)
    assert out == ""
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ")
    assert expected in lines[0]


def assert_refused_unchanged(args: list[str], expected: str, source: Path, tmp_path: Path,
                             monkeypatch: pytest.MonkeyPatch,
                             capsys: pytest.CaptureFixture[str]) -> None:
    """Bad input on a copy of the model directory ``source``: one error line, its manifest intact.

    ``{dir}`` in ``args`` is the copy, ``{missing}`` a path that does not exist.
    """
    import shutil

    directory = tmp_path / "dir"
    shutil.copytree(source, directory)
    before = (directory / "manifest.json").read_bytes()
    filled: list[str | Path] = [a.format(dir=directory, missing=tmp_path / "missing")
                                for a in args]
    assert_one_error_line(*run_main(filled, monkeypatch, capsys), expected)
    assert (directory / "manifest.json").read_bytes() == before
