"""The twin's RGB camera: frames depend only on their inputs."""

import numpy as np

from relaxgrip.rig import RigGeometry
from relaxgrip.twin.render_rgb import RgbObject, RgbRenderer
from relaxgrip.twin.sensors import RgbSensorConfig

RIG = RigGeometry()


def test_a_frame_does_not_depend_on_the_frames_rendered_before():
    """A scene kept from earlier frames is invisible: same inputs, same frame."""
    pose = RIG.marker2cam(0.002, 0.01)
    ball = (RgbObject((0.0, 0.01, 0.12), 0.03, (200, 100, 50)),)
    moved = (RgbObject((0.0, 0.012, 0.12), 0.03, (200, 100, 50)),)
    used = RgbRenderer(RIG, RgbSensorConfig(), 0)
    for objects in (ball, ball, ball, moved, moved, (), ball):
        expected = RgbRenderer(RIG, RgbSensorConfig(), 0).render(4, pose, objects)
        assert np.array_equal(used.render(4, pose, objects), expected)
        used.render(5, RIG.marker2cam(0.003, 0.02), objects)
    assert not np.array_equal(used.render(4, pose, ball), used.render(4, pose, moved))


def test_frames_are_new_arrays_the_caller_may_write():
    renderer = RgbRenderer(RIG, RgbSensorConfig(), 0)
    objects = (RgbObject((0.0, 0.01, 0.12), 0.03, (200, 100, 50)),)
    pose = RIG.marker2cam(0.0, 0.0)
    first = renderer.render(0, pose, objects)
    renderer.render(0, pose, objects)
    first[:] = 0
    assert renderer.render(0, pose, objects).any()
