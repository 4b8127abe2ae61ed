"""``relaxgrip dashboard``: a public address needs --allow-remote; a missing extra is named."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from relaxgrip.cli import app
from relaxgrip.cli.dashboard import check_host, is_loopback
from relaxgrip.dashboard import require_web_stack
from relaxgrip.errors import InputError


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
    import socket

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
    import socket

    probe = socket.socket()
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
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
    import socket

    probe = socket.socket()
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
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
    import json
    import signal
    import socket
    import subprocess
    import time

    sync_client = pytest.importorskip("websockets.sync.client")
    probe = socket.socket()
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    proc = subprocess.Popen([sys.executable, "-m", "relaxgrip", "dashboard", "--port", str(port),
                             "--record-dir", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60.0
        while True:
            try:
                ws = sync_client.connect(f"ws://127.0.0.1:{port}/ws", max_size=None)
                break
            except OSError:
                assert time.monotonic() < deadline
                assert proc.poll() is None
                time.sleep(0.1)
        with ws:
            ws.send(json.dumps({"id": 1, "op": "record", "value": True}))
            while (reply := json.loads(ws.recv()))["type"] != "reply":
                pass
            assert reply["ok"], reply
            time.sleep(0.5)
            proc.send_signal(signal.SIGINT)
            time.sleep(0.05)
            proc.send_signal(signal.SIGINT)  # while uvicorn closes the connections
            _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert "Traceback" not in err, err
    from relaxgrip.recording import read_session

    assert read_session(Path(reply["path"]))["backend"]["name"] == "twin"  # closed, readable
