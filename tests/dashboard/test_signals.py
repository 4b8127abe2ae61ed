"""``relaxgrip dashboard`` stopped by kill or a closed terminal: shut down, no tracebacks."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request

import pytest


def _serving(tmp_path, ignore_hangup: bool = False) -> subprocess.Popen[str]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])

    def ignoring() -> None:
        signal.signal(signal.SIGHUP, signal.SIG_IGN)  # as nohup starts it

    proc = subprocess.Popen(
        [sys.executable, "-m", "relaxgrip", "dashboard", "--host", "127.0.0.1",
         "--port", str(port), "--record-dir", str(tmp_path)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        preexec_fn=ignoring if ignore_hangup else None)
    deadline = time.monotonic() + 60
    while True:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=1) as r:
                if r.status == 200:
                    return proc
        except OSError:
            pass
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            raise AssertionError(f"the dashboard did not start: {proc.communicate()[1]}")
        time.sleep(0.2)


@pytest.mark.parametrize("stop", [signal.SIGTERM, signal.SIGHUP], ids=lambda s: s.name)
def test_kill_and_a_closed_terminal_shut_the_dashboard_down_quietly(
        tmp_path, stop: signal.Signals) -> None:
    # A hang-up raised KeyboardInterrupt inside uvicorn's event loop: its tasks'
    # tracebacks went to the terminal.  Now uvicorn shuts down as on SIGTERM.
    proc = _serving(tmp_path)
    proc.send_signal(stop)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert "CancelledError" not in err


def test_a_dashboard_started_under_nohup_serves_through_a_hangup(tmp_path) -> None:
    proc = _serving(tmp_path, ignore_hangup=True)
    try:
        proc.send_signal(signal.SIGHUP)
        time.sleep(1.0)
        assert proc.poll() is None, "a hangup stopped a dashboard that ignores it"
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=60)
    assert proc.returncode == 130
