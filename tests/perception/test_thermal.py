"""Thermal perception: round trips through the twin's infrared camera."""

import itertools
import math

import numpy as np
import pytest

from relaxgrip.backend import Frame
from relaxgrip.errors import InputError
from relaxgrip.perception.features import finger_temperature_c
from relaxgrip.perception.frames import (
    DEAD_FILL_PASSES,
    MAX_DEAD_FRACTION,
    FrameError,
    check_ir_frame,
)
from relaxgrip.perception.thermal import (
    FingerThermal,
    ThermalFeatures,
    ThermalPerception,
    uncovered_mean_c,
)
from relaxgrip.physics.thermal import HeatParams, node_positions_m
from relaxgrip.rig import FingerGeometry, RigGeometry
from relaxgrip.twin.objects import get_object
from relaxgrip.twin.render_ir import IrObject, IrRenderer
from relaxgrip.twin.sensors import IrSensorConfig

RIG = RigGeometry()
NODES = node_positions_m(HeatParams())
BEAMS = np.asarray(RIG.finger.beam_positions_m)
AMBIENT_C = 25.0
EXAMPLE_C = np.array([[40, 41, 42, 41, 40], [55, 56, 57, 56, 55]], dtype=float)


def motor_mm(aperture_m: float) -> float:
    return (RIG.open_aperture_m - aperture_m) * 1e3


def sense(
    temps_c: np.ndarray,
    aperture_m: float = 0.075,
    objects: tuple[IrObject, ...] = (),
    seed: int = 1,
    seq: int = 0,
) -> tuple[ThermalFeatures, float]:
    """Render a frame with the twin's camera and read it back; also the camera's offset."""
    renderer = IrRenderer(RIG, IrSensorConfig(), seed=seed)
    image = renderer.render(seq, temps_c, NODES, aperture_m, objects, AMBIENT_C)
    features = ThermalPerception(RIG).extract(Frame(12.5, seq, image), motor_mm(aperture_m))
    return features, renderer.offset_k


def cup(name: str, y_m: float) -> IrObject:
    spec = get_object(name)
    return IrObject((0.25, y_m, -0.03), 0.5 * spec.width_m, spec.temp_c, spec.emissivity)


@pytest.mark.parametrize("aperture_m", [0.06, 0.075, 0.1, 0.13])
@pytest.mark.parametrize("seed", [1, 2])
def test_beam_temperatures_round_trip(aperture_m, seed):
    features, offset = sense(EXAMPLE_C, aperture_m, seed=seed)
    for j in (0, 1):
        truth = np.interp(BEAMS, NODES, EXAMPLE_C[j])
        beams = np.array(features.fingers[j].beam_temps_c)
        seen = np.isfinite(beams)
        assert np.count_nonzero(seen) >= 4
        # The camera's offset is unknown to perception: it reads the truth plus the offset.
        assert np.allclose(beams[seen], truth[seen] + offset, atol=0.3)


def test_uniform_finger_reads_uniform_beams():
    temps = np.array([np.full(NODES.size, 50.0), np.full(NODES.size, 35.0)])
    features, offset = sense(temps, 0.075)
    for j, temp in ((0, 50.0), (1, 35.0)):
        beams = np.array(features.fingers[j].beam_temps_c)
        assert np.all(np.isfinite(beams))
        assert float(np.std(beams)) < 0.1  # the tip beam, near the face's end, reads ~0.2 K low
        assert float(np.mean(beams)) == pytest.approx(temp + offset, abs=0.1)
        assert abs(features.fingers[j].gradient_k_per_m) < 5.0


def test_gradient_sign_and_magnitude():
    rising = np.linspace(35.0, 55.0, NODES.size)
    temps = np.array([rising, rising[::-1]])
    slope_k_per_m = (55.0 - 35.0) / (NODES[-1] - NODES[0])
    features, _ = sense(temps, 0.09)
    assert features.fingers[0].gradient_k_per_m == pytest.approx(slope_k_per_m, rel=0.1)
    assert features.fingers[1].gradient_k_per_m == pytest.approx(-slope_k_per_m, rel=0.1)


def test_face_statistics_are_ordered_and_span_the_finger():
    features, offset = sense(EXAMPLE_C, 0.075)
    for j in (0, 1):
        f = features.fingers[j]
        assert f.min_c <= f.mean_c <= f.max_c
        assert f.std_k > 0
        assert f.min_c > EXAMPLE_C[j].min() + offset - 0.5  # no background in the face mask
        assert f.max_c < EXAMPLE_C[j].max() + offset + 0.5
    assert features.background_c == pytest.approx(AMBIENT_C + offset, abs=0.02)
    assert features.t_s == 12.5
    assert features.objects == ()


def test_emissivity_correction_raises_hot_fingers():
    renderer = IrRenderer(RIG, IrSensorConfig(), seed=1)
    frame = Frame(0.0, 0, renderer.render(0, EXAMPLE_C, NODES, 0.075, [], AMBIENT_C))
    corrected = ThermalPerception(RIG, emissivity=0.95).extract(frame, motor_mm(0.075))
    apparent = ThermalPerception(RIG, emissivity=1.0).extract(frame, motor_mm(0.075))
    for j in (0, 1):
        assert corrected.fingers[j].mean_c > apparent.fingers[j].mean_c + 0.5


def test_hot_and_cool_cups_are_found_on_their_sides():
    # Finger 1's side (+y) is the left of the image, finger 0's side (-y) the right.
    hot, cool = cup("paper_cup_hot", 0.06), cup("paper_cup", -0.06)
    features, offset = sense(EXAMPLE_C, 0.075, objects=(hot, cool))
    kinds = sorted(o.kind for o in features.objects)
    assert kinds == ["cool", "warm"]
    warm_obj = next(o for o in features.objects if o.kind == "warm")
    cool_obj = next(o for o in features.objects if o.kind == "cool")
    cx = RIG.ir.intrinsics.cx_px
    assert warm_obj.centroid_px[0] < cx < cool_obj.centroid_px[0]
    assert warm_obj.peak_c > 60.0 + offset
    assert cool_obj.peak_c < features.background_c - 1.0
    assert cool_obj.temp_c < features.background_c
    areas = [o.area_px for o in features.objects]
    assert areas == sorted(areas, reverse=True)
    for o in features.objects:
        x, y, w, h = o.bbox_px
        assert x <= o.centroid_px[0] <= x + w
        assert y <= o.centroid_px[1] <= y + h
        assert o.area_px <= w * h


def test_a_cold_aluminium_can_is_not_an_object():
    can = get_object("aluminium_can")
    obj = IrObject((0.25, 0.0, -0.03), 0.5 * can.width_m, 30.0, can.emissivity)
    features, _ = sense(EXAMPLE_C, 0.075, objects=(obj,))
    assert features.objects == ()


@pytest.mark.parametrize(
    ("image", "message"),
    [
        (np.zeros((0, 0), np.float32), "empty"),
        (np.zeros((100, 100), np.float32), "expected 256x192"),
        (np.zeros((192, 256), np.int16), "dtype"),
        (np.full((192, 256), np.nan, np.float32), "non-finite"),
        (np.zeros((192, 256, 3), np.float32), "dimensions"),
        ([[25.0]], "not an image"),
        (np.zeros(192 * 256, np.float32), "1 dimensions, not an image's rows"),  # a raw buffer
    ],
)
def test_bad_frames_raise_frame_error(image, message):
    with pytest.raises(FrameError, match=message):
        ThermalPerception(RIG).extract(Frame(0.0, 0, image), 75.0)


def test_bad_settings_are_rejected():
    from relaxgrip.errors import InputError

    with pytest.raises(InputError, match="emissivity"):
        ThermalPerception(RIG, emissivity=0.0)
    with pytest.raises(InputError, match="roi_half_px"):
        ThermalPerception(RIG, roi_half_px=-1)
    with pytest.raises(InputError, match="motor_position_mm"):
        ThermalPerception(RIG).extract(Frame(0.0, 0, np.zeros((192, 256), np.float32)), math.inf)


@pytest.mark.parametrize("aperture_m", [0.0, 0.02, 0.075, RIG.open_aperture_m])
def test_every_beam_is_read_over_the_whole_stroke(aperture_m):
    # Looking down on the top faces, the camera sees every beam from closed to fully open.
    features, offset = sense(EXAMPLE_C, aperture_m)
    for j in (0, 1):
        beams = np.array(features.fingers[j].beam_temps_c)
        truth = np.interp(BEAMS, NODES, EXAMPLE_C[j]) + offset
        assert np.allclose(beams, truth, atol=0.3)
        assert math.isfinite(features.fingers[j].gradient_k_per_m)


def test_grasped_object_does_not_hide_the_beams():
    # The object between the fingers would hide their contact faces, not their tops.
    ball = IrObject((0.08, 0.0, 0.0), 0.03, AMBIENT_C, 0.95)
    renderer = IrRenderer(RIG, IrSensorConfig(), seed=0)
    frame = Frame(0.0, 0, renderer.render(0, EXAMPLE_C, NODES, 0.06, [ball], AMBIENT_C))
    features = ThermalPerception(RIG).extract(frame, motor_mm(0.06))
    for j in (0, 1):
        truth = np.interp(BEAMS, NODES, EXAMPLE_C[j]) + renderer.offset_k
        assert np.allclose(features.fingers[j].beam_temps_c, truth, atol=0.3)


@pytest.mark.parametrize("aperture_m", [0.3, 0.6])
def test_fingers_out_of_view_give_nan_without_exceptions(aperture_m):
    # Beyond the stroke the fingers leave the field of view.
    features, _ = sense(EXAMPLE_C, aperture_m)
    for f in features.fingers:
        assert all(math.isnan(b) for b in f.beam_temps_c)
        assert math.isnan(f.gradient_k_per_m)
    assert math.isfinite(features.background_c)


def test_same_frame_gives_same_features():
    renderer = IrRenderer(RIG, IrSensorConfig(), seed=5)
    frame = Frame(1.0, 3, renderer.render(3, EXAMPLE_C, NODES, 0.08, [cup("paper_cup_hot", 0.0)],
                                          AMBIENT_C))
    perception = ThermalPerception(RIG)
    first = perception.extract(frame, motor_mm(0.08))
    perception.extract(Frame(2.0, 4, frame.image), motor_mm(0.05))  # another aperture between
    again = perception.extract(frame, motor_mm(0.08))
    fresh = ThermalPerception(RIG).extract(frame, motor_mm(0.08))
    assert np.allclose(first.fingers[0].beam_temps_c, again.fingers[0].beam_temps_c, equal_nan=True)
    assert repr(first) == repr(again) == repr(fresh)


def test_round_trip_through_a_distorted_lens():
    from relaxgrip.rig import CameraIntrinsics, IrCameraMount

    lens = CameraIntrinsics(256, 192, 128.0, 128.0, 127.5, 95.5, (-0.2, 0.05, 0.0, 0.0))
    rig = RigGeometry(ir=IrCameraMount(intrinsics=lens))
    renderer = IrRenderer(rig, IrSensorConfig(), seed=1)
    image = renderer.render(0, EXAMPLE_C, NODES, 0.09, [], AMBIENT_C)
    features = ThermalPerception(rig).extract(Frame(0.0, 0, image), motor_mm(0.09))
    for j in (0, 1):
        truth = np.interp(BEAMS, NODES, EXAMPLE_C[j]) + renderer.offset_k
        assert np.allclose(features.fingers[j].beam_temps_c, truth, atol=0.3)


def _finger(beams: list[float], mean_c: float) -> FingerThermal:
    return FingerThermal(tuple(beams), mean_c, max(beams), min(beams), 1.0, 0.0)


def test_finger_temperature_leaves_out_covered_and_half_covered_beams():
    # Beams read in closed-loop holds on the ball (background 25.8 °C): at 55 °C the
    # two distal beams show the ball; at 40 °C the fourth is half covered.
    hot = _finger([54.3, 56.3, 56.6, 29.1, 26.4], mean_c=52.1)
    assert uncovered_mean_c(hot, 25.8) == pytest.approx((54.3 + 56.3 + 56.6) / 3)
    warm = _finger([39.8, 40.8, 41.0, 35.3, 30.0], mean_c=39.4)
    assert uncovered_mean_c(warm, 25.8) == pytest.approx((39.8 + 40.8 + 41.0) / 3)
    thermal = ThermalFeatures(0.0, (hot, warm), 25.8, ())
    assert finger_temperature_c(thermal) == pytest.approx(
        (uncovered_mean_c(hot, 25.8) + uncovered_mean_c(warm, 25.8)) / 2)


def test_finger_temperature_falls_back_to_the_face_without_beams_or_contrast():
    blind = _finger([math.nan] * 5, mean_c=47.0)
    assert uncovered_mean_c(blind, 25.0) == 47.0
    cold = _finger([26.0, 26.5, 25.2, 25.1, 25.0], mean_c=25.6)  # no contrast: nothing covered
    assert uncovered_mean_c(cold, 25.0) == pytest.approx(25.56)
    gone = FingerThermal((math.nan,) * 5, math.nan, math.nan, math.nan, math.nan, math.nan)
    assert math.isnan(finger_temperature_c(ThermalFeatures(0.0, (gone, gone), 25.0, ())))


def _clean_frame(aperture_m: float = 0.075) -> np.ndarray:
    return IrRenderer(RIG, IrSensorConfig(), seed=1).render(0, EXAMPLE_C, NODES, aperture_m, [],
                                                            AMBIENT_C)


def _beam_pixel(j: int, i: int, aperture_m: float = 0.075) -> tuple[int, int]:
    """(row, column) of the pixel under beam ``i`` of finger ``j``."""
    perception = ThermalPerception(RIG)
    unbent = np.zeros_like(perception._along_m)
    u, v = perception._beam_pixels(j, aperture_m, unbent)[i]
    return math.floor(v), math.floor(u)


def test_finger_temperature_weighs_the_beams_as_the_finger_bends() -> None:
    """A load at the contact bends the sections near the root most: their beams weigh most,
    those beyond the contact nothing, and a finger warming from the root reads warmer than
    the plain mean of its beams."""
    finger = FingerGeometry()
    weights = finger.bending_weights
    assert sum(weights) == pytest.approx(1.0)
    assert all(a > b for a, b in itertools.pairwise(weights))
    assert weights[-1] == 0.0  # the 99 mm beam lies beyond the 80 mm contact
    assert weights[0] == pytest.approx(69.0**2 / (69.0**2 + 47.0**2 + 25.0**2 + 3.0**2))
    # 50 s into a 40 -> 55 °C ramp (the twin, seed 3001): the tip trails the heaters.
    ramp = _finger([52.91, 55.0, 54.83, 52.31, 49.27], mean_c=52.9)
    weighted = uncovered_mean_c(ramp, 25.8, weights)
    assert weighted == pytest.approx(sum(w * b for w, b in zip(weights, ramp.beam_temps_c,
                                                                  strict=True)))
    assert weighted > uncovered_mean_c(ramp, 25.8) + 0.7
    # A covered beam leaves the mean, and the others' weights make it up.
    held = _finger([54.3, 56.3, 29.6, 29.1, 26.4], mean_c=45.0)
    assert uncovered_mean_c(held, 25.8, weights) == pytest.approx(
        (weights[0] * 54.3 + weights[1] * 56.3) / (weights[0] + weights[1]))
    # No beam of weight in view: the face's mean.
    tip_only = _finger([math.nan, math.nan, math.nan, math.nan, 50.0], mean_c=48.0)
    assert uncovered_mean_c(tip_only, 25.8, weights) == 48.0
    thermal = ThermalFeatures(0.0, (ramp, ramp), 25.8, (), weights)
    assert finger_temperature_c(thermal) == pytest.approx(weighted)
    # Perception gives its features the rig's weights.
    renderer = IrRenderer(RigGeometry(), IrSensorConfig(), seed=0)
    nodes = node_positions_m(HeatParams())
    frame = Frame(0.0, 0, renderer.render(0, np.full((2, nodes.size), 40.0), nodes, 0.07, [],
                                          22.0))
    motor_mm = (RigGeometry().open_aperture_m - 0.07) * 1e3
    assert ThermalPerception(RigGeometry()).extract(frame, motor_mm).beam_weights == weights


def test_a_contact_off_the_finger_is_refused_and_one_before_every_beam_weighs_them_alike() -> None:
    with pytest.raises(InputError, match=r"contact position 0\.2 m is outside the finger"):
        FingerGeometry(contact_m=0.2)
    assert FingerGeometry(contact_m=0.005).bending_weights == (0.2,) * 5


def test_dead_pixels_are_read_from_their_neighbours() -> None:
    # A microbolometer reports its dead pixels as NaN: one on each finger's middle beam,
    # a +inf on the face, a 2x2 cluster in the background, a -inf in a corner.
    clean = _clean_frame()
    image = clean.copy()
    dead = [_beam_pixel(0, 2), _beam_pixel(1, 2), (_beam_pixel(1, 1)[0], _beam_pixel(1, 1)[1] + 1),
            (20, 30), (20, 31), (21, 30), (21, 31), (0, 0)]
    for k, (row, col) in enumerate(dead):
        image[row, col] = (np.nan, np.inf, -np.inf)[k % 3]
    assert np.count_nonzero(~np.isfinite(image)) == len(dead)
    perception = ThermalPerception(RIG)
    got = perception.extract(Frame(0.0, 0, image), motor_mm(0.075))
    want = perception.extract(Frame(0.0, 0, clean), motor_mm(0.075))
    assert np.count_nonzero(~np.isfinite(image)) == len(dead)  # the caller's frame is kept
    for j in (0, 1):
        g, w = got.fingers[j], want.fingers[j]
        assert np.all(np.isfinite(g.beam_temps_c))
        assert np.allclose(g.beam_temps_c, w.beam_temps_c, atol=0.05)
        for name in ("mean_c", "max_c", "min_c", "std_k", "gradient_k_per_m"):
            assert math.isfinite(getattr(g, name)), name
        assert g.mean_c == pytest.approx(w.mean_c, abs=0.01)
    assert got.background_c == pytest.approx(want.background_c, abs=0.01)
    assert got.objects == want.objects


def test_a_dead_pixel_is_the_mean_of_its_live_neighbours() -> None:
    image = np.arange(192 * 256, dtype=np.float32).reshape(192, 256) / 100.0
    image[50, 60] = np.nan  # its eight neighbours are live
    image[100:102, 100] = np.nan  # each has seven live neighbours
    out = check_ir_frame(image, RIG.ir.intrinsics)
    ring = np.r_[image[49, 59:62], image[50, [59, 61]], image[51, 59:62]]
    assert out[50, 60] == pytest.approx(float(ring.mean()), rel=1e-6)
    upper = np.r_[image[99, 99:102], image[100, [99, 101]], image[101, [99, 101]]]
    assert out[100, 100] == pytest.approx(float(upper.mean()), rel=1e-6)
    live = np.isfinite(image)
    assert np.array_equal(out[live], image[live])


def test_a_finite_frame_is_returned_as_it_is() -> None:
    # The fast path: no copy, no fill, so frames without dead pixels read exactly as before.
    clean = _clean_frame()
    assert check_ir_frame(clean, RIG.ir.intrinsics) is clean


def test_a_dead_block_of_four_pixels_is_filled_and_of_five_refused() -> None:
    side = 2 * DEAD_FILL_PASSES
    image = _clean_frame()
    image[60 : 60 + side, 30 : 30 + side] = np.nan
    assert np.all(np.isfinite(check_ir_frame(image, RIG.ir.intrinsics)))
    image[60 : 61 + side, 30 : 31 + side] = np.nan
    with pytest.raises(FrameError, match=f"non-finite temperatures more than {DEAD_FILL_PASSES} "
                                         f"pixels from any finite one"):
        ThermalPerception(RIG).extract(Frame(0.0, 0, image), motor_mm(0.075))


def test_more_dead_pixels_than_a_working_sensor_has_are_refused() -> None:
    image = _clean_frame()
    limit = int(MAX_DEAD_FRACTION * image.size)
    flat = image.reshape(-1)
    spread = np.linspace(0, image.size - 1, limit + 1).astype(int)  # scattered, no clusters
    flat[spread[:-1]] = np.nan
    assert np.all(np.isfinite(check_ir_frame(image, RIG.ir.intrinsics)))
    flat[spread[-1]] = np.nan
    with pytest.raises(FrameError, match=f"{limit + 1} non-finite temperatures, more than the "
                                         f"{limit} dead pixels"):
        ThermalPerception(RIG).extract(Frame(0.0, 0, image), motor_mm(0.075))
