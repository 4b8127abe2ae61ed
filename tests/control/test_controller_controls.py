"""Operator controls of a running grasp: hold now, lift from the hold (used by the dashboard)."""

from __future__ import annotations

import math
from typing import Any

import pytest

from relaxgrip.clock import VirtualClock
from relaxgrip.control import GraspController, GraspPhase, GraspPlan, make_estimator
from relaxgrip.errors import InputError
from relaxgrip.learning.training import load_default_models
from relaxgrip.twin import GripperTwin, TwinConfig


@pytest.fixture(scope="module")
def models():
    return load_default_models()


def _rig(models: Any) -> Any:
    clock = VirtualClock()
    cfg = TwinConfig()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    ctl = GraspController(cfg.rig, make_estimator("relax", models.icfn, models.rcfn),
                          heat=cfg.heat)
    return clock, twin, ctl


def _run(clock: Any, twin: Any, ctl: Any, until: Any, max_s: float = 40.0) -> Any:
    """Step at 30 Hz until ``until(obs)`` is true; the last observation."""
    obs = twin.observe()
    for _ in range(int(max_s * 30)):
        obs = twin.observe()
        twin.act(ctl.step(obs))
        clock.sleep_until(clock.now() + 1 / 30)
        if until(obs):
            return obs
    raise AssertionError(f"condition not reached in {max_s} s (phase {ctl.phase.value})")


def test_hold_and_lift_refused_outside_their_phases(models) -> None:
    _, _, ctl = _rig(models)
    with pytest.raises(InputError, match="nothing to hold in phase done"):
        ctl.hold(0.0)
    with pytest.raises(InputError, match="lift needs a grasp in hold"):
        ctl.lift(0.0, 0.0, 20.0)
    ctl.start(GraspPlan(target_n=3.0), 0.0)
    with pytest.raises(InputError, match="nothing to hold in phase open"):
        ctl.hold(0.0)
    assert ctl.phase.value == "open"


def test_hold_now_then_lift_then_back_to_hold(models) -> None:
    clock, twin, ctl = _rig(models)
    ctl.start(GraspPlan(target_n=5.0, hold_s=math.inf, release=False), clock.now())
    _run(clock, twin, ctl, lambda o: ctl.phase is GraspPhase.CLOSE)
    with pytest.raises(InputError, match="before contact"):
        ctl.hold(clock.now())
    # Hold as soon as the estimate passes 1 N, well short of the 5 N target.
    _run(clock, twin, ctl, lambda o: ctl.estimate.valid and ctl.estimate.force_n > 1.0)
    assert ctl.phase.value == "close"
    ctl.hold(clock.now())
    assert ctl.phase.value == "hold"
    obs = _run(clock, twin, ctl, lambda o: math.isfinite(ctl.estimate.hold_s)
               and ctl.estimate.hold_s > 1.0)
    assert ctl.phase.value == "hold"
    with pytest.raises(InputError, match="lift must be > 0 mm"):
        ctl.lift(obs.t_s, obs.arm_height_mm, 0.0)
    ctl.lift(obs.t_s, obs.arm_height_mm, 15.0)
    assert ctl.phase.value == "lift"
    obs = _run(clock, twin, ctl, lambda o: ctl.phase is GraspPhase.SUSTAIN)
    assert obs.arm_height_mm >= 15.0
    obs = _run(clock, twin, ctl, lambda o: o.t_s > obs.t_s + 2.0)
    assert ctl.phase.value == "sustain"  # sustained until told
    ctl.hold(obs.t_s)
    assert ctl.phase.value == "hold"
    height = obs.arm_height_mm
    obs = _run(clock, twin, ctl, lambda o: o.t_s > obs.t_s + 1.0)
    assert ctl.phase.value == "hold"
    assert obs.arm_height_mm == pytest.approx(height, abs=1.0)
    assert obs.truth is not None
    assert obs.truth.object_lifted
