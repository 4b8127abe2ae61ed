"""One set of limits: every entry point checks force, temperature, duty, speed and travel
against the rig's ``[limits]`` (our gripper's for the twin, :data:`OUR_LIMITS`)."""

from __future__ import annotations

import math
import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from relaxgrip.backend import Command
from relaxgrip.clock import VirtualClock, WallClock
from relaxgrip.errors import InputError
from relaxgrip.limits import OUR_LIMITS, LimitsSpec
from tests.clitools import run_main

DOCS = Path(__file__).resolve().parents[1] / "docs"

#: A lab's gripper, more careful than ours in every limit.
LAB = LimitsSpec(max_target_n=6.0, max_force_n=8.0, min_setpoint_c=30.0, max_setpoint_c=50.0,
                 max_temp_c=55.0, heater_duty_limit=0.5, max_motor_speed_mm_s=8.0,
                 stroke_mm=100.0)


def _rig(limits: dict[str, Any] | None) -> dict[str, Any]:
    data = tomllib.loads((DOCS / "rigs" / "relaxgrip.toml").read_text(encoding="utf-8"))
    if limits is None:
        del data["limits"]
    else:
        data["limits"] = limits
    return data


def test_the_rig_file_gives_the_limits_and_ours_fill_what_it_leaves_out() -> None:
    from relaxgrip.hardware.rig_file import load_rig, parse_rig

    assert load_rig(DOCS / "rigs" / "relaxgrip.toml").limits == OUR_LIMITS
    assert load_rig(DOCS / "rig-emulator.toml").limits == OUR_LIMITS
    assert parse_rig(_rig(None), "x.toml").limits == OUR_LIMITS
    keys = {k: getattr(LAB, k) for k in LAB.__dataclass_fields__}
    assert parse_rig(_rig(keys), "lab.toml").limits == LAB
    assert parse_rig(_rig({"max_temp_c": 68.0}), "x.toml").limits == replace(
        OUR_LIMITS, max_temp_c=68.0)
    with pytest.raises(InputError, match=r"^x.toml: \[limits\] need min_setpoint_c < "
                                         r"max_setpoint_c < max_temp_c, got 28, 65 and 60 °C$"):
        parse_rig(_rig({"max_temp_c": 60.0, "max_setpoint_c": 65.0}), "x.toml")
    with pytest.raises(InputError, match=r"\[limits\] need 0 < max_target_n < max_force_n"):
        parse_rig(_rig({"max_target_n": 12.0}), "x.toml")
    with pytest.raises(InputError, match=r"\[limits\] has unknown key 'max_speed'"):
        parse_rig(_rig({"max_speed": 3.0}), "x.toml")


def test_our_limits_are_the_twin_s_and_the_defaults_everywhere() -> None:
    """Written once: the controller's, the temperature loop's, the experiments' ranges."""
    from relaxgrip.control import MAX_TARGET_N, GraspController, make_estimator
    from relaxgrip.control.temperature import ThermalLimits
    from relaxgrip.experiments.controlled_hold import HOLD_TEMP_RANGE_C
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.twin import TwinConfig

    models = load_default_models()
    ctl = GraspController(TwinConfig().rig, make_estimator("icfn", models.icfn, models.rcfn))
    assert ctl.limits is OUR_LIMITS
    assert ThermalLimits.for_rig(OUR_LIMITS) == ThermalLimits()
    assert ctl.temperature.limits == ThermalLimits()
    assert OUR_LIMITS.max_target_n == MAX_TARGET_N
    assert (OUR_LIMITS.min_setpoint_c, OUR_LIMITS.max_setpoint_c) == HOLD_TEMP_RANGE_C
    assert TwinConfig().motor.max_velocity_mm_s == OUR_LIMITS.max_motor_speed_mm_s
    assert TwinConfig().motor.stroke_mm == OUR_LIMITS.stroke_mm


def _controller(limits: LimitsSpec, **config: Any) -> Any:
    from relaxgrip.control import ForceControlConfig, GraspController, make_estimator
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.twin import TwinConfig

    models = load_default_models()
    cfg = TwinConfig()
    return GraspController(cfg.rig, make_estimator("icfn", models.icfn, models.rcfn),
                           ForceControlConfig(**config), heat=cfg.heat, limits=limits)


def test_the_python_api_checks_the_rig_s_limits() -> None:
    """The controller, its temperature loop and its configuration."""
    from relaxgrip.control import GraspPlan, StiffnessMode

    with pytest.raises(InputError, match=r"the controller's approach speed 10\.0 mm/s is beyond "
                                         r"the rig's limit of 8 mm/s"):
        _controller(LAB)
    ctl = _controller(LAB, approach_mm_s=5.0, release_mm_s=5.0, target_move_mm_s=5.0)
    with pytest.raises(InputError, match=r"target force 7.0 N is outside \(0, 6\] N"):
        ctl.set_target(7.0)
    with pytest.raises(InputError, match=r"target force 7.0 N is outside \(0, 6\] N"):
        ctl.start(GraspPlan(target_n=7.0, temp_c=40.0))
    with pytest.raises(InputError, match=r"temperature setpoint 52\.0 °C is outside the safe "
                                         r"range 30-50 °C"):
        ctl.start(GraspPlan(target_n=3.0, temp_c=52.0))
    with pytest.raises(InputError, match="outside the safe range 30-50"):
        ctl.temperature.set_temperature(52.0)
    with pytest.raises(InputError, match="outside the safe range 30-50"):
        ctl.temperature.set_mode(StiffnessMode.COMPLIANT)  # 58 °C
    assert ctl.temperature.limits.max_temp_c == 55.0
    assert not LAB.force_in_range(8.5)
    assert not LAB.force_in_range(math.nan)
    assert LAB.clamp(20.0, (1.0, math.nan)) == (8.0, (0.5, 0.0))
    assert LAB.clamp(-20.0, (-1.0, 0.2)) == (-8.0, (0.0, 0.2))
    with pytest.raises(InputError, match=r"motor position 120\.0 mm is outside the stroke"):
        LAB.check_travel_mm(120.0)
    with pytest.raises(InputError, match=r"heater duty 0\.6 is outside 0-0\.5"):
        LAB.check_duty(0.6)


def test_the_loop_commands_within_the_rig_s_speed_duty_and_stroke() -> None:
    """On the twin, heating from ambient (the PID asks for full duty) and closing: every
    command is within 8 mm/s and duty 0.5, and the fingers never close past the stroke."""
    from relaxgrip.control import EventKind, GraspPlan, run_loop
    from relaxgrip.twin import GripperTwin, TwinConfig

    ctl = _controller(replace(LAB, stroke_mm=60.0), approach_mm_s=5.0, release_mm_s=5.0,
                      target_move_mm_s=5.0)
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(initial_temp_c=None, object_name=None), seed=0, clock=clock)
    commands: list[Command] = []
    act = twin.act

    def spy(command: Command) -> None:
        commands.append(command)
        act(command)

    twin.act = spy  # type: ignore[method-assign]
    res = run_loop(twin, ctl, clock, GraspPlan(target_n=3.0, temp_c=45.0, wait_for_temp=False),
                   25.0)
    assert max(abs(c.motor_velocity_mm_s) for c in commands) <= 5.0
    duties = [d for c in commands for d in c.heater_duty]
    assert max(duties) == 0.5  # asked for more, given the rig's limit
    # No object: the stroke's end stops the closing (the motor coasts its lag's worth on).
    assert 60.0 <= res["motor_mm"].max() <= 60.5
    assert res.log.first(EventKind.STROKE_END) is not None


def test_the_serial_gripper_and_the_mcu_configuration_keep_the_rig_s_limits() -> None:
    from relaxgrip.hardware.emulator import open_emulated_gripper
    from relaxgrip.hardware.gripper import GripperFaultError

    clock = VirtualClock()
    gripper, emu = open_emulated_gripper(seed=0, clock=clock, grace_s=0.5)
    try:
        gripper.limits = replace(LAB, max_motor_speed_mm_s=20.0)  # the MCU's own: 20 mm/s
        gripper.reset()
        gripper.act(Command(motor_velocity_mm_s=50.0, heater_duty=(1.0, 0.9)))
        assert emu.endpoint.core.outputs.velocity_um_s == 20_000
        assert emu.endpoint.core.outputs.heater_duty_permyriad == (5000, 5000)
    finally:
        gripper.close()
    gripper, emu = open_emulated_gripper(seed=0, clock=VirtualClock(), grace_s=0.5)
    try:
        gripper.limits = LAB  # 8 mm/s: the MCU's 20 mm/s clamp would let a faster motor by
        with pytest.raises(GripperFaultError, match="the MCU's velocity limit 20 mm/s is above "
                                                    "the rig's"):
            gripper.reset()
        assert not emu.endpoint.core.enabled
    finally:
        gripper.close()


def test_the_dashboard_s_controls_check_the_session_s_limits(tmp_path: Path) -> None:
    pytest.importorskip("fastapi")
    from relaxgrip.dashboard.app import _control
    from relaxgrip.dashboard.session import LiveSession
    from relaxgrip.twin import GripperTwin, TwinConfig

    ctl = _controller(LAB, approach_mm_s=5.0, release_mm_s=5.0, target_move_mm_s=5.0)
    session = LiveSession(GripperTwin(TwinConfig(), seed=0), ctl, WallClock(),
                          record_dir=tmp_path)
    with pytest.raises(InputError, match=r"target force 7.0 N is outside \(0, 6\] N"):
        _control(session, "target", 7.0)
    with pytest.raises(InputError, match="outside the safe range 30-50"):
        _control(session, "temperature", 52)
    with pytest.raises(InputError, match="outside the safe range 30-50"):
        _control(session, "mode", "compliant")
    assert _control(session, "target", 5.5)["applied"] == 1
    assert session.state()["target_n"] == 5.5


@pytest.mark.parametrize(("args", "message"), [
    (["hold", "--target-n", "10.5"], "target force 10.5 N is outside (0, 10] N"),
    (["hold", "--temp-c", "27"], "hold temperature 27.0 °C is outside the safe range 28-65 °C"),
    (["hold", "--temp-c", "66"], "outside the safe range 28-65 °C"),
    (["hold", "--temp-profile", "step:70:100"], "outside the safe range 28-65 °C"),
    (["hold", "--target-profile", "step:11:100"], "outside (0, 10] N"),
    (["budget", "--seeds", "0", "--temp-c", "20"], "outside the safe range 28-65 °C"),
    (["budget", "--seeds", "0", "--target-n", "10.5"], "outside (0, 10] N"),
])
def test_the_command_line_checks_our_limits(monkeypatch, capsys, args, message) -> None:
    code, _, err = run_main(args, monkeypatch, capsys)
    assert code == 2
    assert message in err
    assert err.count("\n") == 1
