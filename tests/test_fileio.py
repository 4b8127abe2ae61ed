"""Atomic writes: all files or the previous ones, never a half-written file or a temporary."""

from __future__ import annotations

import numpy as np
import pytest

from relaxgrip.fileio import file_entry, npz_bytes, write_files_atomically, write_text_atomically


def test_files_land_together_and_no_temporary_is_left(tmp_path) -> None:
    data = npz_bytes({"w": np.arange(3.0)})
    write_files_atomically(tmp_path, [("a.npz", data), ("manifest.json", b"{}\n")])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npz", "manifest.json"]
    with np.load(tmp_path / "a.npz") as z:
        np.testing.assert_array_equal(z["w"], [0.0, 1.0, 2.0])
    entry = file_entry("a.npz", data)
    assert entry["bytes"] == len(data)
    assert len(entry["sha256"]) == 64


def test_a_failure_keeps_the_previous_file(tmp_path) -> None:
    target = tmp_path / "report.md"
    write_text_atomically(target, "old")

    with pytest.raises(TypeError):
        write_files_atomically(tmp_path, [("report.md", b"new"), ("second", None)])  # type: ignore[list-item]
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["report.md"]


def test_written_files_get_the_umasks_mode_not_a_private_one(tmp_path) -> None:
    import os

    old = os.umask(0o022)
    try:
        write_text_atomically(tmp_path / "report.md", "x")
    finally:
        os.umask(old)
    assert (tmp_path / "report.md").stat().st_mode & 0o777 == 0o644
