"""The temperature loop: modes, regulation on a heat model, over-temperature and stale-IR guards."""

from __future__ import annotations

import numpy as np
import pytest

from relaxgrip.control.temperature import (
    MODE_SETPOINTS_C,
    StiffnessMode,
    TemperatureLoop,
    TemperatureStatus,
    ThermalLimits,
)
from relaxgrip.errors import InputError
from relaxgrip.perception.thermal import FingerThermal, ThermalFeatures
from relaxgrip.physics.thermal import HeatParams, heat_step

HEAT = HeatParams()
AMBIENT_C = 25.0


def finger(temps: np.ndarray, offset_k: float = 0.0) -> FingerThermal:
    beams = tuple(float(t) + offset_k for t in temps)
    return FingerThermal(beams, float(np.mean(beams)), max(beams), min(beams),
                         float(np.std(beams)), 0.0)


def features(t_s: float, temps: np.ndarray, offset_k: float = 0.0) -> ThermalFeatures:
    return ThermalFeatures(t_s, (finger(temps[0], offset_k), finger(temps[1], offset_k)),
                           AMBIENT_C + offset_k, ())


def simulate(loop: TemperatureLoop, seconds: float, start_c: float = AMBIENT_C,
             offset_k: float = 0.0) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """Both fingers on the heat model, read at 1 Hz, the loop stepped at 10 Hz."""
    temps = np.full((2, HEAT.n_nodes), start_c)
    latest = features(0.0, temps, offset_k)
    duties = []
    for k in range(round(seconds * 10)):
        t = k / 10
        if k % 10 == 0:
            latest = features(t, temps, offset_k)
        duty = loop.update(latest, t)
        duties.append(duty)
        temps = np.vstack([heat_step(temps[j], duty[j], 0.1, HEAT, AMBIENT_C) for j in range(2)])
    return temps, duties


@pytest.mark.parametrize("mode", [StiffnessMode.MEDIUM, StiffnessMode.COMPLIANT])
def test_a_mode_heats_to_its_setpoint_and_holds_it(mode):
    loop = TemperatureLoop(HEAT)
    loop.set_mode(mode)
    temps, duties = simulate(loop, 600.0)
    setpoint = MODE_SETPOINTS_C[mode]
    assert setpoint is not None
    assert temps.mean(axis=1) == pytest.approx([setpoint, setpoint], abs=0.3)
    assert loop.status is TemperatureStatus.REGULATING
    assert all(0.0 <= d <= 1.0 for pair in duties for d in pair)


def test_it_reaches_a_setpoint_within_three_minutes():
    loop = TemperatureLoop(HEAT)
    loop.set_temperature(58.0)
    temps, _ = simulate(loop, 180.0)
    assert temps.mean() > 56.5


def test_the_loop_regulates_what_the_camera_reads():
    loop = TemperatureLoop(HEAT)
    loop.set_temperature(40.0)
    temps, _ = simulate(loop, 600.0, offset_k=-1.0)  # the camera reads 1 K low
    assert temps.mean() == pytest.approx(41.0, abs=0.3)


def test_stiff_mode_switches_the_heaters_off():
    loop = TemperatureLoop(HEAT)
    loop.set_mode("stiff")
    temps = np.full((2, HEAT.n_nodes), 50.0)
    assert loop.update(features(0.0, temps), 0.0) == (0.0, 0.0)
    assert loop.status is TemperatureStatus.OFF


def test_adhesive_mode_regulates_the_pads_at_the_tip():
    loop = TemperatureLoop(HEAT)
    loop.set_mode(StiffnessMode.ADHESIVE)
    temps = np.array([[40.0, 45.0, 50.0, 55.0, 57.0]] * 2)
    assert loop.reading_c(finger(temps[0])) == pytest.approx(56.0)
    loop.set_mode(StiffnessMode.MEDIUM)
    assert loop.reading_c(finger(temps[0])) == pytest.approx(temps[0].mean())


def test_over_temperature_cuts_that_heater_until_it_cools_past_the_hysteresis():
    loop = TemperatureLoop(HEAT, ThermalLimits(max_temp_c=60.0, max_setpoint_c=59.0,
                                               hysteresis_k=2.0))
    loop.set_temperature(59.0)
    cold = np.full(HEAT.n_nodes, 30.0)
    hot = np.array([50.0, 55.0, 58.0, 61.0, 59.0])  # one beam above the limit
    duty = loop.update(features(0.0, np.vstack([hot, cold])), 0.0)
    assert duty[0] == 0.0
    assert duty[1] > 0.5
    assert loop.status is TemperatureStatus.OVER_TEMPERATURE
    cooler = hot - 1.5  # below the limit but within the hysteresis: still cut
    assert loop.update(features(1.0, np.vstack([cooler, cold])), 1.0)[0] == 0.0
    cooled = hot - 3.5
    assert loop.update(features(2.0, np.vstack([cooled, cold])), 2.0)[0] > 0.0
    assert loop.status.value == "regulating"


def test_stale_infrared_switches_every_heater_off():
    loop = TemperatureLoop(HEAT)
    loop.set_temperature(50.0)
    temps = np.full((2, HEAT.n_nodes), 30.0)
    frame = features(0.0, temps)
    assert min(loop.update(frame, 2.9)) > 0.0  # 2.9 s old: still acted on
    assert loop.update(frame, 3.1) == (0.0, 0.0)  # 3.1 s old: stale
    assert loop.status is TemperatureStatus.STALE
    assert loop.update(None, 5.0) == (0.0, 0.0)
    assert min(loop.update(features(6.0, temps), 6.0)) > 0.0  # back


def test_a_finger_out_of_view_is_not_heated_blind():
    loop = TemperatureLoop(HEAT)
    loop.set_temperature(50.0)
    temps = np.full((2, HEAT.n_nodes), 30.0)
    frame = features(0.0, temps)
    blind = FingerThermal((np.nan,) * 5, np.nan, np.nan, np.nan, np.nan, np.nan)
    frame = ThermalFeatures(0.0, (frame.fingers[0], blind), AMBIENT_C, ())
    duty = loop.update(frame, 0.0)
    assert duty[0] > 0.0
    assert duty[1] == 0.0


@pytest.mark.parametrize("mode", [StiffnessMode.ADHESIVE, StiffnessMode.COMPLIANT])
def test_a_finger_out_of_view_while_grasping_is_not_heated_blind(mode):
    # The adhesive pads under an object are read as before the grasp, moved by the
    # proximal beams: with none of them in view, that reading is no reading.
    loop = TemperatureLoop(HEAT)
    loop.set_mode(mode)
    temps = np.full((2, HEAT.n_nodes), 45.0)
    loop.update(features(0.0, temps), 0.0)
    loop.set_grasping(True)
    blind = FingerThermal((np.nan,) * HEAT.n_nodes, np.nan, np.nan, np.nan, np.nan, np.nan)
    frame = ThermalFeatures(1.0, (features(1.0, temps).fingers[0], blind), AMBIENT_C, ())
    assert np.isnan(loop.readings_c(frame)[1])
    duty = loop.update(frame, 1.0)
    assert duty[0] > 0.0
    assert duty[1] == 0.0


@pytest.mark.parametrize("bad", [80.0, 10.0, float("nan")])
def test_setpoints_outside_the_safe_range_are_refused(bad):
    loop = TemperatureLoop(HEAT)
    with pytest.raises(InputError, match="safe range"):
        loop.set_temperature(bad)
    assert loop.setpoint_c is None


def test_unknown_mode_is_refused():
    with pytest.raises(InputError, match="unknown stiffness mode"):
        TemperatureLoop(HEAT).set_mode("squishy")


def test_covered_beams_are_those_nearer_the_background_than_the_warmest():
    from relaxgrip.perception.thermal import covered_beams

    assert covered_beams([54.5, 56.5, 56.9, 30.2, 26.6], 25.0) == (False, False, False, True,
                                                                   True)
    assert covered_beams([54.5, 56.5, 56.9, 52.6, 54.2], 25.0) == (False,) * 5
    assert covered_beams([26.0, 27.0, 25.5], 25.0) == (False,) * 3  # a cold finger: no contrast
    assert covered_beams([55.0, float("nan"), 26.0], float("nan")) == (False,) * 3


def test_an_object_covering_the_tip_does_not_make_the_loop_overheat():
    """A cold object over a beam and a half: the loop regulates the finger, not the object."""
    loop = TemperatureLoop(HEAT)
    loop.set_temperature(55.0)
    temps = np.full((2, HEAT.n_nodes), 55.0)
    covered_from = 300.0
    for k in range(6000):
        t = k / 10
        if k % 10 == 0:
            seen = temps.copy()
            if t >= covered_from:  # a room-temperature ball: over the tip, half over the next
                seen[:, -1] = 26.0
                seen[:, -2] = 0.6 * seen[:, -2] + 0.4 * 26.0
            latest = features(t, seen)
        duty = loop.update(latest, t)
        temps = np.vstack([heat_step(temps[j], duty[j], 0.1, HEAT, AMBIENT_C) for j in range(2)])
    assert temps.mean(axis=1) == pytest.approx([55.0, 55.0], abs=0.3)
    assert loop.readings_c(latest)[0] == pytest.approx(55.0, abs=0.3)
    # The face's mean reads the ball: regulating it would overheat the finger.
    assert latest.fingers[0].mean_c < 50.0


def _adhesive_grasp(loop: TemperatureLoop, blind_at: int | None = None
                    ) -> tuple[np.ndarray, ThermalFeatures]:
    """60 s of the adhesive pads at 58 °C on the heat model, 10 Hz, the loop grasping from
    15 s with a room-temperature ball half over the tips; the infrared frame at step
    ``blind_at`` sees no beam.  The node temperatures at the end, and the last frame."""
    loop.set_mode(StiffnessMode.ADHESIVE)
    temps = np.full((2, HEAT.n_nodes), 58.0)
    blind = FingerThermal((np.nan,) * HEAT.n_nodes, np.nan, np.nan, np.nan, np.nan, np.nan)
    for k in range(6000):
        t = k / 10
        if k == 1500:
            loop.set_grasping(True)
        if k % 10 == 0:
            seen = temps.copy()
            if k >= 1500:  # a room-temperature ball half over the tips
                seen[:, -2:] = 0.6 * seen[:, -2:] + 0.4 * 26.0
            latest = features(t, seen)
            if k == blind_at:
                latest = ThermalFeatures(t, (blind, blind), AMBIENT_C, ())
        duty = loop.update(latest, t)
        temps = np.vstack([heat_step(temps[j], duty[j], 0.1, HEAT, AMBIENT_C) for j in range(2)])
    return temps, latest


def test_adhesive_pads_under_an_object_are_read_as_before_the_grasp():
    """An object over the tips (in part: not yet 'covered') while grasping: the pads read as
    before the fingers closed, moved with the proximal beams; the loop does not overheat."""
    loop = TemperatureLoop(HEAT)
    temps, latest = _adhesive_grasp(loop)
    assert temps[:, -2:].mean(axis=1) == pytest.approx([58.0, 58.0], abs=0.5)
    assert latest.fingers[0].beam_temps_c[-1] < 50.0  # what the camera sees of the pads
    loop.set_grasping(False)
    assert loop.readings_c(latest)[0] < 50.0  # open again: read as they are


def test_a_heater_that_does_not_warm_its_finger_latches_a_fault():
    """A frozen thermal image (fresh stamps, the same temperatures): after the fault
    window at full duty every heater stays off until a setpoint is given again."""
    loop = TemperatureLoop(HEAT)
    loop.set_temperature(58.0)
    frozen = np.full((2, HEAT.n_nodes), 26.0)
    duties = [loop.update(features(float(t), frozen), float(t)) for t in range(0, 75)]
    assert min(duties[30]) > 0.8
    assert loop.status is TemperatureStatus.HEATER_FAULT
    fault = loop.fault
    assert fault is not None
    assert "heater 0 drove" in fault
    assert duties[-1] == (0.0, 0.0)
    loop.set_temperature(58.0)  # the operator's call
    assert loop.fault is None
    assert min(loop.update(features(80.0, frozen), 80.0)) > 0.8


def test_a_heater_that_warms_its_finger_is_no_fault():
    loop = TemperatureLoop(HEAT)
    loop.set_mode(StiffnessMode.COMPLIANT)
    temps, _ = simulate(loop, 400.0)
    assert temps.mean(axis=1) == pytest.approx([58.0, 58.0], abs=0.3)
    assert loop.status is TemperatureStatus.REGULATING
    assert loop.fault is None


@pytest.mark.parametrize("stamp", [float("nan"), float("inf"), 10.0])
def test_an_infrared_frame_stamped_never_or_in_the_future_counts_as_none(stamp):
    loop = TemperatureLoop(HEAT)
    loop.set_temperature(50.0)
    frame = features(stamp, np.full((2, HEAT.n_nodes), 30.0))
    assert loop.update(frame, 1.0) == (0.0, 0.0)
    assert loop.status is TemperatureStatus.STALE


def test_a_mode_outside_the_lab_s_setpoint_range_is_refused():
    loop = TemperatureLoop(HEAT, ThermalLimits(max_setpoint_c=50.0, max_temp_c=55.0))
    with pytest.raises(InputError, match="outside the safe range 28-50"):
        loop.set_mode(StiffnessMode.COMPLIANT)
    assert loop.setpoint_c is None
    loop.set_mode(StiffnessMode.MEDIUM)
    assert loop.setpoint_c == 40.0


def test_a_finger_out_of_view_when_the_setpoint_changes_does_not_keep_the_old_integral():
    """A new setpoint re-seeds both integrators on the next frame, a finger out of view then
    too: its integral, wound up towards the old setpoint, heated it past the new one."""
    loop = TemperatureLoop(HEAT)
    loop.set_temperature(60.0)
    below = np.full((2, HEAT.n_nodes), 55.0)
    for t in range(30):
        loop.update(features(float(t), below), float(t))
    loop.set_temperature(40.0)
    near = np.full((2, HEAT.n_nodes), 39.0)
    blind = FingerThermal((np.nan,) * HEAT.n_nodes, np.nan, np.nan, np.nan, np.nan, np.nan)
    seeded = ThermalFeatures(30.0, (features(30.0, near).fingers[0], blind), AMBIENT_C, ())
    assert loop.update(seeded, 30.0)[1] == 0.0
    # Back in view: its PID starts afresh, as a new loop's does on its first frame.
    fresh_loop = TemperatureLoop(HEAT)
    fresh_loop.set_temperature(40.0)
    expected = fresh_loop.update(features(31.0, near), 31.0)[1]
    assert loop.update(features(31.0, near), 31.0)[1] == pytest.approx(expected)


def test_a_frame_out_of_view_before_the_grasp_does_not_lose_the_adhesive_pads():
    """One infrared frame with no beam in view just before the fingers close: the pads were
    then read as the object covers them, and the loop heated them to 66 °C for 58 °C."""
    temps, _ = _adhesive_grasp(TemperatureLoop(HEAT), blind_at=1490)
    assert temps[:, -2:].mean(axis=1) == pytest.approx([58.0, 58.0], abs=0.5)
