"""The twin's board views: corners where the distorted camera projects them, seeded, in view."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from relaxgrip.board import CharucoBoard
from relaxgrip.errors import InputError
from relaxgrip.perception.camera_calibration import detect_board
from relaxgrip.rig import CameraIntrinsics, transform_from
from relaxgrip.twin.render_board import BoardRenderer, board_poses, monotonic_radius
from relaxgrip.twin.sensors import RgbSensorConfig

CAMERA = CameraIntrinsics(640, 480, 612.0, 608.0, 324.5, 236.0,
                          (-0.21, 0.08, 0.0008, -0.0006, -0.02))


def test_detected_corners_lie_where_the_distorted_camera_projects_them() -> None:
    board = CharucoBoard()
    rng = np.random.default_rng(0)
    renderer = BoardRenderer(board, CAMERA, RgbSensorConfig(blur_sigma_px=1.0))
    errors = []
    for pose in board_poses(board, CAMERA, 6, rng):
        image = renderer.render(pose, rng)
        assert image.shape == (480, 640, 3)
        assert image.dtype == np.uint8
        view = detect_board(np.asarray(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY), np.uint8),
                            board)
        if view is None:  # far and tilted, its markers a few pixels wide
            continue
        truth = renderer.corners_px(pose)[view.ids]
        errors.append(np.linalg.norm(view.corners_px - truth, axis=1))
    assert len(errors) >= 4
    err = np.concatenate(errors)
    # Sub-pixel, and unbiased by the distortion: a pinhole projection is pixels off near
    # the image's edges (the lens bends them by up to 20 px here).
    assert float(np.sqrt(np.mean(err**2))) < 0.1
    assert float(err.max()) < 0.5


def test_straight_edges_are_drawn_bent_by_the_lens() -> None:
    board = CharucoBoard()
    renderer = BoardRenderer(board, CAMERA, RgbSensorConfig(noise_dn=0.0))
    pose = transform_from(np.eye(3), [-0.045, -0.035, 0.09])  # the board filling the view
    corners = renderer.corners_px(pose)
    pinhole = CameraIntrinsics(640, 480, 612.0, 608.0, 324.5, 236.0).project(
        board.corners_m @ pose[:3, :3].T + pose[:3, 3])
    assert float(np.linalg.norm(corners - pinhole, axis=1).max()) > 10.0
    image = renderer.render(pose, np.random.default_rng(1))
    view = detect_board(image[:, :, 0], board)
    assert view is not None
    assert np.allclose(view.corners_px, corners[view.ids], atol=0.3)


def test_views_are_seeded_and_spread_over_the_image() -> None:
    board = CharucoBoard()
    first = board_poses(board, CAMERA, 9, np.random.default_rng(5))
    again = board_poses(board, CAMERA, 9, np.random.default_rng(5))
    assert all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
    renderer = BoardRenderer(board, CAMERA)
    centres = np.array([renderer.corners_px(p).mean(axis=0) for p in first])
    assert np.ptp(centres[:, 0]) > 0.5 * 640
    assert np.ptp(centres[:, 1]) > 0.4 * 480
    for pose in first:
        px = renderer.corners_px(pose)
        inside = (px[:, 0] >= 8) & (px[:, 0] <= 631) & (px[:, 1] >= 8) & (px[:, 1] <= 471)
        assert inside.mean() >= 0.7
        tilt = math.degrees(math.acos(abs(pose[2, 2])))
        assert tilt <= 50.0 + 1e-9
    a = renderer.render(first[0], np.random.default_rng(2))
    assert np.array_equal(a, renderer.render(first[0], np.random.default_rng(2)))


def test_the_lens_model_is_used_only_where_it_is_one_to_one() -> None:
    assert monotonic_radius(()) == 3.0
    # r (1 + k1 r^2) stops growing at r = 1 / sqrt(-3 k1).
    assert monotonic_radius((-0.3, 0.0, 0.0, 0.0)) == pytest.approx(1 / math.sqrt(0.9), abs=2e-3)
    renderer = BoardRenderer(CharucoBoard(), CameraIntrinsics(
        640, 480, 300.0, 300.0, 319.5, 239.5, (-0.3, 0.0, 0.0, 0.0)))
    wide = transform_from(np.eye(3), [-0.3, -0.1, 0.05])  # the board far off axis
    with pytest.raises(InputError, match="beyond where the lens model is one-to-one"):
        renderer.render(wide, np.random.default_rng(0))
    with pytest.raises(InputError, match="behind the camera"):
        renderer.render(transform_from(np.eye(3), [0.0, 0.0, -0.1]), np.random.default_rng(0))
