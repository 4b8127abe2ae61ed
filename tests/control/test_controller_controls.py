"""Operator controls of a running grasp: hold now, lift from the hold, a new target."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from relaxgrip.clock import VirtualClock
from relaxgrip.control import (
    ForceControlConfig,
    GraspController,
    GraspPhase,
    GraspPlan,
    make_estimator,
)
from relaxgrip.control.controller import _loading_stiffness
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


def _step_target(models: Any, **config: Any) -> tuple[list[tuple[float, float, float]], Any]:
    """Hold 5 N (seed 0), then 2 N from 6 s into the hold: (time since the change,
    estimate, motor command) for 3 s, and the controller."""
    clock = VirtualClock()
    cfg = TwinConfig()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    ctl = GraspController(cfg.rig, make_estimator("relax", models.icfn, models.rcfn),
                          ForceControlConfig(**config), heat=cfg.heat)
    ctl.start(GraspPlan(target_n=5.0, temp_c=40.0, hold_s=math.inf, release=False),
              clock.now())
    _run(clock, twin, ctl, lambda o: math.isfinite(ctl.estimate.hold_s)
         and ctl.estimate.hold_s > 6.0, max_s=80.0)
    ctl.set_target(2.0)
    start = clock.now()
    rows = []
    while clock.now() < start + 3.0:
        command = ctl.step(twin.observe())
        twin.act(command)
        rows.append((clock.now() - start, ctl.estimate.force_n, command.motor_velocity_mm_s))
        clock.sleep_until(clock.now() + 1 / 30)
    return rows, ctl


def test_a_new_target_moves_the_motor_by_the_loadings_stiffness(models) -> None:
    """5 -> 2 N in the hold: the feed-forward opens at up to 10 mm/s by 0.9 of the
    travel the loading's stiffness gives, the PID takes up the rest, and the force
    is there in 1.2 s without swinging past; the PID alone, capped at
    3 mm/s, is still above 2.5 N a second later."""
    rows, ctl = _step_target(models)
    assert 0.1 < ctl._stiffness_n_per_mm < 1.0  # the ball in series with two fingers
    assert min(v for _, _, v in rows) < -9.0
    assert all(abs(f - 2.0) < 0.15 for t, f, _ in rows if t > 1.2)
    assert min(f for _, f, _ in rows) > 1.85
    slow, _ = _step_target(models, target_move_mm_s=0.0)
    assert min(v for _, _, v in slow) >= -3.0
    assert all(f > 2.5 for t, f, _ in slow if t < 2.0)


def test_loading_stiffness_is_the_top_of_the_loadings_slope() -> None:
    loading = [(m, 0.3 * (m - 100.0)) for m in np.linspace(100.0, 117.0, 60)]
    loading = [(100.0 + 0.1 * i, 0.02 * i) for i in range(30)] + loading  # a soft start
    assert _loading_stiffness(loading, 5.1, 0.5) == pytest.approx(0.3)
    assert math.isnan(_loading_stiffness(loading[:2], 5.1, 0.0))  # too few frames
    assert math.isnan(_loading_stiffness([(100.0, 3.0), (101.0, 2.9), (102.0, 2.8)], 3.0,
                                         0.5))  # not rising: nothing to feed forward


@pytest.mark.parametrize("kwargs", [{"target_move_mm_s": -1.0}, {"target_move_mm_s": math.nan},
                                    {"target_move_share": 0.0}, {"target_move_share": 1.5},
                                    {"loading_share": 1.0}, {"loading_share": -0.1}])
def test_feed_forward_settings_that_cannot_work_are_refused(kwargs: dict[str, Any]) -> None:
    with pytest.raises(ValueError, match=r"(target move|loading share)"):
        ForceControlConfig(**kwargs)
