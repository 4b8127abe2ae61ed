"""Grasp phases and the events a grasp reports (paper Fig. "grasp": Open, Close, Hold, Lift…)."""

from __future__ import annotations

import enum
from collections.abc import Collection
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Event", "EventKind", "GraspPhase", "PhaseLog"]


class GraspPhase(enum.StrEnum):
    """Where a grasp is."""

    OPEN = "open"
    """Fingers open; the tracker zeroes, the fingers reach their temperature."""
    CLOSE = "close"
    """Closing: fast until contact, then under force control up to the target."""
    HOLD = "hold"
    """Holding the target force (or the aperture, for the fixed baseline)."""
    LIFT = "lift"
    """The arm lifts the object while the force is held."""
    SUSTAIN = "sustain"
    """Object in the air, force held."""
    RELEASE = "release"
    """Opening until the fingers are free."""
    DONE = "done"
    """Finished: motor stopped."""
    STOPPED = "stopped"
    """Stopped by the operator or a fault: motor stopped, heaters off."""


#: Phase codes for compact time series (index in this tuple).
PHASES: tuple[GraspPhase, ...] = tuple(GraspPhase)


class EventKind(enum.StrEnum):
    """Things worth a line in the grasp's log."""

    CONTACT = "contact"
    HOLD_ONSET = "hold_onset"
    SLIP = "slip"
    MARKER_LOST = "marker_lost"
    MARKER_BACK = "marker_back"
    ESTIMATE_LOST = "estimate_lost"
    ESTIMATE_BACK = "estimate_back"
    FORCE_LIMIT = "force_limit"
    OVER_TEMPERATURE = "over_temperature"
    IR_STALE = "ir_stale"
    STROKE_END = "stroke_end"
    HEATER_FAULT = "heater_fault"
    STOP = "stop"


@dataclass(frozen=True)
class Event:
    """One event: when, what, and a line of detail."""

    t_s: float
    kind: EventKind
    detail: str = ""

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form."""
        return {"t_s": self.t_s, "kind": self.kind.value, "detail": self.detail}


@dataclass
class PhaseLog:
    """Phase transitions and events of one grasp, in time order."""

    transitions: list[tuple[float, GraspPhase]] = field(default_factory=list)
    events: list[Event] = field(default_factory=list)

    def enter(self, t_s: float, phase: GraspPhase) -> None:
        """Record entering ``phase`` at ``t_s``."""
        self.transitions.append((t_s, phase))

    def event(self, t_s: float, kind: EventKind, detail: str = "") -> None:
        """Record an event."""
        self.events.append(Event(t_s, kind, detail))

    def first(self, kind: EventKind) -> Event | None:
        """The first event of a kind, if any."""
        return next((e for e in self.events if e.kind is kind), None)

    def entered(self, phase: GraspPhase) -> float | None:
        """When ``phase`` was first entered, if it was."""
        return next((t for t, p in self.transitions if p is phase), None)

    def summary(self, skip: Collection[EventKind] = ()) -> list[str]:
        """One line per run of events of one kind in a row, with the count of repeats.

        A fault that repeats every period (a model's absurd force, read 30
        times a second) is said once: ``"12.0 s force_limit estimate 1e+06 N
        (and 241 more to 20.0 s)"``.  Kinds in ``skip`` are left out.
        """
        lines: list[str] = []
        run: list[Event] = []

        def close() -> None:
            if run:
                first, last = run[0], run[-1]
                more = (f" (and {len(run) - 1} more to {last.t_s:.1f} s)" if len(run) > 1
                        else "")
                lines.append(f"{first.t_s:.1f} s {first.kind.value} {first.detail}".strip()
                             + more)

        for event in self.events:
            if event.kind in skip:
                continue
            if run and event.kind is not run[0].kind:
                close()
                run = []
            run.append(event)
        close()
        return lines

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form."""
        return {"transitions": [{"t_s": t, "phase": p.value} for t, p in self.transitions],
                "events": [e.to_dict() for e in self.events]}
