"""Injected time: the same loop runs in virtual time or in wall-clock time.

Nothing below the loop runner calls :func:`time.monotonic`; it asks the
clock it was given.  :class:`VirtualClock` jumps to the requested time at
once (runs as fast as the CPU allows); :class:`WallClock` sleeps.
"""

from __future__ import annotations

import time
from typing import Protocol, runtime_checkable

__all__ = ["TIME_SLACK_S", "Clock", "VirtualClock", "WallClock"]

#: Times closer than this count as the same instant (s): clock arithmetic slack, for a
#: clock stepped by sums of a period (``VirtualClock.advance(1 / 30)``) too, whose
#: round-off passes a nanosecond after half an hour.
TIME_SLACK_S = 1e-6


@runtime_checkable
class Clock(Protocol):
    """A source of time in seconds since the clock's start."""

    def now(self) -> float:
        """Current time (s)."""
        ...

    def sleep_until(self, t_s: float) -> None:
        """Return once ``now() >= t_s``."""
        ...


class VirtualClock:
    """Simulated time that advances only when asked to.

    Parameters
    ----------
    start_s : float
        Initial time (s).
    """

    def __init__(self, start_s: float = 0.0) -> None:
        self._t = float(start_s)

    def now(self) -> float:
        """Current virtual time (s)."""
        return self._t

    def sleep_until(self, t_s: float) -> None:
        """Jump forward to ``t_s`` (never backwards)."""
        self._t = max(self._t, float(t_s))

    def advance(self, dt_s: float) -> None:
        """Move forward by ``dt_s`` seconds (``>= 0``)."""
        if dt_s < 0:
            raise ValueError(f"cannot advance a clock by a negative step {dt_s}")
        self._t += float(dt_s)


class WallClock:
    """Real time from :func:`time.monotonic`, zeroed at construction."""

    def __init__(self) -> None:
        self._t0 = time.monotonic()

    def now(self) -> float:
        """Seconds since the clock was made."""
        return time.monotonic() - self._t0

    def sleep_until(self, t_s: float) -> None:
        """Sleep until ``t_s`` seconds after the clock was made."""
        delay = t_s - self.now()
        if delay > 0:
            time.sleep(delay)
