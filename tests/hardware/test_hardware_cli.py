"""``check-rig`` and ``hold --backend``: bad input is one line and exit 2."""

from __future__ import annotations

import contextlib
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

import relaxgrip.hardware.emulator as emulator_module
from tests.clitools import assert_one_error_line, run_main

DOCS = Path(__file__).resolve().parents[2] / "docs"
OURS = DOCS / "rigs" / "relaxgrip.toml"


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "relaxgrip", *args], capture_output=True,
                          text=True, timeout=120, check=False)


def test_check_rig_bad_file_and_missing_device(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(OURS.read_text(encoding="utf-8")
                   .replace("fps = 30.0", "fps = -1.0"), encoding="utf-8")
    out = _run("check-rig", str(bad))
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0
    assert "[rgb] fps must be > 0" in out.stderr
    if Path("/dev/ttyACM0").exists():  # a real MCU is plugged in: nothing is missing
        return
    out = _run("check-rig", str(OURS))
    assert out.returncode == 2
    assert "cannot open serial port /dev/ttyACM0" in out.stderr


def test_check_rig_exits_1_when_the_files_marker_is_not_on_the_frame(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    import relaxgrip.perception.rig_check as rig_check

    def missing(rig: object) -> rig_check.RigCheck:
        return rig_check.RigCheck("example", "/dev/ttyACM0", "fw 1", 200, 20.0, [], (480, 640, 3),
                                  (192, 256), (24.0, 25.0, 26.0), 3, False, float("nan"),
                                  float("nan"), float("nan"), [0])

    monkeypatch.setattr(rig_check, "check_rig", missing)
    code, out, err = run_main(["check-rig", OURS], monkeypatch, capsys)
    assert code == 1, err
    assert "marker id 3" in out
    assert "NOT FOUND (the frame shows id 0" in " ".join(out.split())
    code, out, err = run_main(["check-rig", OURS, "--json"], monkeypatch,
                              capsys)
    assert code == 1
    assert '"marker_ids_seen": [' in out


def test_hold_rejects_an_unknown_backend() -> None:
    out = _run("hold", "--backend", "robot", "--duration-s", "10")
    assert out.returncode == 2
    assert "--backend must be twin, emulator or serial:RIG.toml, got 'robot'" in out.stderr


def _emulator_rig(tmp_path: Path, port: Path, socket: Path) -> Path:
    text = (DOCS / "rig-emulator.toml").read_text(encoding="utf-8")
    text = (text.replace('"/tmp/relaxgrip-emulator/tty"', f'"{port}"')
            .replace('"/tmp/relaxgrip-emulator/frames.sock"', f'"{socket}"'))
    rig = tmp_path / "rig.toml"
    rig.write_text(text, encoding="utf-8")
    return rig


def test_emulator_cleans_up_its_link_and_socket(tmp_path: Path) -> None:
    port, sock = tmp_path / "dev" / "tty", tmp_path / "run" / "frames.sock"
    port.parent.mkdir()
    sock.parent.mkdir()
    out = _run("emulator", "--rig", str(_emulator_rig(tmp_path, port, sock)),
               "--duration-s", "0.3")
    assert out.returncode == 0, out.stderr
    assert f"linked from {port}" in out.stdout
    assert not port.is_symlink()
    assert not sock.exists()


def test_emulator_leaves_files_it_did_not_make_alone(tmp_path: Path) -> None:
    port, sock = tmp_path / "tty", tmp_path / "results.csv"
    sock.write_text("t,f\n1,2\n", encoding="utf-8")
    out = _run("emulator", "--rig", str(_emulator_rig(tmp_path, port, sock)), "--duration-s", "5")
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0
    assert "frame channel socket" in out.stderr
    assert "not a socket" in out.stderr
    assert sock.read_text(encoding="utf-8") == "t,f\n1,2\n"

    (tmp_path / "device").write_text("", encoding="utf-8")
    port.symlink_to("device")
    out = _run("emulator", "--rig", str(_emulator_rig(tmp_path, port, tmp_path / "f.sock")),
               "--duration-s", "5")
    assert out.returncode == 2
    assert "is a link to device, not to an emulator's pseudo-terminal" in out.stderr
    assert port.is_symlink()

    long_sock = tmp_path / ("d" * 110) / "frames.sock"
    out = _run("emulator", "--rig", str(_emulator_rig(tmp_path, tmp_path / "tty2", long_sock)),
               "--duration-s", "5")
    assert out.returncode == 2
    assert "107 bytes a Unix socket path may have" in out.stderr
    assert not (tmp_path / "tty2").exists()


def test_a_second_emulator_does_not_take_the_first_one_s_socket(tmp_path: Path) -> None:
    import time

    sock = tmp_path / "frames.sock"
    first = subprocess.Popen([sys.executable, "-m", "relaxgrip", "emulator", "--rig",
                              str(_emulator_rig(tmp_path, tmp_path / "tty", sock)),
                              "--duration-s", "30"], stdout=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30.0
        while not sock.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert sock.exists()
        out = _run("emulator", "--rig", str(_emulator_rig(tmp_path, tmp_path / "tty2", sock)),
                   "--duration-s", "1")
        assert out.returncode == 2
        assert "another emulator is serving it" in out.stderr
        assert sock.exists()  # the first one's, untouched
        assert first.poll() is None
    finally:
        first.terminate()
        first.wait(10)


@pytest.mark.parametrize("missing", ["port", "socket"])
def test_emulator_makes_no_folders_for_a_rig_file(tmp_path: Path, missing: str) -> None:
    port, sock = tmp_path / "tty", tmp_path / "frames.sock"
    if missing == "port":
        port = tmp_path / "nodir" / "a" / "tty"
    else:
        sock = tmp_path / "nodir" / "a" / "frames.sock"
    out = _run("emulator", "--rig", str(_emulator_rig(tmp_path, port, sock)),
               "--duration-s", "5")
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0
    what = "[serial] port" if missing == "port" else "frame channel socket"
    assert f"{what} {tmp_path / 'nodir' / 'a'}" in out.stderr
    assert f"directory {tmp_path / 'nodir' / 'a'} does not exist" in out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]


@pytest.mark.parametrize("duration", ["inf", "1e308", "nan", "0", "86401"])
def test_emulator_duration_is_finite_and_at_most_a_day(
        duration: str, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_main(["emulator", "--duration-s", duration], monkeypatch, capsys)
    assert_one_error_line(code, out, err, "--duration-s must be > 0 and at most 86400 s")


def test_emulator_makes_and_removes_its_default_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "relaxgrip-emulator"
    monkeypatch.setattr(emulator_module, "EMULATOR_DIR", folder)
    code, out, err = run_main(["emulator", "--duration-s", "0.2"], monkeypatch, capsys)
    assert code == 0, err
    assert f"frames: {folder / 'frames.sock'}" in out
    assert not folder.exists()


def _dispositions(ignored: signal.Signals) -> None:
    """The stop signals as a terminal sets them, ``ignored`` ignored: whatever this test run
    was started with (``nohup`` hands SIGHUP ignored down, a shell's ``&`` SIGINT)."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN if sig == ignored else signal.SIG_DFL)


@contextlib.contextmanager
def _emulator_process(tmp_path: Path, ignored: signal.Signals
                      ) -> Iterator[tuple[subprocess.Popen[str], Path, Path]]:
    """``relaxgrip emulator`` in a process started with ``ignored`` ignored (as a shell's
    ``&`` starts a command with SIGINT, ``nohup`` with SIGHUP), once its link and socket are
    up; with its link and socket paths.  Killed if still running after."""
    import time

    port, sock = tmp_path / "tty", tmp_path / "frames.sock"
    proc = subprocess.Popen([sys.executable, "-m", "relaxgrip", "emulator", "--rig",
                             str(_emulator_rig(tmp_path, port, sock))],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: _dispositions(ignored))
    try:
        deadline = time.monotonic() + 60.0
        while not (sock.exists() and port.is_symlink()) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert sock.exists()
        time.sleep(0.3)
        yield proc, port, sock
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_emulator_stopped_by_a_signal_removes_its_link_and_socket(
        tmp_path: Path, sig: signal.Signals) -> None:
    # SIGINT ignored, as a shell starts a command with ``&``: the emulator still stops on it.
    with _emulator_process(tmp_path, signal.SIGINT) as (proc, port, sock):
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert not sock.exists()
    assert not port.is_symlink()


def test_emulator_started_with_nohup_outlives_its_terminal(tmp_path: Path) -> None:
    import time

    # SIGHUP ignored, as ``nohup`` starts a command: a closed terminal must not stop it.
    with _emulator_process(tmp_path, signal.SIGHUP) as (proc, port, sock):
        proc.send_signal(signal.SIGHUP)
        time.sleep(1.0)
        assert proc.poll() is None, "the hang-up stopped the emulator"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert not sock.exists()
    assert not port.is_symlink()
