"""The zero pose: measured on a gripper at rest, refused by name when it is not."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from relaxgrip.backend import BackendInfo, Command, Observation
from relaxgrip.clock import VirtualClock
from relaxgrip.perception.zero_pose import (
    GripperNotAtRestError,
    ZeroPoseLimits,
    measure_zero_pose,
)
from relaxgrip.twin import GripperTwin, TwinConfig
from relaxgrip.twin.sensors import RgbSensorConfig


def _twin(config: TwinConfig | None = None, seed: int = 0) -> tuple[GripperTwin, VirtualClock]:
    clock = VirtualClock()
    twin = GripperTwin(config if config is not None else TwinConfig(), seed, clock)
    twin.reset()
    return twin, clock


def _run(twin: GripperTwin, clock: VirtualClock, seconds: float, command: Command) -> None:
    end = clock.now() + seconds
    while clock.now() < end:
        twin.act(command)
        clock.advance(0.02)
        twin.observe()


class _Pressing:
    """A gripper whose motor keeps closing whatever it is told, without a force reference."""

    def __init__(self, twin: GripperTwin, velocity_mm_s: float) -> None:
        self.twin = twin
        self.velocity_mm_s = velocity_mm_s

    @property
    def info(self) -> BackendInfo:
        return self.twin.info

    def reset(self, seed: int | None = None) -> Observation:
        return replace(self.twin.reset(seed), force_ref=None)

    def observe(self) -> Observation:
        return replace(self.twin.observe(), force_ref=None)

    def act(self, command: Command) -> None:
        self.twin.act(replace(command, motor_velocity_mm_s=self.velocity_mm_s))

    def close(self) -> None:
        self.twin.close()


def test_the_zero_pose_of_a_gripper_at_rest_is_where_the_marker_is() -> None:
    twin, clock = _twin()
    zero = measure_zero_pose(twin, clock, twin.config.rig)
    truth = twin.config.rig.marker2cam()[:3, 3]  # the twin draws the unbent marker there
    assert np.linalg.norm(np.asarray(zero.position_m) - truth) < 1e-4
    assert zero.offset_m < 1e-4
    assert zero.frames == zero.frames_seen == 30
    assert zero.spread_m < 5e-5
    assert zero.max_force_n is not None
    assert zero.max_force_n < 0.1
    assert 20.0 < zero.finger_temp_c < 30.0
    assert twin.observe().heater_duty == (0.0, 0.0)
    d = zero.to_dict()
    assert d["position_mm"][2] == pytest.approx(zero.position_m[2] * 1e3)
    again_twin, again_clock = _twin()
    assert measure_zero_pose(again_twin, again_clock, again_twin.config.rig) == zero


def test_heaters_on_are_refused() -> None:
    twin, clock = _twin()
    twin.act(Command(heater_duty=(0.5, 0.5)))
    with pytest.raises(GripperNotAtRestError, match=r"heaters on \(duty 0.50, 0.50\)"):
        measure_zero_pose(twin, clock, twin.config.rig)


def test_warm_fingers_are_refused() -> None:
    twin, clock = _twin()
    _run(twin, clock, 40.0, Command(heater_duty=(1.0, 1.0)))
    twin.act(Command())
    with pytest.raises(GripperNotAtRestError, match=r"fingers at [\d.]+ °C, warmer than 35 °C"):
        measure_zero_pose(twin, clock, twin.config.rig)


def test_a_loaded_finger_is_refused() -> None:
    twin, clock = _twin()
    _run(twin, clock, 5.0, Command(motor_velocity_mm_s=20.0))  # closed on the force ball
    with pytest.raises(GripperNotAtRestError, match=r"the force reference reads [\d.]+ N, over "
                       r"0.1 N"):
        measure_zero_pose(twin, clock, twin.config.rig)


def test_a_hidden_marker_is_refused() -> None:
    twin, clock = _twin(TwinConfig(rgb=RgbSensorConfig(occlusion=1.0)))
    with pytest.raises(GripperNotAtRestError, match="marker DICT_4X4_50 id 0 found on 0 of 30"):
        measure_zero_pose(twin, clock, twin.config.rig)


def test_a_moving_marker_is_refused() -> None:
    twin, clock = _twin()
    _run(twin, clock, 4.6, Command(motor_velocity_mm_s=20.0))  # at the ball
    pressing = _Pressing(twin, 2.0)
    with pytest.raises(GripperNotAtRestError, match=r"marker pose unstable over \d+ frames"):
        measure_zero_pose(pressing, clock, twin.config.rig, require_force_ref=False)


def test_no_force_reference_needs_saying_so() -> None:
    twin, clock = _twin()
    still = _Pressing(twin, 0.0)
    with pytest.raises(GripperNotAtRestError, match="pass --no-force-ref"):
        measure_zero_pose(still, clock, twin.config.rig)
    zero = measure_zero_pose(still, clock, twin.config.rig, require_force_ref=False)
    assert zero.max_force_n is None


def test_limits_are_checked() -> None:
    with pytest.raises(ValueError, match="--frames must be 5 to 10000"):
        ZeroPoseLimits(frames=2)
    with pytest.raises(ValueError, match="max_force_n must be > 0"):
        ZeroPoseLimits(max_force_n=0.0)
