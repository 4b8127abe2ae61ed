"""Input files that are not regular files, or far too large, give one error line at once.

A FIFO without a writer blocks whoever opens it, ``/dev/zero`` and
``/dev/urandom`` never end: each command that reads a file refuses them by
name before opening them (:func:`relaxgrip.fileio.check_input_file`).  The
commands that could hang or fill the memory, were the check lost, run in a
child process with a timeout and a cap on its memory.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from relaxgrip.errors import InputError
from relaxgrip.fileio import check_input_file
from relaxgrip.hardware.rig_file import MAX_RIG_BYTES, load_rig
from tests.clitools import assert_one_error_line, run_main

DOCS = Path(__file__).resolve().parents[1] / "docs"
#: Address space the child may take: four times what these commands need (under 1 GiB with
#: one BLAS thread), so that reading ``/dev/zero``, were a check lost, ends in a MemoryError
#: within seconds rather than in the machine's memory.
CHILD_MEMORY_BYTES = 4 << 30
#: One thread per thread pool: the address space the child needs does not grow with the cores.
ONE_THREAD = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                      "MKL_NUM_THREADS")}


def _cap_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (CHILD_MEMORY_BYTES, CHILD_MEMORY_BYTES))


def _run(*args: str | Path, pass_fds: tuple[int, ...] = ()) -> tuple[int, str, str]:
    """``python -m relaxgrip ARGS`` in a child that may not hang (60 s) nor fill the memory."""
    done = subprocess.run([sys.executable, "-m", "relaxgrip", *map(str, args)],
                          capture_output=True, text=True, timeout=60.0, check=False,
                          env={**os.environ, **ONE_THREAD}, stdin=subprocess.DEVNULL,
                          pass_fds=pass_fds, preexec_fn=_cap_memory)
    return done.returncode, done.stdout, done.stderr


@pytest.fixture
def fifo(tmp_path: Path) -> Path:
    """A FIFO nobody writes to: opening it for reading blocks for ever."""
    path = tmp_path / "input"
    os.mkfifo(path)
    return path


@pytest.mark.parametrize("command", [
    ["replay", "{fifo}"],
    ["recover", "{fifo}", "{tmp}/out.mcap"],
    ["dataset", "from-recordings", "{fifo}", "--out", "{tmp}/data"],
    ["check-rig", "{fifo}"],
    ["perceive", "{fifo}"],
    ["fit-relaxation", "{fifo}"],
], ids=lambda command: command[0])
def test_a_fifo_is_refused_at_once(command: list[str], fifo: Path, tmp_path: Path) -> None:
    args = [a.format(fifo=fifo, tmp=tmp_path) for a in command]
    assert_one_error_line(*_run(*args), f"{fifo}: is a FIFO, not a regular file")
    assert sorted(tmp_path.iterdir()) == [fifo]  # no output begun


def test_a_pipe_is_refused_not_taken_for_a_truncated_recording(tmp_path: Path) -> None:
    """``relaxgrip replay <(cat rec.mcap)``: the shell gives a pipe's /dev/fd path."""
    read_fd, write_fd = os.pipe()
    try:
        os.write(write_fd, b"\x89MCAP0\r\n")  # what a recording begins with; the rest never comes
        code, out, err = _run("replay", f"/dev/fd/{read_fd}", pass_fds=(read_fd,))
    finally:
        os.close(read_fd)
        os.close(write_fd)
    assert_one_error_line(code, out, err, f"/dev/fd/{read_fd}: is a FIFO, not a regular file")


@pytest.mark.parametrize(("command", "device"), [
    (["check-rig", "/dev/zero"], "/dev/zero"),
    (["check-rig", "/dev/urandom"], "/dev/urandom"),
    (["emulator", "--rig", "/dev/zero", "--duration-s", "1"], "/dev/zero"),
    (["dashboard", "--backend", "serial:/dev/zero"], "/dev/zero"),
    (["perceive", "/dev/zero"], "/dev/zero"),
], ids=["check-rig-zero", "check-rig-urandom", "emulator-rig", "dashboard-rig", "perceive"])
def test_a_device_is_refused_unread(command: list[str], device: str) -> None:
    assert_one_error_line(*_run(*command), f"{device}: is a character device, not a regular file")


def test_an_oversize_rig_file_is_refused_unread(tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    big = tmp_path / "rig.toml"
    big.write_bytes(b"#" * (2 << 20))
    code, out, err = run_main(["check-rig", big], monkeypatch, capsys)
    assert_one_error_line(code, out, err,
                          f"{big}: is 2,097,152 bytes, over the 1 MiB limit for a rig file")


def test_a_rig_file_at_the_limit_is_read(tmp_path: Path) -> None:
    path = tmp_path / "rig.toml"
    path.write_bytes(b"#" * (MAX_RIG_BYTES - 1) + b"\n")  # one long comment: valid TOML
    with pytest.raises(InputError, match=r"table \[serial\] is missing"):
        load_rig(path)


def test_a_rig_file_not_utf8_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "rig.toml"
    path.write_bytes(b"[rig]\nname = \"caf\xe9\"\n")  # Latin-1
    code, out, err = run_main(["check-rig", path], monkeypatch, capsys)
    assert_one_error_line(code, out, err,
                          f"rig file {path} is not UTF-8 text (byte 0xe9 at offset 17)")


def test_a_link_to_a_rig_file_is_read(tmp_path: Path) -> None:
    link = tmp_path / "rig.toml"
    link.symlink_to(DOCS / "rig-emulator.toml")
    assert load_rig(link).geometry == load_rig(DOCS / "rig-emulator.toml").geometry


@pytest.mark.parametrize("command", [["replay", "{dir}"], ["recover", "{dir}", "{tmp}/o.mcap"]])
def test_a_directory_is_not_a_recording(command: list[str], tmp_path: Path,
                                        monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "rec.mcap"
    folder.mkdir()
    args: list[str | Path] = [a.format(dir=folder, tmp=tmp_path) for a in command]
    code, out, err = run_main(args, monkeypatch, capsys)
    assert_one_error_line(code, out, err, f"{folder}: is a directory, not a recording")
    assert sorted(tmp_path.iterdir()) == [folder]


def test_check_input_file(tmp_path: Path, fifo: Path) -> None:
    data = tmp_path / "data.bin"
    data.write_bytes(b"x" * 2048)
    link = tmp_path / "link"
    link.symlink_to(data)
    assert check_input_file(link, "table", ValueError, max_bytes=2048) == link
    for path, message in (
        (tmp_path / "absent", "no such table"),
        (data / "below-a-file", "no such table"),
        (tmp_path, "is a directory, not a table"),
        (fifo, "is a FIFO, not a regular file"),
        (Path("/dev/null"), "is a character device, not a regular file"),
    ):
        with pytest.raises(ValueError, match=f"^{path}: {message}$"):
            check_input_file(path, "table", ValueError)
    with pytest.raises(ValueError, match=f"^{data}: is 2,048 bytes, over the 1 KiB limit for a "
                                         "table$"):
        check_input_file(data, "table", ValueError, max_bytes=1024)
    with pytest.raises(ValueError, match="is a directory, not an image"):
        check_input_file(tmp_path, "image", ValueError)
