"""Shared fixtures: a live twin session behind the dashboard app, and the dashboard command."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

pytest.importorskip("fastapi", reason="the dashboard extra (fastapi) is not installed")

from relaxgrip.clock import WallClock
from relaxgrip.dashboard.session import open_session

#: The access token the tests' dashboards run with.
TOKEN = "test-token-0123"


@pytest.fixture
def make_session(tmp_path):
    """Factory of twin sessions (recording into a temporary directory)."""

    def make(**kwargs):
        return open_session("twin", clock=WallClock(), record_dir=tmp_path, **kwargs)

    return make


def free_port() -> int:
    """A loopback port no one listens on now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
    return port


def dispositions(ignore_hangup: bool = False) -> Callable[[], None]:
    """A ``preexec_fn`` that sets the stop signals as a terminal starts a command.

    A test that signals the child relies on them: a test run under ``nohup``
    hands its children SIGHUP ignored, one started with ``&`` SIGINT ignored.
    With ``ignore_hangup``, SIGHUP ignored, as ``nohup`` starts it.
    """

    def preexec() -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_DFL)
        signal.signal(signal.SIGHUP, signal.SIG_IGN if ignore_hangup else signal.SIG_DFL)

    return preexec


@contextlib.contextmanager
def dashboard_process(record_dir: Path, *args: str, ignore_hangup: bool = False,
                      stdout: int | None = subprocess.DEVNULL,
                      ) -> Iterator[tuple[subprocess.Popen[str], int]]:
    """``relaxgrip dashboard --token TOKEN`` on a free loopback port, once it serves the page;
    killed on the way out if it still runs."""
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "relaxgrip", "dashboard", "--host", "127.0.0.1",
         "--port", str(port), "--record-dir", str(record_dir), "--token", TOKEN, *args],
        stdout=stdout, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"}, preexec_fn=dispositions(ignore_hangup))
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/?token={TOKEN}",
                                            timeout=1) as r:
                    if r.status == 200:
                        break
            except urllib.error.HTTPError as exc:
                raise AssertionError(f"the dashboard answered {exc.code}") from None
            except OSError:
                pass
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                raise AssertionError(f"the dashboard did not start: {proc.communicate()[1]}")
            time.sleep(0.2)
        yield proc, port
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
