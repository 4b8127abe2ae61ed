"""Camera calibration: known intrinsics recovered from twin views; poor views refused by name."""

from __future__ import annotations

import math

import numpy as np
import pytest

from relaxgrip.board import CharucoBoard
from relaxgrip.errors import InputError
from relaxgrip.experiments.camera_calibration import TRUTH, calibrate_on_twin
from relaxgrip.perception.camera_calibration import (
    BoardView,
    CalibrationLimits,
    PoorCalibrationError,
    board_tilt,
    calibrate_camera,
)
from relaxgrip.rig import rotation_x, transform_from
from relaxgrip.twin.render_board import BoardRenderer, board_poses

BOARD = CharucoBoard()
SIZE = (TRUTH.width_px, TRUTH.height_px)
#: The issue's goal: fx, fy, cx, cy within 0.5 %, RMS reprojection at most 0.3 px.
MAX_RELATIVE_ERROR = 0.005
MAX_RMS_PX = 0.3
#: Seeds of the reported figures; the settings (views, blur, model) were chosen on 0-4.
FIGURE_SEEDS = (5000, 5001, 5002, 5003, 5004)


def _check_figure(seed: int) -> dict[str, float]:
    run = calibrate_on_twin(seed)
    errors = run.relative_errors
    assert max(errors.values()) <= MAX_RELATIVE_ERROR, (seed, errors)
    assert run.calibration.rms_px <= MAX_RMS_PX, (seed, run.calibration.rms_px)
    assert not run.calibration.problems
    return {**errors, "rms_px": run.calibration.rms_px}


def test_calibration_recovers_the_twin_camera() -> None:
    _check_figure(FIGURE_SEEDS[0])


@pytest.mark.slow
def test_calibration_recovers_the_twin_camera_over_five_seeds() -> None:
    rows = [(seed, _check_figure(seed)) for seed in FIGURE_SEEDS]
    for seed, row in rows:  # the report's figures: pytest -m slow -s
        print(f"seed {seed}: " + ", ".join(
            f"{k} {100 * v:.3f} %" if k != "rms_px" else f"RMS {v:.3f} px"
            for k, v in row.items()))


def _views(poses: list[np.ndarray], noise_px: float = 0.05, seed: int = 0) -> list[BoardView]:
    """The board's corners where the true camera puts them, with noise (no rendering)."""
    rng = np.random.default_rng(seed)
    renderer = BoardRenderer(BOARD, TRUTH)
    views = []
    for k, pose in enumerate(poses):
        px = renderer.corners_px(pose)
        inside = ((px[:, 0] > 2) & (px[:, 0] < SIZE[0] - 3)
                  & (px[:, 1] > 2) & (px[:, 1] < SIZE[1] - 3))
        ids = np.flatnonzero(inside)
        views.append(BoardView(f"v{k}", px[ids] + rng.normal(0.0, noise_px, (ids.size, 2)), ids))
    return views


def _spread_poses(n: int, tilt_deg: tuple[float, float] = (10.0, 50.0),
                  flat_share: float = 0.15) -> list[np.ndarray]:
    return board_poses(BOARD, TRUTH, n, np.random.default_rng(3), tilt_deg=tilt_deg,
                       flat_share=flat_share)


def test_synthetic_corners_calibrate_exactly() -> None:
    result = calibrate_camera(_views(_spread_poses(20)), SIZE, BOARD)
    got = result.intrinsics
    # The principal point is the least constrained: 0.2-0.5 px apart with 0.05 px corners.
    for name, rel in (("fx", 1e-3), ("fy", 1e-3), ("cx", 3e-3), ("cy", 3e-3)):
        assert getattr(got, f"{name}_px") == pytest.approx(getattr(TRUTH, f"{name}_px"),
                                                           rel=rel)
    assert result.rms_px == pytest.approx(0.05 * math.sqrt(2), rel=0.25)
    assert len(result.views) == 20
    assert result.coverage > 0.6
    d = result.to_dict()
    assert d["fx_px"] == got.fx_px
    assert len(d["dist"]) == 5
    assert len(d["views"]) == 20


def test_outlier_corners_are_dropped() -> None:
    views = _views(_spread_poses(16))
    bad = views[4]
    moved = bad.corners_px.copy()
    moved[:3] += 2.5  # three corners the detector put 3.5 px off
    views[4] = BoardView(bad.name, moved, bad.ids)
    result = calibrate_camera(views, SIZE, BOARD)
    assert result.views[4].n_dropped == 3
    assert result.n_dropped == 3
    assert result.rms_px < 0.1
    assert result.intrinsics.fx_px == pytest.approx(TRUTH.fx_px, rel=1e-3)


def test_too_few_views_are_refused() -> None:
    with pytest.raises(PoorCalibrationError, match="too few views: 5 with the board, at least 12"):
        calibrate_camera(_views(_spread_poses(5)), SIZE, BOARD)


def test_face_on_views_are_refused_for_too_little_tilt() -> None:
    flat = _spread_poses(16, tilt_deg=(0.0, 8.0), flat_share=1.0)
    with pytest.raises(PoorCalibrationError, match=r"too little tilt: 0 of 16 views tilted 20°"):
        calibrate_camera(_views(flat), SIZE, BOARD)


def test_views_tilted_about_one_axis_are_refused() -> None:
    poses = []
    for k, pose in enumerate(_spread_poses(16, tilt_deg=(0.0, 3.0), flat_share=1.0)):
        turned = pose.copy()  # tip it forward and back about the board's x only
        turned[:3, :3] = rotation_x(math.radians(30.0 if k % 2 else -30.0)) @ pose[:3, :3]
        poses.append(turned)
    result = calibrate_camera(_views(poses), SIZE, BOARD, check=False)
    assert any("about one axis only" in p for p in result.problems), result.problems
    with pytest.raises(PoorCalibrationError, match="about one axis only"):
        calibrate_camera(_views(poses), SIZE, BOARD)


def test_views_in_the_middle_only_are_refused_for_coverage() -> None:
    poses = [transform_from(p[:3, :3], [-0.045, -0.035, 0.0] @ p[:3, :3].T + [0.0, 0.0, 0.3])
             for p in _spread_poses(16)]  # every view small in the image's middle
    with pytest.raises(PoorCalibrationError, match=r"too little image coverage: the board "
                       r"reached \d+ % of the image, at least 60 % needed \(the top left, top "
                       r"right, bottom left, bottom right corners"):
        calibrate_camera(_views(poses), SIZE, BOARD)


def test_a_large_error_is_refused_and_every_failed_check_is_named() -> None:
    with pytest.raises(PoorCalibrationError, match=r"RMS reprojection error [\d.]+ px \(at most "
                       r"1 px; worst view"):
        calibrate_camera(_views(_spread_poses(16), noise_px=1.5), SIZE, BOARD)
    flat = _spread_poses(16, tilt_deg=(0.0, 8.0), flat_share=1.0)
    result = calibrate_camera(_views(flat, noise_px=1.5), SIZE, BOARD, check=False)
    assert len(result.problems) >= 2
    assert "too little tilt" in result.problems[0]


def test_limits_and_models_are_checked() -> None:
    with pytest.raises(InputError, match="unknown distortion model"):
        calibrate_camera(_views(_spread_poses(12)), SIZE, BOARD, model="k1")
    with pytest.raises(InputError, match="at least 3 views"):
        CalibrationLimits(min_views=2)
    rational = calibrate_camera(_views(_spread_poses(16)), SIZE, BOARD, model="rational",
                                check=False)
    assert len(rational.intrinsics.dist) == 8


def test_board_tilt() -> None:
    assert board_tilt(np.zeros(3))[0] == 0.0
    tilt, direction = board_tilt(np.array([math.radians(30.0), 0.0, 0.0]))
    assert tilt == pytest.approx(30.0)
    assert abs(direction) == pytest.approx(90.0)  # leaning up or down the image
