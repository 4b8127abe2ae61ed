"""The infrared windows follow the fingers as their load bends them.

A real finger moves its distal beams 5 mm at 5 N and 40 °C, 12 mm at 8 N and
55 °C, across a 12 mm face: read where the unloaded finger is, those windows
see the gap or the room.  The twin draws the bend (``IrSensorConfig.draw_bend``,
on by default), and perception reads the windows on the bent fingers from the
marker's deflection and slope (``RigGeometry.ir_follow_bend``, on by default).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from relaxgrip.backend import Frame
from relaxgrip.perception.pipeline import finger_bend
from relaxgrip.perception.thermal import ThermalPerception
from relaxgrip.physics.beam import beam_grid, unit_profile_m_per_n
from relaxgrip.rig import RigGeometry, bend_profile_m
from relaxgrip.twin import TwinConfig
from relaxgrip.twin.render_ir import IrRenderer
from relaxgrip.twin.sensors import IrSensorConfig

CFG = TwinConfig()
RIG = CFG.rig
NODES = np.linspace(0.0, RIG.finger.length_m, 12)
APERTURE_M = 0.07
MOTOR_MM = (RIG.open_aperture_m - APERTURE_M) * 1e3


def _bent(force_n: float, temps_c: np.ndarray, contact_m: float = 0.08
          ) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """The fingers' deflection on the beam grid under ``force_n`` (the twin's beam), and
    the marker finger's deflection and slope at the tab."""
    x = beam_grid(CFG.finger)
    z, slope = unit_profile_m_per_n(contact_m, np.interp(x, NODES, temps_c), CFG.finger)
    tab = RIG.marker.position_m
    return x, force_n * z, (force_n * float(np.interp(tab, x, z)),
                            force_n * float(np.interp(tab, x, slope)))


@pytest.mark.parametrize(("force_n", "hot_c"), [(5.0, 40.0), (8.0, 55.0)])
def test_windows_on_bent_fingers_read_the_fingers(force_n: float, hot_c: float) -> None:
    temps = np.linspace(hot_c, hot_c - 12.0, NODES.size)  # graded: a window off reads wrong
    x, bend, at_tab = _bent(force_n, temps)
    renderer = IrRenderer(RIG, IrSensorConfig(netd_k=0.0, max_offset_k=0.0), seed=0)
    frame = Frame(0.0, 0, renderer.render(0, np.stack([temps, temps]), NODES, APERTURE_M, [],
                                          22.0, (x, np.stack([bend, bend]))))
    truth = np.interp(RIG.finger.beam_positions_m, NODES, temps)
    following = ThermalPerception(RIG)
    unbent = ThermalPerception(replace(RIG, ir_follow_bend=False))
    for j in (0, 1):
        read = np.array(following.extract(frame, MOTOR_MM, at_tab).fingers[j].beam_temps_c)
        assert np.all(np.isfinite(read)), read
        assert np.abs(read - truth).max() < 0.2, (read, truth)
        off = np.array(unbent.extract(frame, MOTOR_MM, at_tab).fingers[j].beam_temps_c)
        # Read where the unloaded finger is, the distal beam misses it (nan counts too).
        assert not np.abs(off[-1] - truth[-1]) < 1.0, (off, truth)
    # Unbent frames read the same either way: no load, no move.
    flat = Frame(0.0, 0, renderer.render(0, np.stack([temps, temps]), NODES, APERTURE_M, [],
                                         22.0))
    assert np.array_equal(following.extract(flat, MOTOR_MM, (0.0, 0.0)).fingers[0].beam_temps_c,
                          unbent.extract(flat, MOTOR_MM).fingers[0].beam_temps_c)


def test_the_bend_read_from_the_marker_is_the_finger_s() -> None:
    """The marker's pose relative to its zero gives the tab's deflection and slope, and
    the profile through them is within 4 % of the beam's at every beam (loaded at 80 mm)."""
    import cv2

    x, bend, (deflection, slope) = _bent(8.0, np.full(NODES.size, 55.0))
    rest, bent = RIG.marker2cam(), RIG.marker2cam(deflection, slope)
    delta_r = np.asarray(cv2.Rodrigues(bent[:3, :3] @ rest[:3, :3].T)[0], dtype=np.float64).ravel()
    read = finger_bend(RIG, bent[:3, 3] - rest[:3, 3], delta_r)
    assert read == pytest.approx((deflection, slope), abs=1e-12)
    beams = np.asarray(RIG.finger.beam_positions_m)
    profile = bend_profile_m(beams, RIG.marker.position_m, *read)
    true = np.interp(beams, x, bend)
    assert np.abs(profile / true - 1.0).max() < 0.04


def test_a_rig_that_does_not_follow_ignores_the_bend() -> None:
    """Frames of fingers drawn unbent (the twin before v5) are read unbent: a bend given
    to a perception that does not follow changes nothing."""
    temps = np.full(NODES.size, 40.0)
    renderer = IrRenderer(RIG, IrSensorConfig(), seed=0)
    frame = Frame(0.0, 0, renderer.render(0, np.stack([temps, temps]), NODES, APERTURE_M, [],
                                          22.0))
    perception = ThermalPerception(RigGeometry(ir_follow_bend=False))
    a = perception.extract(frame, MOTOR_MM)
    b = perception.extract(frame, MOTOR_MM, (0.005, 0.1))
    assert np.array_equal(a.fingers[0].beam_temps_c, b.fingers[0].beam_temps_c)


def test_perception_reads_the_infrared_frame_on_the_bend_the_marker_shows() -> None:
    """Through the pipeline: the marker zeroed, then bent over a second under 8 N at 55 °C,
    then an infrared frame: with ``ir_follow_bend`` it is read on the bent fingers."""
    from relaxgrip.perception.pipeline import Perception
    from relaxgrip.twin.render_rgb import RgbRenderer
    from relaxgrip.twin.sensors import RgbSensorConfig

    temps = np.linspace(55.0, 43.0, NODES.size)
    x, bend, (deflection, slope) = _bent(8.0, temps)
    rgb = RgbRenderer(RIG, RgbSensorConfig(), 0)
    ir = IrRenderer(RIG, IrSensorConfig(netd_k=0.0, max_offset_k=0.0), seed=0)
    ir_frame = ir.render(0, np.stack([temps, temps]), NODES, APERTURE_M, [], 22.0,
                         (x, np.stack([bend, bend])))
    truth = np.interp(RIG.finger.beam_positions_m, NODES, temps)
    errors = {}
    for follow in (False, True):
        perception = Perception(replace(RIG, ir_follow_bend=follow))
        for k in range(60):  # 1 s at rest (the zero), then bent over 1 s
            share = min(1.0, max(0.0, (k - 29) / 30))
            pose = RIG.marker2cam(share * deflection, share * slope)
            perception.update(Frame(k / 30, k, rgb.render(k, pose)), None, MOTOR_MM)
        percept = perception.update(Frame(2.0, 60, rgb.render(60, pose)),
                                    Frame(2.0, 0, ir_frame), MOTOR_MM)
        assert percept.thermal is not None
        errors[follow] = np.array(percept.thermal.fingers[0].beam_temps_c) - truth
    assert np.abs(errors[True]).max() < 0.3, errors[True]
    assert not np.abs(errors[False][-1]) < 5.0, errors[False]


def test_only_the_loaded_fingers_are_read_bent() -> None:
    """An object pressed against the marker finger alone (the other is a rigid jaw):
    with ``loaded_fingers=(marker finger,)`` the jaw's windows stay where it is, unbent.
    Read bent as in a grasp, its distal windows leave it."""
    temps = np.linspace(55.0, 43.0, NODES.size)
    x, bend, at_tab = _bent(8.0, temps)
    j = RIG.marker_finger
    bends = np.zeros((2, x.size))
    bends[j] = bend
    renderer = IrRenderer(RIG, IrSensorConfig(netd_k=0.0, max_offset_k=0.0), seed=0)
    frame = Frame(0.0, 0, renderer.render(0, np.stack([temps, temps]), NODES, APERTURE_M, [],
                                          22.0, (x, bends)))
    truth = np.interp(RIG.finger.beam_positions_m, NODES, temps)
    one = ThermalPerception(RIG, loaded_fingers=(j,)).extract(frame, MOTOR_MM, at_tab)
    for finger in one.fingers:
        read = np.array(finger.beam_temps_c)
        assert np.abs(read - truth).max() < 0.2, (read, truth)
    both = ThermalPerception(RIG).extract(frame, MOTOR_MM, at_tab)
    jaw = np.array(both.fingers[1 - j].beam_temps_c)
    assert not np.abs(jaw[-1] - truth[-1]) < 1.0, (jaw, truth)


@pytest.mark.parametrize("loaded", [(0, 0), (2,), (-1, 1)])
def test_loaded_fingers_must_be_fingers(loaded: tuple[int, ...]) -> None:
    from relaxgrip.errors import InputError

    with pytest.raises(InputError, match="loaded_fingers"):
        ThermalPerception(RIG, loaded_fingers=loaded)
