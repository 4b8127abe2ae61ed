"""The twin's RGB camera: frames depend only on their inputs."""

import numpy as np
import pytest

from relaxgrip.rig import RigGeometry
from relaxgrip.twin import render_rgb
from relaxgrip.twin.raster import area_coverage
from relaxgrip.twin.render_rgb import _TAB_TINT, RgbObject, RgbRenderer, _composite
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


def test_the_tab_is_composited_as_the_float32_formula_says():
    """Table lookups stand in for the products: the pixels are the plain formula's."""
    rng = np.random.default_rng(0)
    tint = np.array(_TAB_TINT, dtype=np.float32)
    for _ in range(20):
        scene = rng.integers(0, 256, (31, 17, 3), dtype=np.uint8)
        tab = rng.integers(0, 256, (31, 17), dtype=np.uint8)
        coverage = rng.choice(np.array([0, 1, 128, 254, 255], np.uint8), (31, 17))
        transmit = 1.0 - coverage.astype(np.float32) * np.float32(1.0 / 255.0)
        expected = scene * transmit[..., None] + tab.astype(np.float32)[..., None] * tint
        roi = scene.copy()
        _composite(roi, tab, coverage)
        np.testing.assert_array_equal(roi, np.clip(expected, 0.0, 255.0).astype(np.uint8))


def test_the_tab_grey_levels_round_as_opencv_does() -> None:
    """addWeighted in float64, then convertScaleAbs in float32 with halves to even; and
    the fused compositing is the compositing of those levels."""
    import cv2

    rng = np.random.default_rng(4)
    for trial in range(300):
        h, w = (int(v) for v in rng.integers(3, 40, 2))
        outline = rng.random((h, w))
        outline[rng.random((h, w)) < 0.3] = 1.0
        black = np.minimum(outline, rng.random((h, w)))
        if trial % 3 == 0:  # values whose grey lands on or next to a half
            outline, black = np.round(outline * 510) / 510, np.round(black * 408) / 408
        if trial % 5 == 0:  # a tab seen from behind: every area negative
            outline, black = -outline, -black
        areas = np.stack([outline, black])
        tab, coverage = np.empty((h, w), np.uint8), np.empty((h, w), np.uint8)
        render_rgb._grey_levels(areas, tab, coverage)
        grey = cv2.addWeighted(outline, float(render_rgb._TAB_WHITE), black,
                               float(render_rgb._INK - render_rgb._TAB_WHITE), 0.0)
        np.testing.assert_array_equal(tab, cv2.convertScaleAbs(grey))
        np.testing.assert_array_equal(coverage, cv2.convertScaleAbs(outline, alpha=255.0))
        scene = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        fused, apart = scene.copy(), scene.copy()
        render_rgb._composite_areas(fused, areas)
        _composite(apart, tab, coverage)
        np.testing.assert_array_equal(fused, apart)


def test_the_noise_saturates_as_opencv_adds_and_subtracts() -> None:
    """One pass of 8-bit arithmetic on signed noise: OpenCV's add of its positive part,
    then subtract of its negative part, each clipped."""
    import cv2

    rng = np.random.default_rng(1)
    image = rng.choice(np.array([0, 1, 2, 127, 128, 253, 254, 255], np.uint8), (23, 40, 3))
    signed = rng.integers(-127, 128, (30, 50, 3), dtype=np.int16)
    signed[0, :8, 0] = [-127, -1, 0, 1, 127, -128 + 1, 2, -2]
    bank = signed.astype(np.int8).view(np.uint8)
    noise = bank[3:26, 5:45]  # a view into a bank
    positive = np.clip(signed, 0, 255).astype(np.uint8)[3:26, 5:45]
    negative = np.clip(-signed, 0, 255).astype(np.uint8)[3:26, 5:45]
    out = np.empty_like(image)
    render_rgb._add_noise(image, noise, out)
    np.testing.assert_array_equal(out, cv2.subtract(cv2.add(image, positive), negative))
    np.testing.assert_array_equal(
        out, np.clip(image.astype(np.int16) + signed[3:26, 5:45], 0, 255).astype(np.uint8))
    render_rgb._add_noise(image, noise, image)  # in place
    np.testing.assert_array_equal(image, out)
    with pytest.raises(ValueError, match="contiguous"):
        render_rgb._add_noise(image[:, ::2], noise[:, ::2], out[:, ::2])


def test_the_noise_bank_is_the_rounded_gaussian_clipped_to_signed_bytes() -> None:
    bank = render_rgb._noise_bank((40, 60), 2.0)
    values = bank.view(np.int8).astype(np.float64)
    assert bank.dtype == np.uint8
    assert not bank.flags.writeable
    assert values.shape == (render_rgb._NOISE_BANKS, 40 + render_rgb._NOISE_PAD,
                            60 + render_rgb._NOISE_PAD, 3)
    assert abs(values.mean()) < 0.02
    assert 1.95 < values.std() < 2.1
    wide = render_rgb._noise_bank((8, 8), 80.0).view(np.int8)
    assert wide.min() == -127
    assert wide.max() == 127


def test_a_frame_is_the_same_in_any_order_across_blocks_of_draws():
    """Each frame's draws come from its own seeded generator, made a block at a time."""
    pose = RIG.marker2cam(0.001, 0.0)
    config = RgbSensorConfig(lighting_flicker=0.05)
    used = RgbRenderer(RIG, config, 3)
    for seq in (63, 64, 0, 200, 64, 1000, 63):
        assert np.array_equal(used.render(seq, pose), RgbRenderer(RIG, config, 3).render(seq, pose))
    assert not np.array_equal(used.render(64, pose), used.render(65, pose))


@pytest.mark.parametrize("config", [RgbSensorConfig(), RgbSensorConfig(occlusion=0.3),
                                    RgbSensorConfig(noise_dn=6.0)])
def test_noise_added_apart_to_the_scene_and_the_tab_draws_the_same_pixels(
        config: RgbSensorConfig, monkeypatch: pytest.MonkeyPatch) -> None:
    """The frame as one pass fewer makes it is the frame drawn in order: scene, tab, noise."""
    ball = (RgbObject((0.0, 0.01, 0.12), 0.03, (200, 100, 50)),)
    poses = [RIG.marker2cam(d, s) for d, s in ((0.0, 0.0), (0.004, 0.05), (-0.002, -0.03))]
    fused = RgbRenderer(RIG, config, 2)
    frames = [fused.render(k, pose, objects) for k, pose in enumerate(poses)
              for objects in ((), ball, ball)]
    monkeypatch.setattr(render_rgb, "_FUSED", False)
    ordered = RgbRenderer(RIG, config, 2)
    for frame, expected in zip(frames, [ordered.render(k, pose, objects)
                                        for k, pose in enumerate(poses)
                                        for objects in ((), ball, ball)], strict=True):
        np.testing.assert_array_equal(frame, expected)


def _position_error_um(renderer: RgbRenderer) -> np.ndarray:
    """The marker's position read from noise-free frames of a 3 mm bend, less its mean (um)."""
    return _bend_errors(renderer)[0]


def test_the_texture_follows_the_supersampling_so_edges_do_not_alias(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """At 2x the marker is read along a bend to a few micrometres; v5's texture of 48 px a
    module, twice as fine as that sampling grid, aliased."""
    modules = RIG.marker.aruco_dictionary.markerSize + 2 + 2 * render_rgb._QUIET_MODULES
    default = RgbRenderer(RIG, RgbSensorConfig(drawing="supersampled", noise_dn=0.0), 0)
    assert default._texture.shape == (48 * modules, 48 * modules)  # v5's frames as before
    coarse = RgbSensorConfig(drawing="supersampled", noise_dn=0.0, supersample=2)
    sampled = RgbRenderer(RIG, coarse, 0)
    assert sampled._texture.shape == (24 * modules, 24 * modules)
    assert (_position_error_um(default).std(axis=0) < 1.5).all()  # measured 0.61, 0.01, 1.05 um
    assert (_position_error_um(sampled).std(axis=0) < 3.0).all()  # measured 1.09, 0.01, 2.44 um
    monkeypatch.setattr(render_rgb, "_TEXELS_PER_MODULE_PER_SUPERSAMPLE", 24)
    aliased = RgbRenderer(RIG, coarse, 0)
    assert aliased._texture.shape == (48 * modules, 48 * modules)
    sd_aliased = _position_error_um(aliased).std(axis=0)
    assert sd_aliased[0] > 5.0  # measured 7.2 um
    assert sd_aliased[2] > 5.0  # measured 7.3 um


def _bend_errors(renderer: RgbRenderer) -> tuple[np.ndarray, np.ndarray]:
    """The marker's position (um) and rotation (mdeg, about the camera's x, y, z axes)
    read from noise-free frames of a 3 mm bend, each less its mean."""
    import cv2

    from relaxgrip.perception.marker import PoseSolver, locate_marker, make_detector

    detector = make_detector(RIG.marker.aruco_dictionary)
    solver = PoseSolver(RIG.marker.size_m, RIG.rgb.intrinsics)
    position, rotation = [], []
    for deflection_m in np.linspace(0.0, 0.003, 121):
        pose = RIG.marker2cam(deflection_m, 0.3 * deflection_m)
        found = locate_marker(renderer.render(0, pose), detector, solver)
        assert found is not None
        position.append(1e6 * (found.tvec_m - pose[:3, 3]))
        rvec, _ = cv2.Rodrigues(found.rotation @ pose[:3, :3].T)
        rotation.append(np.degrees(rvec.ravel()) * 1e3)
    return (np.array(position) - np.mean(position, axis=0),
            np.array(rotation) - np.mean(rotation, axis=0))


def test_the_exact_drawing_reads_the_bend_better_than_four_times_supersampling():
    """Each pixel the exact area of the tab it covers: the rotation about the camera's y
    axis, which follows the sub-pixel phase of the marker's edges, reads closer than at
    the 4x supersampling."""
    exact = _bend_errors(RgbRenderer(RIG, RgbSensorConfig(drawing="exact", noise_dn=0.0), 0))
    supersampled = _bend_errors(
        RgbRenderer(RIG, RgbSensorConfig(drawing="supersampled", noise_dn=0.0), 0))
    assert exact[1][:, 1].std() < 6.0  # mdeg; measured 4.6 (4x: 8.5-8.8, 8x: 5.8)
    assert exact[1][:, 1].std() < 0.8 * supersampled[1][:, 1].std()
    assert (exact[0].std(axis=0) < 1.0).all()  # um


def _enclosed(start: np.ndarray, stop: np.ndarray) -> float:
    """Area enclosed by closed outlines given as directed edges (N, 2) each, clockwise
    on the screen positive (the shoelace formula, edge by edge)."""
    return 0.5 * float(np.sum(start[:, 0] * stop[:, 1] - stop[:, 0] * start[:, 1]))


@pytest.mark.parametrize(("deflection_m", "slope"), [(0.0, 0.0), (0.004, 0.05), (-0.002, -0.2)])
def test_the_exact_tab_holds_the_area_of_its_white_and_black(deflection_m: float,
                                                              slope: float) -> None:
    renderer = RgbRenderer(RIG, RgbSensorConfig(drawing="exact", noise_dn=0.0), 0)
    pose = RIG.marker2cam(deflection_m, slope)
    box = renderer._tab_box(pose)
    assert box is not None
    tab, coverage = renderer._exact_tab(box)
    import cv2

    shape = renderer._shape
    px = cv2.perspectiveTransform(shape.vertices, box.plane_to_img)[:, 0]
    start, stop = px[shape.ends[0]], px[shape.ends[1]]
    outline, black = (_enclosed(start[shape.planes == k], stop[shape.planes == k]) for k in (0, 1))
    assert outline > 0
    assert black > 0
    white, ink = render_rgb._TAB_WHITE, render_rgb._INK
    # Drawn as 8-bit levels: each pixel within half a level.
    assert coverage.sum() / 255.0 == pytest.approx(outline, rel=2e-4)
    assert tab.sum(dtype=np.int64) == pytest.approx(white * outline - (white - ink) * black,
                                                    rel=2e-4)
    # The ArUco marker's black is its border ring and some of its inner bits.
    modules = RIG.marker.aruco_dictionary.markerSize + 2
    ring = (modules**2 - (modules - 2) ** 2) / (modules + 2) ** 2
    assert ring * outline < black < (modules / (modules + 2)) ** 2 * outline


def test_the_black_is_drawn_as_its_boundary_the_same_area_as_its_modules() -> None:
    """The tab's black is the boundary of the black modules' union, every straight run
    of it one edge: it encloses each black module of the marker once."""
    import cv2

    renderer = RgbRenderer(RIG, RgbSensorConfig(), 0)
    shape = renderer._shape
    modules = RIG.marker.aruco_dictionary.markerSize + 2
    bits = cv2.aruco.generateImageMarker(RIG.marker.aruco_dictionary, RIG.marker.marker_id,
                                         modules, borderBits=1) < 128
    # On a grid of modules (x right, y down, the black square from 0 to `modules`), the
    # union's boundary covers each module by its exact area: 1 black, 0 white.
    module_m = RIG.marker.size_m / modules
    grid = shape.vertices[:, 0] * (1.0, -1.0) / module_m + 0.5 * modules - 0.5
    black = shape.planes == 1
    edges = np.stack([grid[shape.ends[0][black]], grid[shape.ends[1][black]]])
    covered = area_coverage(edges, 1.0, (modules, modules))[0]
    np.testing.assert_allclose(covered, bits, atol=1e-12)
    # Straight runs merged: no two edges of the black continue one another.
    along = edges[1] - edges[0]
    for i, j in zip(*np.nonzero(np.all(edges[1][:, None] == edges[0][None], axis=2)), strict=True):
        assert abs(along[i, 0] * along[j, 1] - along[i, 1] * along[j, 0]) > 0


def test_a_tab_half_out_of_the_frame_is_the_crop_of_a_larger_frame():
    import dataclasses

    intrinsics = RIG.rgb.intrinsics
    wide = dataclasses.replace(intrinsics, width_px=intrinsics.width_px + 300,
                               cx_px=intrinsics.cx_px + 300)
    wide_rig = dataclasses.replace(RIG, rgb=dataclasses.replace(RIG.rgb, intrinsics=wide))
    config = RgbSensorConfig(drawing="exact", noise_dn=0.0)
    narrow, larger = RgbRenderer(RIG, config, 0), RgbRenderer(wide_rig, config, 0)
    pose = RIG.marker2cam(0.0, 0.0)
    corners = narrow.marker_corners_px(pose)
    # Shift the marker left in the camera frame until its tab straddles the left edge.
    pose = pose.copy()
    pose[0, 3] -= (corners[:, 0].mean() + 5.0) * pose[2, 3] / intrinsics.fx_px
    xs = narrow.marker_corners_px(pose)[:, 0]
    assert xs.min() < 0 < xs.max()
    box, wide_box = narrow._tab_box(pose), larger._tab_box(pose)
    assert box is not None
    assert wide_box is not None
    tab, coverage = narrow._exact_tab(box)
    wide_tab, wide_coverage = larger._exact_tab(wide_box)
    # The larger frame's pixel (r, c + 300) is the frame's (r, c).
    rows = slice(box.y0 - wide_box.y0, box.y1 - wide_box.y0)
    cols = slice(box.x0 + 300 - wide_box.x0, box.x1 + 300 - wide_box.x0)
    assert box.x0 == 0
    assert coverage.any()
    np.testing.assert_allclose(tab, wide_tab[rows, cols], atol=1)
    np.testing.assert_allclose(coverage, wide_coverage[rows, cols], atol=1)


@pytest.mark.parametrize("config", [RgbSensorConfig(), RgbSensorConfig(drawing="supersampled"),
                                    RgbSensorConfig(blur_sigma_px=0.8),
                                    RgbSensorConfig(lighting_flicker=0.05),
                                    RgbSensorConfig(noise_dn=0.0)])
def test_a_region_drawn_alone_is_the_crop_of_the_whole_frame(config: RgbSensorConfig) -> None:
    """What a tracker reads of a frame drawn on demand is what the whole frame holds there."""
    renderer = RgbRenderer(RIG, config, 3)
    ball = (RgbObject((0.0, 0.01, 0.12), 0.03, (200, 100, 50)),)
    h, w = RIG.rgb.intrinsics.shape
    for seq, (deflection, slope) in enumerate([(0.0, 0.0), (0.004, 0.03), (-0.002, -0.01)]):
        pose = RIG.marker2cam(deflection, slope)
        whole = renderer.render(seq, pose, ball)
        corners = renderer.marker_corners_px(pose)
        (cx, cy), half = corners.mean(axis=0).astype(int), 40
        regions = [(cy - half, cy + half, cx - half, cx + half),  # the marker
                   (cy - 5, cy + 5, cx - 200, cx),  # across the tab's box
                   (0, 17, 0, 23), (h - 9, h + 20, w - 30, w), (-5, 12, -3, 40),  # at the edges
                   (10, 10, 5, 50), (0, h, 0, w)]
        for y0, y1, x0, x1 in regions:
            drawing = renderer.prepare(seq, pose, ball)
            part = drawing.region(y0, y1, x0, x1)
            crop = whole[max(y0, 0):max(min(y1, h), 0), max(x0, 0):max(min(x1, w), 0)]
            assert part.dtype == np.uint8
            assert np.array_equal(part, crop), (config, seq, (y0, y1, x0, x1))
            # Twice from one drawing (the tab painted once), then the whole frame after it.
            assert np.array_equal(drawing.region(y0, y1, x0, x1), crop)
            assert np.array_equal(drawing.image(), whole)


def test_a_twin_frame_drawn_on_demand_copies_and_pickles_as_a_plain_frame() -> None:
    import copy
    import pickle

    from relaxgrip.backend import Frame
    from relaxgrip.twin import GripperTwin

    obs = GripperTwin(seed=2).observe()
    frame = obs.rgb
    assert frame is not None
    layout = frame.layout()
    assert isinstance(layout, np.ndarray)
    assert layout.shape == (*RIG.rgb.intrinsics.shape, 3)
    assert layout.dtype == np.uint8
    part = frame.region(100, 140, 200, 260)
    for other in (copy.deepcopy(frame), pickle.loads(pickle.dumps(frame))):
        assert type(other) is Frame
        assert (other.t_s, other.seq) == (frame.t_s, frame.seq)
        assert np.array_equal(other.image, frame.image)
        assert np.array_equal(other.region(100, 140, 200, 260), part)
