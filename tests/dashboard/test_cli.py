"""``relaxgrip dashboard``: a public address needs --allow-remote; a missing extra is named."""

from __future__ import annotations

import contextlib
import json
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from relaxgrip.cli import app
from relaxgrip.cli.dashboard import check_host, is_loopback
from relaxgrip.dashboard import require_web_stack
from relaxgrip.errors import InputError


def _free_port() -> int:
    """A loopback port no one listens on now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
    return port


@contextlib.contextmanager
def _dashboard(record_dir: Path) -> Iterator[tuple[subprocess.Popen[str], int]]:
    """``relaxgrip dashboard`` started on a free loopback port, and that port; killed on the
    way out if it is still running."""
    port = _free_port()
    proc = subprocess.Popen([sys.executable, "-m", "relaxgrip", "dashboard", "--port", str(port),
                             "--record-dir", str(record_dir)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        yield proc, port
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)


def _viewer(proc: subprocess.Popen[str], port: int) -> Any:
    """A WebSocket client of the dashboard, once it listens (within a minute)."""
    sync_client = pytest.importorskip("websockets.sync.client")
    deadline = time.monotonic() + 60.0
    while True:
        try:
            return sync_client.connect(f"ws://127.0.0.1:{port}/ws", max_size=None)
        except OSError:
            assert time.monotonic() < deadline
            assert proc.poll() is None
            time.sleep(0.1)


def _reply(ws: Any, message: dict[str, Any]) -> Any:
    """Send a control to the dashboard and wait for its reply (state pushes are skipped)."""
    ws.send(json.dumps(message))
    while (msg := json.loads(ws.recv(timeout=10)))["type"] != "reply":
        pass
    return msg


def test_public_host_needs_allow_remote() -> None:
    result = CliRunner().invoke(app, ["dashboard", "--host", "0.0.0.0"])
    assert isinstance(result.exception, InputError)
    assert "--allow-remote" in str(result.exception)
    assert is_loopback("127.0.0.1")
    assert is_loopback("::1")
    assert is_loopback("localhost")
    assert not is_loopback("0.0.0.0")
    assert not is_loopback("example.org")


def test_missing_web_stack_is_a_helpful_error(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "fastapi", None)
    with pytest.raises(InputError, match=r"pip install 'relaxgrip\[dashboard\]'"):
        require_web_stack()


def test_a_port_in_use_is_refused_before_the_session_opens(monkeypatch) -> None:
    import relaxgrip.dashboard.session as session_module

    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError("the session opened")

    monkeypatch.setattr(session_module, "open_session", never)
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    try:
        port = busy.getsockname()[1]
        result = CliRunner().invoke(app, ["dashboard", "--port", str(port)])
    finally:
        busy.close()
    assert isinstance(result.exception, InputError)
    assert f"cannot serve on 127.0.0.1:{port}: Address already in use" in str(result.exception)
    result = CliRunner().invoke(app, ["dashboard", "--host", "nosuchhost.invalid",
                                      "--allow-remote"])
    assert isinstance(result.exception, InputError)
    assert "--host nosuchhost.invalid" in str(result.exception)


@pytest.mark.parametrize("host", ["not a host", "", "999.1.1.1", "1.2.3", "-rig", "a..b",
                                  "[::1]", "rig_1.lab"])
def test_an_invalid_host_is_named_before_the_remote_check(host: str) -> None:
    result = CliRunner().invoke(app, ["dashboard", "--host", host])
    assert isinstance(result.exception, InputError)
    assert str(result.exception) == (f"--host {host!r} is an invalid host: give an IP address "
                                     "(127.0.0.1, ::1) or a host name")


@pytest.mark.parametrize("host", ["localhost", "127.0.0.1", "::1", "0.0.0.0", "example.org",
                                  "rig-1.lab.", "x1"])
def test_addresses_and_host_names_are_valid_hosts(host: str) -> None:
    assert check_host(host) == host


@pytest.mark.parametrize(("flag", "expected"), [("--observer", "not an observer model directory"),
                                                ("--models", "no such model directory")])
def test_a_missing_model_directory_is_named_and_the_port_freed(flag: str, expected: str,
                                                               tmp_path) -> None:
    port = _free_port()
    result = CliRunner().invoke(app, ["dashboard", "--port", str(port), "--record-dir",
                                      str(tmp_path), flag, str(tmp_path / "none")])
    assert isinstance(result.exception, InputError)
    assert expected in str(result.exception)
    again = socket.socket()
    again.bind(("127.0.0.1", port))  # the dashboard's listener was closed
    again.close()


def test_a_recording_directory_is_checked_before_the_dashboard_serves(tmp_path) -> None:
    # Recording starts at a click long after start-up: a folder it cannot write is named now.
    a_file = tmp_path / "notes.txt"
    a_file.write_text("not a folder\n")

    port = _free_port()
    for record_dir, expected in ((a_file, f"recording directory {a_file} is not a directory"),
                                 (tmp_path / "none", "does not exist"),
                                 (Path("/sys"), "cannot write in /sys")):
        result = CliRunner().invoke(app, ["dashboard", "--port", str(port), "--record-dir",
                                          str(record_dir)])
        assert isinstance(result.exception, InputError), result.output
        assert expected in str(result.exception)


def test_a_second_ctrl_c_still_stops_the_session_without_a_traceback(tmp_path) -> None:
    # uvicorn's force quit skipped the app's shutdown; its lifespan was cancelled, with a
    # traceback. The shutdown (motor stopped, heaters off, recording closed) still runs.
    pytest.importorskip("websockets.sync.client")
    with _dashboard(tmp_path) as (proc, port), _viewer(proc, port) as ws:
        reply = _reply(ws, {"id": 1, "op": "record", "value": True})
        assert reply["ok"], reply
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        time.sleep(0.05)
        proc.send_signal(signal.SIGINT)  # while uvicorn closes the connections
        _, err = proc.communicate(timeout=30)
    assert "Traceback" not in err, err
    from relaxgrip.recording import read_session

    assert read_session(Path(reply["path"]))["backend"]["name"] == "twin"  # closed, readable


def _server_frames(stream: Any) -> Iterator[tuple[int, bytes]]:
    """Opcode and payload of each frame a server sends (unmasked, whole), until it closes."""
    while head := stream.read(2):
        length = head[1] & 0x7F
        if length >= 126:
            length = int.from_bytes(stream.read(2 if length == 126 else 8), "big")
        yield head[0] & 0x0F, stream.read(length)


def test_invalid_utf8_from_a_client_is_one_line_and_the_others_are_served(tmp_path) -> None:
    # uvicorn decodes a text frame before the app sees it: on invalid UTF-8 it closed the
    # connection with 1007 and logged the decoding's traceback, for a client's bad byte.
    import base64

    pytest.importorskip("websockets.sync.client")
    target = {"op": "target", "value": 3.0}
    with _dashboard(tmp_path) as (proc, port):
        with (_viewer(proc, port) as ws,
              socket.create_connection(("127.0.0.1", port), timeout=10) as raw):
            stream = raw.makefile("rb")
            key = base64.b64encode(b"sixteen byte key").decode()
            raw.sendall(f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                        f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                        "Sec-WebSocket-Version: 13\r\n\r\n".encode())
            assert stream.readline().startswith(b"HTTP/1.1 101")
            while stream.readline() not in (b"\r\n", b""):
                pass
            raw.sendall(bytes([0x81, 0x82, 0, 0, 0, 0]) + b"\xff\xfe")  # text, zero mask
            close = next(data for opcode, data in _server_frames(stream) if opcode == 0x8)
            assert int.from_bytes(close[:2], "big") == 1007
            assert _reply(ws, {"id": 1, **target}) == {"type": "reply", "id": 1, "ok": True,
                                                        "error": None}
            with _viewer(proc, port) as again:  # the server runs on
                assert _reply(again, {"id": 2, **target})["ok"]
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    assert "Traceback" not in err, err
    told = [line for line in err.splitlines() if "UTF-8" in line]
    assert len(told) == 1, err
    assert "WebSocket client sent a text frame that is not UTF-8" in told[0]
    assert "1007" in told[0]


def test_a_decoding_error_of_the_application_keeps_its_traceback() -> None:
    import logging

    from relaxgrip.cli.dashboard import _InvalidTextFilter

    try:
        b"\xff".decode()
    except UnicodeDecodeError:
        record = logging.LogRecord("uvicorn.error", logging.ERROR, __file__, 1,
                                   "Exception in ASGI application\n", None, sys.exc_info())
    assert _InvalidTextFilter().filter(record)
    assert record.exc_info is not None
    assert record.levelno == logging.ERROR
    assert record.getMessage() == "Exception in ASGI application\n"


def test_the_session_runs_the_twin_of_the_rig_given(make_session) -> None:
    from relaxgrip.clock import WallClock
    from relaxgrip.dashboard.session import open_session
    from relaxgrip.twin import GripperTwin
    from tests.rigs import twin_of

    lab = twin_of("lab")
    session = make_session(config=lab)
    try:
        assert isinstance(session.backend, GripperTwin)
        assert session.backend.config.rig == lab.rig
        assert session.backend.config.finger == lab.finger
        assert session.controller.rig == lab.rig
        assert session.controller.temperature.heat == lab.heat
        assert session.controller.config.stroke_mm == lab.motor.stroke_mm
    finally:
        session.close()
    with pytest.raises(InputError, match="--rig chooses the twin's gripper; a serial backend"):
        open_session("serial:rig.toml", clock=WallClock(), config=lab)
