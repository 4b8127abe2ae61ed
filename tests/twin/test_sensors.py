"""The twin's sensor streams: schedules, determinism, the force ball, the approach axis."""

from __future__ import annotations

import math

import numpy as np
import pytest

from relaxgrip.backend import Command, Observation, Truth
from relaxgrip.clock import VirtualClock
from relaxgrip.errors import InputError
from relaxgrip.twin import GripperTwin, TwinConfig
from relaxgrip.twin.sensors import (
    ForceSensorConfig,
    IrSensorConfig,
    RgbSensorConfig,
    SceneObject,
)


def truth(obs: Observation) -> Truth:
    assert obs.truth is not None
    return obs.truth


def test_frames_arrive_at_30_and_1_hz_with_capture_times() -> None:
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(), seed=0, clock=clock)
    seen_rgb, seen_ir = set(), set()
    for _ in range(75):
        clock.advance(1 / 30)
        obs = twin.observe()
        assert obs.rgb is not None
        assert obs.ir is not None
        assert obs.rgb.t_s <= obs.t_s + 1e-9
        seen_rgb.add((obs.rgb.seq, round(obs.rgb.t_s, 9)))
        seen_ir.add((obs.ir.seq, round(obs.ir.t_s, 9)))
    assert sorted(seen_rgb) == [(k, round(k / 30, 9)) for k in range(1, 76)]
    assert sorted(seen_ir) == [(0, 0.0), (1, 1.0), (2, 2.0)]
    rgb, ir = obs.rgb, obs.ir
    assert rgb is not None
    assert ir is not None
    assert rgb.image.shape == (480, 640, 3)
    assert rgb.image.dtype == np.uint8
    assert ir.image.shape == (192, 256)
    assert ir.image.dtype == np.float32


def test_slow_observer_gets_the_latest_frame_only() -> None:
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(), seed=0, clock=clock)
    clock.advance(0.5)
    obs = twin.observe()
    assert obs.rgb is not None
    assert obs.rgb.seq == 15


def test_frames_are_deterministic_whatever_the_observation_rate() -> None:
    def frame_at(step_s: float) -> np.ndarray:
        clock = VirtualClock()
        twin = GripperTwin(TwinConfig(initial_temp_c=40.0), seed=3, clock=clock)
        twin.act(Command(10.0))
        for _ in range(round(1.0 / step_s)):
            clock.advance(step_s)
            obs = twin.observe()
        assert obs.rgb is not None
        assert obs.rgb.seq == 30
        return obs.rgb.image

    assert np.array_equal(frame_at(1 / 30), frame_at(0.25))


def test_no_cameras_no_frames() -> None:
    twin = GripperTwin(TwinConfig().without_cameras())
    obs = twin.observe()
    assert obs.rgb is None
    assert obs.ir is None


def test_force_ball_reports_100_hz_reference_with_small_noise() -> None:
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(initial_temp_c=40.0).without_cameras(), seed=0, clock=clock)
    twin.act(Command(20.0))
    clock.advance(4.8)
    twin.act(Command(0.0))
    twin.observe()
    t: list[float] = []
    f: list[float] = []
    true: list[float] = []
    for _ in range(30):
        clock.advance(1 / 30)
        obs = twin.observe()
        assert obs.force_ref is not None
        t.extend(obs.force_ref.t_s)
        f.extend(obs.force_ref.force_n)
        true.append(truth(obs).contact_force_n)
    assert np.allclose(np.diff(t), 0.01)
    assert len(t) == 100
    assert truth(obs).contact_force_n > 1.0
    residual = np.asarray(f) - np.interp(t, np.arange(1, 31) / 30 + 4.8, true)
    assert 0.005 < np.std(residual) < 0.02


def test_objects_without_a_sensor_give_no_reference() -> None:
    clock = VirtualClock()
    cfg = TwinConfig(object_name="orange").without_cameras()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    twin.act(Command(20.0))
    clock.advance(4.0)
    assert twin.observe().force_ref is None


def test_approach_brings_the_object_between_the_fingers_and_stops() -> None:
    clock = VirtualClock()
    cfg = TwinConfig(object_name="orange", object_distance_m=0.1).without_cameras()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    twin.act(Command(motor_velocity_mm_s=20.0))  # closing on nothing: the orange is ahead
    clock.advance(3.0)
    assert truth(twin.observe()).contact_force_n == 0.0
    twin.act(Command(motor_velocity_mm_s=0.0, approach_velocity_mm_s=50.0))
    clock.advance(3.0)
    obs = twin.observe()
    assert truth(obs).object_ahead_m == pytest.approx(0.0)
    assert obs.arm_forward_mm == pytest.approx(100.0)
    twin.act(Command(motor_velocity_mm_s=20.0))
    clock.advance(1.0)
    assert truth(twin.observe()).contact_force_n > 0.5


def test_a_too_narrow_aperture_does_not_swallow_the_object() -> None:
    clock = VirtualClock()
    cfg = TwinConfig(object_name="orange", object_distance_m=0.05).without_cameras()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    twin.act(Command(motor_velocity_mm_s=20.0))
    clock.advance(4.0)  # aperture 70 mm < 75 mm orange
    twin.act(Command(0.0, approach_velocity_mm_s=50.0))
    clock.advance(2.0)
    twin.act(Command(20.0))
    clock.advance(1.0)
    assert truth(twin.observe()).contact_force_n == 0.0


def test_scene_objects_show_in_the_infrared() -> None:
    scene = (SceneObject("paper_cup_hot", (0.25, 0.06, -0.03)),)
    cfg = TwinConfig(object_name=None, scene=scene, rgb=None)
    cold = GripperTwin(TwinConfig(object_name=None, rgb=None), seed=0).observe().ir
    hot = GripperTwin(cfg, seed=0).observe().ir
    assert hot is not None
    assert cold is not None
    assert hot.image.max() > cold.image.max() + 20.0


def test_sensor_config_validation() -> None:
    with pytest.raises(InputError, match="occlusion"):
        RgbSensorConfig(occlusion=1.5)
    with pytest.raises(InputError, match="unknown object"):
        SceneObject("anvil", (0.0, 0.0, 0.0))
    with pytest.raises(InputError, match="object distance"):
        TwinConfig(object_distance_m=-0.1)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: RgbSensorConfig(noise_dn=math.nan), "noise"),
        (lambda: RgbSensorConfig(blur_sigma_px=math.inf), "blur"),
        (lambda: RgbSensorConfig(lighting_flicker=math.nan), "flicker"),  # a black frame
        (lambda: RgbSensorConfig(supersample=2.5), "supersample"),  # type: ignore[arg-type]
        (lambda: RgbSensorConfig(drawing="antialiased"), "drawing"),
        (lambda: IrSensorConfig(netd_k=math.nan), "NETD"),  # no noise at all
        (lambda: IrSensorConfig(max_offset_k=math.inf), "offset"),
        (lambda: IrSensorConfig(psf_sigma_px=math.nan), "blur"),
        (lambda: ForceSensorConfig(rate_hz=0.0), "rate_hz"),  # ZeroDivisionError at reset
        (lambda: ForceSensorConfig(noise_n=math.nan), "noise_n"),
        (lambda: ForceSensorConfig(noise_n=-0.01), "noise_n"),
    ],
)
def test_sensor_configs_refuse_nan_and_impossible_values(make, match) -> None:
    with pytest.raises(InputError, match=match):
        make()
