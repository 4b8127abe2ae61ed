"""Shared fixtures: a live twin session behind the dashboard app (wall-clock time)."""

from __future__ import annotations

import pytest

pytest.importorskip("fastapi", reason="the dashboard extra (fastapi) is not installed")

from relaxgrip.clock import WallClock
from relaxgrip.dashboard.session import open_session


@pytest.fixture
def make_session(tmp_path):
    """Factory of twin sessions (recording into a temporary directory)."""

    def make(**kwargs):
        return open_session("twin", clock=WallClock(), record_dir=tmp_path, **kwargs)

    return make
