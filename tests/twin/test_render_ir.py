"""The twin's infrared camera: radiometry, offset, noise, determinism, geometry."""

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.physics.thermal import HeatParams, node_positions_m
from relaxgrip.rig import RigGeometry, transform_points
from relaxgrip.twin.render_ir import IrObject, IrRenderer, apparent_temp_c
from relaxgrip.twin.sensors import IrSensorConfig

RIG = RigGeometry()
NODES = node_positions_m(HeatParams())
AMBIENT_C = 25.0
EXAMPLE_C = np.array([[40, 41, 42, 41, 40], [55, 56, 57, 56, 55]], dtype=float)
QUIET = IrSensorConfig(netd_k=0.0, max_offset_k=0.0)


def at_ambient() -> np.ndarray:
    return np.full((2, NODES.size), AMBIENT_C)


def face_pixel(j: int, aperture_m: float, along_m: float) -> tuple[int, int]:
    """(row, col) of the pixel nearest to a point on the centre line of finger j's face."""
    p = transform_points(RIG.ir.gripper2cam, RIG.top_points_gripper(j, aperture_m, along_m))
    u, v = RIG.ir.intrinsics.project(p)
    return round(float(v)), round(float(u))


def object_pixel(center_gripper_m: tuple[float, float, float]) -> tuple[int, int]:
    u, v = RIG.ir.intrinsics.project(transform_points(RIG.ir.gripper2cam, center_gripper_m))
    return round(float(v)), round(float(u))


def test_frame_shape_and_dtype():
    img = IrRenderer(RIG, IrSensorConfig(), seed=0).render(
        0, EXAMPLE_C, NODES, 0.075, [], AMBIENT_C
    )
    assert img.shape == RIG.ir.intrinsics.shape == (192, 256)
    assert img.dtype == np.float32
    assert np.all(np.isfinite(img))


def test_uniform_scene_reads_ambient_plus_offset_with_netd_noise():
    config = IrSensorConfig()
    renderer = IrRenderer(RIG, config, seed=4)
    img = renderer.render(0, at_ambient(), NODES, 0.075, [], AMBIENT_C)
    assert float(img.mean()) == pytest.approx(AMBIENT_C + renderer.offset_k, abs=0.005)
    assert float(img.std()) == pytest.approx(config.netd_k, rel=0.05)


def test_offset_is_bounded_fixed_per_unit_and_varies_across_units():
    config = IrSensorConfig(max_offset_k=0.8)
    assert IrRenderer(RIG, config, seed=3).offset_k == IrRenderer(RIG, config, seed=9).offset_k
    offsets = [IrRenderer(RIG, config, seed=0, unit=u).offset_k for u in range(20)]
    assert all(abs(o) <= config.max_offset_k for o in offsets)
    assert len(set(offsets)) == len(offsets)
    assert max(offsets) - min(offsets) > config.max_offset_k  # spread over the range
    assert IrRenderer(RIG, config, seed=2, unit=7).offset_k == offsets[7]
    renderer = IrRenderer(RIG, config, seed=5, unit=7)
    means = [
        float(renderer.render(seq, at_ambient(), NODES, 0.075, [], AMBIENT_C).mean())
        for seq in range(3)
    ]
    assert np.allclose(means, AMBIENT_C + offsets[7], atol=0.005)


def test_no_offset_and_no_noise_reads_ambient_exactly():
    img = IrRenderer(RIG, QUIET, seed=1).render(0, at_ambient(), NODES, 0.05, [], AMBIENT_C)
    assert np.allclose(img, AMBIENT_C, atol=1e-3)


def test_frames_are_deterministic_per_seed_and_seq():
    args = (EXAMPLE_C, NODES, 0.075, [IrObject((0.2, 0.0, 0.0), 0.03, 50.0, 0.9)], AMBIENT_C)
    a = IrRenderer(RIG, IrSensorConfig(), seed=3)
    first = a.render(5, *args)
    a.render(6, *args)
    b = IrRenderer(RIG, IrSensorConfig(), seed=3)
    assert np.array_equal(first, a.render(5, *args))
    assert np.array_equal(first, b.render(5, *args))
    assert not np.array_equal(first, a.render(6, *args))
    assert not np.array_equal(first, IrRenderer(RIG, IrSensorConfig(), seed=4).render(5, *args))


def test_hot_finger_appears_hot_where_it_is_projected():
    config = IrSensorConfig()
    renderer = IrRenderer(RIG, config, seed=2)
    temps = at_ambient()
    temps[0] = 60.0
    aperture = 0.075
    img = renderer.render(0, temps, NODES, aperture, [], AMBIENT_C)
    expected = float(apparent_temp_c(60.0, config.finger_emissivity, AMBIENT_C))
    for along in (0.02, 0.055, 0.09):
        row, col = face_pixel(0, aperture, along)
        assert img[row, col] == pytest.approx(expected + renderer.offset_k, abs=0.3)
        assert col > RIG.ir.intrinsics.cx_px  # finger 0 is on the right of the image
        row1, col1 = face_pixel(1, aperture, along)
        assert col1 < RIG.ir.intrinsics.cx_px
        assert img[row1, col1] == pytest.approx(AMBIENT_C + renderer.offset_k, abs=0.3)
    # Far from the fingers: background.
    assert img[5, 5] == pytest.approx(AMBIENT_C + renderer.offset_k, abs=0.3)


def test_graded_finger_shows_its_gradient_root_to_tip():
    temps = np.array([np.linspace(35.0, 55.0, NODES.size), np.linspace(55.0, 35.0, NODES.size)])
    aperture = 0.09
    img = IrRenderer(RIG, QUIET, seed=0).render(0, temps, NODES, aperture, [], AMBIENT_C)
    along = np.array([0.02, 0.04, 0.06, 0.08])
    for j, sign in ((0, 1.0), (1, -1.0)):
        readings = np.array([img[face_pixel(j, aperture, a)] for a in along])
        truth = apparent_temp_c(np.interp(along, NODES, temps[j]), 0.95, AMBIENT_C)
        assert np.all(sign * np.diff(readings) > 0)
        assert np.allclose(readings, truth, atol=1.0)  # a pixel spans mm of finger


@pytest.mark.parametrize(("emissivity", "low", "high"), [(0.92, 65.0, 70.0), (0.1, 25.0, 31.0)])
def test_object_appears_by_its_emissivity(emissivity, low, high):
    centre = (0.25, 0.0, -0.03)
    img = IrRenderer(RIG, QUIET, seed=0).render(
        0, at_ambient(), NODES, 0.075, [IrObject(centre, 0.0375, 70.0, emissivity)], AMBIENT_C
    )
    value = float(img[object_pixel(centre)])
    assert low < value < high
    assert value == pytest.approx(float(apparent_temp_c(70.0, emissivity, AMBIENT_C)), abs=0.01)


def test_aluminium_shows_the_room_not_itself():
    assert float(apparent_temp_c(70.0, 0.1, AMBIENT_C)) - AMBIENT_C < 0.15 * (70.0 - AMBIENT_C)
    assert float(apparent_temp_c(AMBIENT_C, 0.1, AMBIENT_C)) == pytest.approx(AMBIENT_C)


def test_near_things_cover_far_ones():
    aperture = 0.075
    temps = np.full((2, NODES.size), 60.0)
    row, col = face_pixel(0, aperture, 0.08)
    # A sphere on the line of sight to the finger covers it ...
    p = transform_points(RIG.ir.gripper2cam, RIG.top_points_gripper(0, aperture, 0.08))
    ray = transform_points(RIG.ir.cam2gripper, 0.5 * p)
    front = IrObject((float(ray[0]), float(ray[1]), float(ray[2])), 0.01, 35.0, 1.0)
    # ... one behind it does not.
    far = transform_points(RIG.ir.cam2gripper, 2.0 * p)
    back = IrObject((float(far[0]), float(far[1]), float(far[2])), 0.02, 35.0, 1.0)
    renderer = IrRenderer(RIG, QUIET, seed=0)
    covered = renderer.render(0, temps, NODES, aperture, [front], AMBIENT_C)
    assert covered[row, col] == pytest.approx(35.0, abs=0.05)
    hidden = renderer.render(0, temps, NODES, aperture, [back], AMBIENT_C)
    finger_c = float(apparent_temp_c(60.0, 0.95, AMBIENT_C))
    assert hidden[row, col] == pytest.approx(finger_c, abs=0.05)
    # Between the two: the order in which objects are given does not matter.
    both = renderer.render(0, temps, NODES, aperture, [back, front], AMBIENT_C)
    swapped = renderer.render(0, temps, NODES, aperture, [front, back], AMBIENT_C)
    assert np.array_equal(both, swapped)


@pytest.mark.parametrize("aperture_m", [0.15, 0.4, 2.0])
def test_fingers_out_of_view_do_not_crash(aperture_m):
    img = IrRenderer(RIG, IrSensorConfig(), seed=0).render(
        0, EXAMPLE_C, NODES, aperture_m, [], AMBIENT_C
    )
    assert img.shape == (192, 256)
    assert np.all(np.isfinite(img))


@pytest.mark.parametrize(
    "centre",
    [
        (-0.3, 0.0, 0.0),  # behind the camera
        (0.2, 2.0, 0.0),  # far to the side
        (-0.05, 0.0, 0.03),  # around the lens
        (-0.04, 0.0, 0.03),  # partly behind the lens
        (10.0, 0.0, 0.0),  # a dot far away
    ],
)
def test_objects_out_of_view_do_not_crash(centre):
    img = IrRenderer(RIG, QUIET, seed=0).render(
        0, at_ambient(), NODES, 0.075, [IrObject(centre, 0.03, 60.0, 0.9)], AMBIENT_C
    )
    assert np.all(np.isfinite(img))
    assert float(img.max()) <= float(apparent_temp_c(60.0, 0.9, AMBIENT_C)) + 1e-3


def test_bad_inputs_are_rejected():
    renderer = IrRenderer(RIG, IrSensorConfig(), seed=0)
    with pytest.raises(InputError, match="shape"):
        renderer.render(0, np.zeros((2, 3)), NODES, 0.075, [], AMBIENT_C)
    with pytest.raises(InputError, match="increasing"):
        renderer.render(0, EXAMPLE_C, NODES[::-1], 0.075, [], AMBIENT_C)
    with pytest.raises(InputError, match="aperture"):
        renderer.render(0, EXAMPLE_C, NODES, float("nan"), [], AMBIENT_C)
    with pytest.raises(InputError, match="absolute zero"):
        renderer.render(0, EXAMPLE_C, NODES, 0.075, [], -300.0)
    with pytest.raises(InputError, match="seed"):
        IrRenderer(RIG, IrSensorConfig(), seed=-1)
    with pytest.raises(InputError, match="emissivity"):
        IrObject((0.2, 0.0, 0.0), 0.03, 60.0, 0.0)
    with pytest.raises(InputError, match="radius"):
        IrObject((0.2, 0.0, 0.0), -0.03, 60.0, 0.5)


def test_a_frame_does_not_depend_on_the_frames_rendered_before():
    """The kept ray cast of the last geometry is invisible: same inputs, same frame."""
    ball = IrObject((0.09, 0.0, 0.0), 0.03, 50.0, 0.9)
    fresh = IrRenderer(RIG, IrSensorConfig(), seed=2)
    used = IrRenderer(RIG, IrSensorConfig(), seed=2)
    for aperture, objects in ((0.075, [ball]), (0.06, []), (0.06, [ball]), (0.075, [ball]),
                              (0.075, [IrObject((0.09, 0.0, 0.0), 0.03, 30.0, 0.9)])):
        used.render(1, EXAMPLE_C, NODES, aperture, objects, AMBIENT_C)
        used.render(2, EXAMPLE_C + 5.0, NODES, aperture, objects, AMBIENT_C)
        for temps in (EXAMPLE_C, EXAMPLE_C[::-1]):
            expected = IrRenderer(RIG, IrSensorConfig(), seed=2).render(
                3, temps, NODES, aperture, objects, AMBIENT_C)
            assert np.array_equal(used.render(3, temps, NODES, aperture, objects, AMBIENT_C),
                                  expected)
    assert not np.array_equal(fresh.render(3, EXAMPLE_C, NODES, 0.075, [ball], AMBIENT_C),
                              fresh.render(3, EXAMPLE_C, NODES, 0.074, [ball], AMBIENT_C))


def _bent_frame(samples: int, tip_m: float) -> np.ndarray:
    """Both fingers at 40 °C in a 25 °C room, bent linearly to ``tip_m`` at the tip."""
    config = IrSensorConfig(netd_k=0.0, max_offset_k=0.0, samples_per_px=samples)
    renderer = IrRenderer(RIG, config, seed=0)
    grid = np.linspace(0.0, RIG.finger.length_m, 23)
    bend = tip_m * grid / RIG.finger.length_m
    frame: np.ndarray = renderer.render(0, np.full((2, NODES.size), 40.0), NODES, 0.044, [],
                                        25.0, (grid, np.stack([bend, bend])))
    return frame


def test_a_pixel_drawn_by_its_area_follows_an_outline_between_pixel_centres() -> None:
    """Bent 20 µm further, drawn by pixel centres few pixels change; drawn by area, the
    pixels along the outlines do."""
    centre = [_bent_frame(1, tip) for tip in (4.00e-3, 4.02e-3)]
    area = [_bent_frame(4, tip) for tip in (4.00e-3, 4.02e-3)]
    changed_centre = np.count_nonzero(centre[0] != centre[1])
    changed_area = np.count_nonzero(np.abs(area[0] - area[1]) > 1e-4)
    assert changed_area > 5 * max(int(changed_centre), 1)
    # Far from the outlines a pixel is its surface either way.
    assert area[0][0, 0] == pytest.approx(centre[0][0, 0], abs=1e-4)
    # The mean over the frame is the faces' area, which both draw alike.
    assert float(area[0].mean()) == pytest.approx(float(centre[0].mean()), rel=2e-3)


def test_away_from_outlines_the_area_drawing_is_the_centre_drawing() -> None:
    """Where a pixel and its neighbours see one surface, its samples all see it too."""
    import cv2

    centre, area = _bent_frame(1, 4e-3), _bent_frame(4, 4e-3)
    kernel = np.ones((5, 5), np.uint8)
    uniform = (cv2.dilate(centre, kernel) - cv2.erode(centre, kernel)) < 1e-6
    assert uniform.mean() > 0.8
    np.testing.assert_allclose(area[uniform], centre[uniform], atol=1e-3)
    assert not np.allclose(area[~uniform], centre[~uniform], atol=1e-3)


@pytest.mark.parametrize("samples", [0, 9, 2.5, True])
def test_bad_sample_counts_are_refused(samples: object) -> None:
    with pytest.raises(InputError, match="samples_per_px"):
        IrSensorConfig(samples_per_px=samples)  # type: ignore[arg-type]
