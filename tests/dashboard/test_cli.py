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
from tests.dashboard.conftest import TOKEN, dashboard_process, free_port


def _free_port() -> int:
    return free_port()


@contextlib.contextmanager
def _dashboard(record_dir: Path) -> Iterator[tuple[subprocess.Popen[str], int]]:
    """``relaxgrip dashboard`` serving on a free loopback port, and that port."""
    with dashboard_process(record_dir, stdout=subprocess.PIPE) as served:
        yield served


def _viewer(proc: subprocess.Popen[str], port: int) -> Any:
    """A WebSocket client of the dashboard, once it listens (within a minute)."""
    sync_client = pytest.importorskip("websockets.sync.client")
    deadline = time.monotonic() + 60.0
    while True:
        try:
            return sync_client.connect(f"ws://127.0.0.1:{port}/ws?token={TOKEN}",
                                       max_size=None)
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
            raw.sendall(f"GET /ws?token={TOKEN} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
                        "Upgrade: websocket\r\n"
                        f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                        "Sec-WebSocket-Version: 13\r\n\r\n".encode())
            assert stream.readline().startswith(b"HTTP/1.1 101")
            while stream.readline() not in (b"\r\n", b""):
                pass
            raw.sendall(bytes([0x81, 0x82, 0, 0, 0, 0]) + b"\xff\xfe")  # text, zero mask
            close = next(data for opcode, data in _server_frames(stream) if opcode == 0x8)
            assert int.from_bytes(close[:2], "big") == 1007
            assert _reply(ws, {"id": 1, **target}) == {"type": "reply", "id": 1, "ok": True,
                                                        "error": None, "applied": 1}
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
        assert session.controller.limits.stroke_mm == lab.motor.stroke_mm
    finally:
        session.close()
    with pytest.raises(InputError, match="--rig chooses the twin's gripper; a serial backend"):
        open_session("serial:rig.toml", clock=WallClock(), config=lab)


@pytest.mark.parametrize(("args", "message"), [
    (["--host", "0.0.0.0", "--allow-remote"], "with --allow-remote needs TLS: give --certfile "
                                              "and --keyfile, or --insecure-remote"),
    (["--insecure-remote"], "--insecure-remote is for --allow-remote"),
    (["--certfile", "cert.pem"], "TLS needs both --certfile and --keyfile"),
    (["--token", "short"], "--token must be 8-256 characters of letters, digits and ._~- "
                           "(got 5 characters, too short)"),
    (["--token", "has spaces in it"], "--token must be 8-256 characters"),
])
def test_remote_access_needs_tls_and_a_token_is_checked(args: list[str], message: str) -> None:
    result = CliRunner().invoke(app, ["dashboard", "--port", str(free_port()), *args])
    assert isinstance(result.exception, InputError), result.output
    assert message in str(result.exception)
    assert "has spaces in it" not in str(result.exception)  # a token is not repeated


def _self_signed(tmp_path: Path) -> tuple[Path, Path]:
    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    try:
        subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                        "ec_paramgen_curve:prime256v1", "-nodes", "-days", "1", "-subj",
                        "/CN=localhost", "-keyout", str(key), "-out", str(cert)],
                       check=True, capture_output=True, timeout=60)
    except (OSError, subprocess.CalledProcessError) as exc:
        pytest.skip(f"no openssl to make a test certificate: {exc}")
    return cert, key


def test_a_certificate_that_does_not_load_is_named(tmp_path: Path) -> None:
    cert, key = _self_signed(tmp_path)
    junk = tmp_path / "junk.pem"
    junk.write_text("not a certificate\n")
    for c, k, expected in ((junk, key, "do not load as a TLS certificate and its key"),
                           (cert, junk, "do not load as a TLS certificate and its key"),
                           (tmp_path / "none.pem", key, "no such --certfile file")):
        result = CliRunner().invoke(app, ["dashboard", "--port", str(free_port()),
                                          "--certfile", str(c), "--keyfile", str(k)])
        assert isinstance(result.exception, InputError), result.output
        assert expected in str(result.exception)


def test_the_dashboard_serves_https_and_wss_with_a_certificate(tmp_path: Path) -> None:
    """TLS on loopback (tests bind no other address); the printed URL is https, with the
    token; without the token the page is refused."""
    import ssl
    import urllib.error
    import urllib.request

    cert, key = _self_signed(tmp_path)
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "relaxgrip", "dashboard", "--port", str(port),
                             "--record-dir", str(tmp_path), "--certfile", str(cert),
                             "--keyfile", str(key)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    context = ssl.create_default_context(cafile=str(cert))
    context.check_hostname = False
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()  # printed before the server starts
        assert line.startswith(f"dashboard (twin) on https://127.0.0.1:{port}/?token=")
        url = line.split(" on ", 1)[1].strip()
        token = url.split("token=", 1)[1]
        assert len(token) >= 40  # a new random token: 32 bytes
        deadline = time.monotonic() + 120
        while True:
            try:
                with urllib.request.urlopen(url, context=context, timeout=2) as r:
                    assert r.status == 200
                    break
            except urllib.error.HTTPError:
                raise
            except OSError:
                assert proc.poll() is None, proc.communicate()[1]
                assert time.monotonic() < deadline
                time.sleep(0.2)
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(f"https://127.0.0.1:{port}/", context=context, timeout=5)
        assert refused.value.code == 403
        sync_client = pytest.importorskip("websockets.sync.client")
        with sync_client.connect(f"wss://127.0.0.1:{port}/ws?token={token}", ssl=context,
                                 max_size=None) as ws:
            assert json.loads(ws.recv(timeout=10))["type"] == "state"
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
