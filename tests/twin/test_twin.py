"""The digital twin: protocol, determinism, motor, heaters, contact, lift."""

import math
from dataclasses import replace

import numpy as np
import pytest

from relaxgrip.backend import Command, Gripper, Observation, Truth, check_backend
from relaxgrip.clock import VirtualClock, WallClock
from relaxgrip.errors import InputError
from relaxgrip.twin import (
    CATALOGUE,
    GripperTwin,
    MotorParams,
    ScatterParams,
    TwinConfig,
    get_object,
)


def truth(obs: Observation) -> Truth:
    assert obs.truth is not None, "the twin always reports its truth"
    return obs.truth


def run_grasp(seed: int, config: TwinConfig | None = None, seconds: float = 12.0):
    clock = VirtualClock()
    twin = GripperTwin(config or TwinConfig(initial_temp_c=40.0), seed=seed, clock=clock)
    rows = []
    for k in range(int(seconds * 30)):
        v = 20.0 if k < 150 else 0.0
        twin.act(Command(v, (0.3, 0.2)))
        clock.advance(1 / 30)
        obs = twin.observe()
        t = truth(obs)
        rows.append((obs.t_s, obs.motor_position_mm, t.contact_force_n,
                     *t.finger_temps_c[0], *t.marker_deflection_m))
    return np.array(rows)


def test_twin_implements_the_backend_protocol():
    clock = VirtualClock()
    twin = GripperTwin(clock=clock)
    assert isinstance(twin, Gripper)
    check_backend(twin, clock.advance)
    assert twin.info.has_truth
    assert twin.info.version.startswith("relaxgrip-twin-v")


def test_same_seed_identical_run_other_seed_differs():
    a, b, c = run_grasp(3), run_grasp(3), run_grasp(4)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_virtual_time_and_step_size_independence():
    # The integrators are exact: observing at 30 Hz or once at the end agrees.
    cfg = TwinConfig(initial_temp_c=40.0)
    fine_clock, coarse_clock = VirtualClock(), VirtualClock()
    fine = GripperTwin(cfg, seed=1, clock=fine_clock)
    coarse = GripperTwin(cfg, seed=1, clock=coarse_clock)
    for twin in (fine, coarse):
        twin.act(Command(20.0, (0.4, 0.4)))
    for _ in range(90):
        fine_clock.advance(1 / 30)
        fine.observe()
    coarse_clock.advance(3.0)
    a, b = truth(fine.observe()), truth(coarse.observe())
    assert a.aperture_m == pytest.approx(b.aperture_m, abs=1e-9)
    assert a.finger_temps_c[0][2] == pytest.approx(b.finger_temps_c[0][2], abs=1e-9)


def test_wall_clock_runs_in_real_time():
    clock = WallClock()
    twin = GripperTwin(clock=clock)
    t_act = clock.now()
    twin.act(Command(10.0))
    clock.sleep_until(t_act + 0.2)
    obs = twin.observe()
    assert obs.t_s >= t_act + 0.2
    assert obs.motor_position_mm == pytest.approx(10.0 * (obs.t_s - t_act), abs=1.0)


def test_motor_velocity_limit_lag_and_encoder():
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(object_name=None), clock=clock)
    twin.act(Command(1000.0))
    clock.advance(0.05)
    lagged = twin.observe().motor_position_mm
    limit = twin.config.motor.max_velocity_mm_s
    assert 0 < lagged < limit * 0.05
    clock.advance(1.0)
    obs = twin.observe()
    assert obs.motor_position_mm == pytest.approx(limit * 1.05 - limit * twin.config.motor.lag_s,
                                                  abs=0.05)
    res = twin.config.motor.encoder_resolution_mm
    assert obs.motor_position_mm / res == pytest.approx(round(obs.motor_position_mm / res))
    clock.advance(30.0)
    assert twin.observe().motor_position_mm == pytest.approx(twin.config.motor.stroke_mm)


def test_each_finger_heats_with_its_own_heater():
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(object_name=None), clock=clock)
    twin.act(Command(0.0, (1.0, 0.0)))
    clock.advance(120.0)
    t = truth(twin.observe())
    assert np.mean(t.finger_temps_c[0]) > 55.0
    assert np.mean(t.finger_temps_c[1]) == pytest.approx(twin.material.ambient_c, abs=0.01)


def test_contact_force_and_relaxation_at_fixed_aperture():
    rows = run_grasp(0, seconds=60.0)
    force = rows[:, 2]
    held = force[200:]
    assert held[0] > 3.0
    assert np.all(np.diff(held) < 1e-9), "force relaxes at a fixed aperture"
    assert np.all(force >= 0.0)
    assert np.all(rows[150:, -1] > 0), "the marker moves with the loaded finger"


def test_release_brings_the_force_to_zero_and_fingers_recover():
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(initial_temp_c=55.0), seed=0, clock=clock)
    twin.act(Command(20.0))
    clock.advance(5.5)
    assert truth(twin.observe()).contact_force_n > 1.0
    twin.act(Command(-20.0))
    clock.advance(2.0)
    t = truth(twin.observe())
    assert t.contact_force_n == 0.0
    clock.advance(600.0)
    assert max(abs(x) for x in truth(twin.observe()).finger_deflection_m) < 1e-5


def test_crushable_object_takes_a_permanent_set():
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(object_name="aluminium_can"), seed=0, clock=clock)
    twin.act(Command(20.0))
    clock.advance(5.0)
    t = truth(twin.observe())
    assert t.contact_force_n == pytest.approx(get_object("aluminium_can").yield_force_n)
    assert t.object_crushed
    assert t.object_plastic_m > 0.0


@pytest.mark.parametrize(("name", "lifted"), [("hammer", True), ("weight_1kg", False)])
def test_lift_holds_by_friction_or_slips(name, lifted):
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(object_name=name, initial_temp_c=25.0), seed=0, clock=clock)
    obj = get_object(name)
    gap_s = (150.0 - obj.width_m * 1e3) / 20.0
    twin.act(Command(20.0))
    clock.advance(gap_s + 0.45)  # ~8 mm interpenetration: about 5 N
    twin.act(Command(0.0, arm_velocity_mm_s=20.0))
    clock.advance(1.0)
    t = truth(twin.observe())
    assert t.object_lifted is lifted
    assert t.object_slipping is (not lifted)


def _hammer_lifted(grip_n: float, lift_mm: float) -> tuple[GripperTwin, VirtualClock]:
    """The hammer gripped with ``grip_n`` and the arm raised by ``lift_mm`` at 30 mm/s."""
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(object_name="hammer").without_sensors(), seed=0, clock=clock)
    twin.act(Command(5.0))
    while truth(twin.observe()).contact_force_n < grip_n:
        clock.advance(1 / 30)
    twin.act(Command(0.0, arm_velocity_mm_s=30.0))
    clock.advance(lift_mm / 30.0)
    twin.act(Command())
    return twin, clock


def test_a_lifted_object_let_go_of_falls_and_stays_behind():
    twin, clock = _hammer_lifted(5.0, 40.0)
    assert truth(twin.observe()).object_lifted
    twin.act(Command(-20.0))  # open with the arm still: it fell nowhere and went along
    clock.advance(5.0)
    t = truth(twin.observe())
    assert t.contact_force_n == 0.0
    assert not t.object_lifted
    twin.act(Command(0.0, approach_velocity_mm_s=-20.0))  # back off: it stays on the table
    clock.advance(2.0)
    assert truth(twin.observe()).object_ahead_m == pytest.approx(0.040)


def test_an_object_that_slipped_is_gripped_again_where_it_lies():
    # 1 N cannot carry the hammer: it slips back to the table as the arm rises 30 mm.
    # Squeezed harder, it is held where the fingers are on it, not lifted to the arm
    # (it jumped 30 mm in one period), and rises with the arm from there.
    twin, clock = _hammer_lifted(1.0, 30.0)
    t = truth(twin.observe())
    assert t.object_slipping
    assert not t.object_lifted
    twin.act(Command(5.0))
    while truth(twin.observe()).contact_force_n < 8.0:
        clock.advance(1 / 30)
        assert not truth(twin.observe()).object_lifted
    twin.act(Command(0.0, arm_velocity_mm_s=30.0))
    clock.advance(0.5)
    t = truth(twin.observe())
    assert t.object_lifted
    assert not t.object_slipping


def test_an_object_is_put_between_open_fingers_only():
    twin, clock = _hammer_lifted(5.0, 0.0)
    with pytest.raises(InputError, match="open them first"):
        twin.set_object("orange")
    twin.set_object("orange", ahead_m=0.1)  # ahead of them: any aperture
    twin.act(Command(-20.0))
    clock.advance(8.0)
    twin.observe()
    twin.set_object("orange")
    assert truth(twin.observe()).contact_force_n == 0.0


def test_frames_keep_time_with_a_clock_stepped_by_sums():
    # advance(1/30) far from t = 0 adds round-off of 1e-10 s a step: past a nanosecond,
    # every observation carried the previous period's frame (after half an hour from 0).
    clock = VirtualClock(1e6)
    twin = GripperTwin(TwinConfig(ir=None), seed=0, clock=clock)
    seqs = []
    for _ in range(300):
        clock.advance(1 / 30)
        obs = twin.observe()
        assert obs.rgb is not None
        assert abs(obs.rgb.t_s - obs.t_s) < 1e-6
        seqs.append(obs.rgb.seq)
    assert np.all(np.diff(seqs) == 1)


def test_a_command_keeps_the_duties_it_was_checked_with():
    duty = [1.0, 1.0]
    command = Command(0.0, duty)  # type: ignore[arg-type]
    duty[0] = 50.0
    assert command.heater_duty == (1.0, 1.0)


def test_adhesion_pads_hold_a_flat_object_only_when_heated():
    def lift(temp_c: float) -> bool:
        clock = VirtualClock()
        cfg = TwinConfig(object_name="flat_box", initial_temp_c=temp_c)
        twin = GripperTwin(cfg, seed=0, clock=clock)
        twin.act(Command(20.0, (0.5, 0.5)))
        clock.advance((150.0 - 40.0) / 20.0 + 0.05)
        twin.act(Command(0.0, (0.5, 0.5), arm_velocity_mm_s=20.0))
        clock.advance(0.5)
        return truth(twin.observe()).object_lifted

    assert not lift(25.0)
    assert lift(58.0)


def test_catalogue_and_bad_input():
    assert {"force_ball", "hammer", "orange", "balloon", "paper_cup", "glass", "aluminium_can",
            "weight_1kg", "feather", "brush", "wrench"} <= set(CATALOGUE)
    with pytest.raises(InputError, match="unknown object 'anvil'"):
        TwinConfig(object_name="anvil")
    with pytest.raises(InputError, match="outside 0-1"):
        Command(0.0, (1.2, 0.0))
    with pytest.raises(InputError, match="finite"):
        Command(math.nan)
    with pytest.raises(InputError, match="absolute zero"):
        TwinConfig(ambient_c=-300.0)
    with pytest.raises(InputError, match=r"heat model's finger is 0\.15 m long"):
        TwinConfig(heat=replace(TwinConfig().heat, length_m=0.15))
    with pytest.raises(InputError, match="non-negative"):
        GripperTwin(seed=-1)


def test_nominal_twin_has_no_scatter():
    cfg = TwinConfig(scatter=ScatterParams().scaled(0.0))
    a, b = GripperTwin(cfg, seed=1).material, GripperTwin(cfg, seed=2).material
    assert a == b
    assert replace(cfg).object is not None


@pytest.mark.parametrize("push_n", [-2.0, -20.0])
def test_a_push_towards_finger_0_never_pulls_on_finger_1(push_n):
    # Finger 1 presses with F + push: a push towards finger 0 larger than the squeeze
    # had finger 1 pull the object (F + push < 0, finger 1 bent inwards).
    twin, clock = _hammer_lifted(5.0, 0.0)
    twin.set_external_force(push_n)
    for _ in range(30):
        clock.advance(1 / 30)
        t = truth(twin.observe())
        assert t.contact_force_n >= 0.0
        assert t.contact_force_n + push_n >= -1e-9 or t.contact_force_n == 0.0
        assert t.finger_deflection_m[1] >= 0.0
    if push_n == -2.0:  # the squeeze holds: finger 0 presses harder than finger 1, by the push
        assert t.contact_force_n > 2.0
        assert t.finger_deflection_m[0] > t.finger_deflection_m[1]


def test_a_push_either_way_is_mirrored_between_the_fingers():
    # Two identical fingers: a push towards finger 0 is the mirror of one towards finger 1
    # (the object was compressed by the larger force one way and the smaller the other).
    def pushed(push_n: float) -> Truth:
        clock = VirtualClock()
        cfg = TwinConfig(object_name="hammer", scatter=ScatterParams().scaled(0.0))
        twin = GripperTwin(cfg.without_sensors(), seed=0, clock=clock)
        twin.act(Command(5.0))
        while truth(twin.observe()).contact_force_n < 5.0:
            clock.advance(1 / 30)
        twin.act(Command())
        twin.set_external_force(push_n)
        clock.advance(1.0)
        return truth(twin.observe())

    towards_1, towards_0 = pushed(2.0), pushed(-2.0)
    assert towards_0.contact_force_n == pytest.approx(towards_1.contact_force_n + 2.0, abs=1e-9)
    assert towards_0.finger_deflection_m == pytest.approx(towards_1.finger_deflection_m[::-1],
                                                          abs=1e-12)


@pytest.mark.parametrize(
    ("motor", "match"),
    [
        ({"lag_s": 0.0}, "lag_s"),  # ZeroDivisionError at the first step
        ({"encoder_resolution_mm": 0.0}, "encoder_resolution_mm"),  # at the first observe
        ({"stroke_mm": -1.0}, "stroke_mm"),  # the motor sat at -1 mm
        ({"max_velocity_mm_s": math.nan}, "max_velocity_mm_s"),  # the motor moved anyway
        ({"max_velocity_mm_s": -20.0}, "max_velocity_mm_s"),
    ],
)
def test_motor_params_refuse_impossible_values(motor, match):
    with pytest.raises(InputError, match=match):
        MotorParams(**motor)


@pytest.mark.parametrize("seed", [None, 1.5, "3", True])
def test_a_seed_that_is_no_integer_is_refused(seed):
    # None raised AttributeError; 1.5 ran as seed 1 and "3" as seed 3.
    with pytest.raises(InputError, match="seed"):
        GripperTwin(TwinConfig().without_sensors(), seed=seed)


def test_a_scene_of_anything_but_scene_objects_is_refused():
    twin = GripperTwin(TwinConfig(rgb=None))
    with pytest.raises(InputError, match="SceneObject"):
        twin.set_scene(("glass",))  # type: ignore[arg-type]
    twin.observe()  # the old scene is kept (it raised AttributeError in the camera)


def test_fingers_lowered_onto_an_object_that_slid_out_close_on_it():
    # The hammer slid out of a 1 N grip; the arm comes back down over it with the fingers
    # open: they closed through it (2 mm apart around a 32 mm hammer, no force).
    twin, clock = _hammer_lifted(1.0, 60.0)
    assert truth(twin.observe()).object_ahead_m == 0.0
    twin.act(Command(-20.0))
    clock.advance(1.0)
    twin.act(Command(0.0, arm_velocity_mm_s=-30.0))
    clock.advance(2.5)
    twin.act(Command(5.0))
    while truth(twin.observe()).contact_force_n < 5.0:
        clock.advance(1 / 30)
        assert twin.aperture_m > get_object("hammer").width_m - 0.02
    twin.act(Command(0.0, arm_velocity_mm_s=30.0))
    clock.advance(0.5)
    assert truth(twin.observe()).object_lifted


def test_closed_fingers_lowered_onto_an_object_stop_on_its_top():
    twin, clock = _hammer_lifted(1.0, 60.0)
    twin.act(Command(0.0, arm_velocity_mm_s=-30.0))  # still closed on nothing: 30 mm apart
    clock.advance(2.5)
    obs = twin.observe()
    assert obs.arm_height_mm == pytest.approx(get_object("hammer").grip_length_m * 1e3)
    assert truth(obs).contact_force_n == 0.0


def test_an_object_gripped_after_the_fingers_slid_down_it_rises_with_the_arm():
    # Raised 30 mm with the fingers open and lowered again, the fingers held the hammer
    # 30 mm above the table: squeezed and lifted 15 mm, it stayed on the table, not slipping.
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(object_name="hammer").without_sensors(), seed=0, clock=clock)
    twin.act(Command(0.0, arm_velocity_mm_s=30.0))
    clock.advance(1.0)
    twin.act(Command(0.0, arm_velocity_mm_s=-30.0))
    clock.advance(1.5)
    twin.act(Command(20.0))
    while truth(twin.observe()).contact_force_n < 5.0:
        clock.advance(1 / 30)
    twin.act(Command(0.0, arm_velocity_mm_s=30.0))
    clock.advance(0.5)
    t = truth(twin.observe())
    assert t.object_lifted
    assert not t.object_slipping
