"""Atomic writes: all files or the previous ones, never a half-written file or a temporary."""

from __future__ import annotations

import errno
import os
import socket
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.fileio import (
    atomic_file,
    check_output_dir,
    check_replaceable,
    check_writable,
    file_entry,
    made_directory,
    npz_bytes,
    write_files_atomically,
    write_text_atomically,
)


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


def test_atomic_file_appears_whole_or_not_at_all(tmp_path) -> None:
    target = tmp_path / "big.bin"
    target.write_bytes(b"old")

    def killed_mid_write() -> None:
        with atomic_file(target) as fh:
            fh.write(b"half")
            raise RuntimeError("killed")

    with pytest.raises(RuntimeError):
        killed_mid_write()
    assert target.read_bytes() == b"old"
    with atomic_file(target) as fh:
        fh.write(b"new")
    assert target.read_bytes() == b"new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.bin"]


def test_check_writable_probes_the_place_and_leaves_nothing(tmp_path) -> None:
    check_writable(tmp_path / "not" / "yet" / "there.png", ValueError)
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError, match="is not a directory"):
        check_writable(tmp_path / "file" / "out.png", ValueError)
    with pytest.raises(ValueError, match=r"/proc/x\.png: cannot write in /proc"):
        check_writable(Path("/proc/x.png"), ValueError)


def test_special_files_are_never_replaced_by_a_rename(tmp_path) -> None:
    fifo = tmp_path / "out.png"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match=f"^{fifo} is a FIFO, not a regular file: choose "
                                         "another output$"):
        check_writable(fifo, ValueError)
    with pytest.raises(OSError, match="is a FIFO, not a regular file to replace"):
        write_files_atomically(tmp_path, [("a.txt", b"a"), ("out.png", b"png")])
    with pytest.raises(OSError, match="is a FIFO"), atomic_file(fifo) as fh:
        fh.write(b"data")
    with pytest.raises(ValueError, match="is a directory, not a regular file"):
        check_replaceable(tmp_path, ValueError)
    with pytest.raises(ValueError, match="is a character device"):
        check_replaceable(Path("/dev/null"), ValueError)  # checked only, never written
    sock = socket.socket(socket.AF_UNIX)
    try:
        sock.bind(str(tmp_path / "s"))
        with pytest.raises(ValueError, match="is a socket"):
            check_replaceable(tmp_path / "s", ValueError)
    finally:
        sock.close()
    # Nothing written, nothing replaced; a regular file or a link to one stays replaceable.
    assert fifo.is_fifo()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.png", "s"]
    (tmp_path / "f.txt").write_text("old")
    (tmp_path / "link.txt").symlink_to(tmp_path / "f.txt")
    check_replaceable(tmp_path / "f.txt", ValueError)
    check_replaceable(tmp_path / "link.txt", ValueError)
    check_replaceable(tmp_path / "absent.txt", ValueError)


def test_check_output_dir_replaces_only_its_own_outputs(tmp_path) -> None:
    own = ("a.npz", "manifest.json")
    out = tmp_path / "models"
    assert check_output_dir(out, "fmt", own, ValueError) == out  # absent
    out.mkdir()
    check_output_dir(out, "fmt", own, ValueError)  # empty
    (out / "manifest.json").write_text('{"format": "other"}')
    with pytest.raises(ValueError, match="holds no fmt output"):
        check_output_dir(out, "fmt", own, ValueError)
    (out / "manifest.json").write_text('{"format": "fmt"}')
    (out / "a.npz").write_bytes(b"")
    check_output_dir(out, "fmt", own, ValueError)  # an earlier output: replaced
    (out / "notes.txt").write_text("mine")
    with pytest.raises(ValueError, match=r"holds files that are not the fmt output's \(notes"):
        check_output_dir(out, "fmt", own, ValueError)
    with pytest.raises(ValueError, match="exists and is not a directory"):
        check_output_dir(out / "notes.txt", "fmt", own, ValueError)


def test_a_full_disk_names_the_file_it_was_writing(tmp_path, monkeypatch) -> None:
    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")  # names no file

    write_text_atomically(tmp_path / "report.md", "old")
    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError, match="No space left") as caught:
        write_files_atomically(tmp_path, [("report.md", b"new")])
    assert caught.value.filename == str(tmp_path / "report.md")
    assert (tmp_path / "report.md").read_text() == "old"
    with pytest.raises(OSError, match="No space left") as caught, \
            atomic_file(tmp_path / "big.bin") as fh:
        fh.write(b"x")
    assert caught.value.filename == str(tmp_path / "big.bin")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.md"]


def test_a_failed_output_leaves_no_folder_it_made(tmp_path) -> None:
    kept = tmp_path / "kept"
    kept.mkdir()

    def fail_in(folder: Path, theirs: bool = False) -> None:
        with made_directory(folder) as out:
            assert out.is_dir()
            if theirs:
                (out / "theirs").write_text("keep")
            raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OSError, match="No space left"):
        fail_in(kept / "a" / "b")
    assert list(kept.iterdir()) == []  # a and b are gone, the folder that was there stays
    with made_directory(kept / "c") as out:
        (out / "x").write_text("done")
    assert (kept / "c" / "x").read_text() == "done"
    with pytest.raises(OSError, match="No space left"):
        fail_in(kept / "d", theirs=True)
    assert (kept / "d" / "theirs").is_file()  # someone else's file keeps its folder
