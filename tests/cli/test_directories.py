"""A file given where a directory is expected is named as such, in every command that reads one."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.clitools import run_main


@pytest.mark.parametrize(("args", "what"), [
    (["train", "--data", "{f}", "--out", "{d}/m"], "a dataset directory"),
    (["evaluate", "--data", "{f}"], "a dataset directory"),
    (["fit-observer", "--data", "{f}", "--out", "{d}/o"], "a dataset directory"),
    (["hold", "--models", "{f}", "--duration-s", "5"], "a model directory"),
    (["hold", "--estimator", "observer", "--observer", "{f}", "--duration-s", "5"],
     "an observer model directory"),
    (["calibrate-hold", "{f}", "--dry-run"], "a model directory"),
    (["calibrate-band", "{f}", "--dry-run"], "an observer model directory"),
    (["evaluate", "--data", "{d}/none"], None),
])
def test_a_file_where_a_directory_is_expected_is_named(monkeypatch, capsys, tmp_path: Path,
                                                       args: list[str], what: str | None):
    a_file = tmp_path / "notes.txt"
    a_file.write_text("not a directory\n")
    argv: list[str | Path] = [a.format(f=a_file, d=tmp_path) for a in args]
    code, _, err = run_main(argv, monkeypatch, capsys)
    assert code == 2
    if what is None:
        assert err == f"error: {tmp_path / 'none'}: no such dataset directory\n"
    else:
        assert err == f"error: {a_file}: a file, not a directory ({what} is expected)\n"
