"""``relaxgrip dashboard`` stopped by kill or a closed terminal: shut down, no tracebacks.

Each child starts with the stop signals set as a terminal sets them
(:func:`~tests.dashboard.conftest.dispositions`): the tests pass under
``nohup`` and from a shell's ``&`` too.
"""

from __future__ import annotations

import signal
import time

import pytest

from tests.dashboard.conftest import dashboard_process


@pytest.mark.parametrize("stop", [signal.SIGTERM, signal.SIGHUP], ids=lambda s: s.name)
def test_kill_and_a_closed_terminal_shut_the_dashboard_down_quietly(
        tmp_path, stop: signal.Signals) -> None:
    # A hang-up raised KeyboardInterrupt inside uvicorn's event loop: its tasks'
    # tracebacks went to the terminal.  Now uvicorn shuts down as on SIGTERM.
    with dashboard_process(tmp_path) as (proc, _):
        proc.send_signal(stop)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert "CancelledError" not in err


def test_a_dashboard_started_under_nohup_serves_through_a_hangup(tmp_path) -> None:
    with dashboard_process(tmp_path, ignore_hangup=True) as (proc, _):
        proc.send_signal(signal.SIGHUP)
        time.sleep(1.0)  # what the hangup would have stopped by now, it did not
        assert proc.poll() is None, "a hangup stopped a dashboard that ignores it"
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=60)
    assert proc.returncode == 130
