"""The phase log: a reason repeated every period is said once, with the count."""

from __future__ import annotations

from relaxgrip.control import EventKind
from relaxgrip.control.phases import PhaseLog


def test_a_run_of_one_kind_is_one_line_with_its_count() -> None:
    log = PhaseLog()
    log.event(13.1, EventKind.CONTACT, "marker deflection 0.128 mm")
    for k in range(7260):  # a model's absurd force, every period for four minutes
        log.event(19.0 + k / 30, EventKind.FORCE_LIMIT, f"estimate {1e6 + k:.4g} N")
    log.event(261.0, EventKind.STOP, "operator")
    lines = log.summary()
    assert lines == ["13.1 s contact marker deflection 0.128 mm",
                     "19.0 s force_limit estimate 1e+06 N (and 7259 more to 261.0 s)",
                     "261.0 s stop operator"]
    assert sum(len(line) for line in lines) < 200
    assert log.summary(skip=(EventKind.CONTACT,))[0].startswith("19.0 s force_limit")
    assert PhaseLog().summary() == []
