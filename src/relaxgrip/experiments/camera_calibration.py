"""Camera calibration on the twin: board views drawn with known intrinsics, calibrated, scored.

The twin renders the ChArUco board (:class:`relaxgrip.twin.render_board.BoardRenderer`)
through a camera whose focal lengths, principal point and distortion are
known (:data:`TRUTH`: the rig's 640x480 RGB camera with a moderate barrel
lens, off-centre principal point and slightly non-square pixels), in views
spread over the image and tilted up to 50 degrees
(:func:`relaxgrip.twin.render_board.board_poses`), with the twin's pixel noise
and an optical blur.  :func:`calibrate_on_twin` runs the same detection and
calibration as ``relaxgrip calibrate-camera`` on them and compares the result
with the truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from relaxgrip.board import CharucoBoard
from relaxgrip.perception.camera_calibration import (
    CalibrationLimits,
    CameraCalibration,
    calibrate_camera,
    detect_board,
    make_board_detector,
)
from relaxgrip.rig import CameraIntrinsics
from relaxgrip.twin import TWIN_VERSION
from relaxgrip.twin.render_board import BoardRenderer, board_poses
from relaxgrip.twin.sensors import RgbSensorConfig

__all__ = ["BLUR_SIGMA_PX", "N_VIEWS", "TRUTH", "TwinCalibration", "calibrate_on_twin"]

#: The camera the views are drawn through: k1, k2, p1, p2, k3 of a moderate barrel lens.
TRUTH = CameraIntrinsics(640, 480, 612.0, 608.0, 324.5, 236.0,
                         (-0.21, 0.08, 0.0008, -0.0006, -0.02))
#: Views drawn per calibration (a few miss the board where it is far and tilted).
N_VIEWS = 20
#: The optics' blur (pixels, Gaussian sigma): a focused webcam's.
BLUR_SIGMA_PX = 1.0


@dataclass(frozen=True)
class TwinCalibration:
    """One calibration on twin-rendered views, against the truth.

    Attributes
    ----------
    seed : int
        Seed of the views' poses, background and noise.
    calibration : CameraCalibration
        What the calibration found.
    truth : CameraIntrinsics
        The camera that drew the views.
    views_drawn : int
        Views rendered (``len(calibration.views)`` had the board found).
    """

    seed: int
    calibration: CameraCalibration
    truth: CameraIntrinsics
    views_drawn: int

    @property
    def relative_errors(self) -> dict[str, float]:
        """``|estimate / truth - 1|`` of fx, fy, cx, cy."""
        got, true = self.calibration.intrinsics, self.truth
        return {name: abs(getattr(got, f"{name}_px") / getattr(true, f"{name}_px") - 1.0)
                for name in ("fx", "fy", "cx", "cy")}

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form."""
        return {"seed": self.seed, "twin_version": TWIN_VERSION,
                "views_drawn": self.views_drawn, "views_used": len(self.calibration.views),
                "relative_errors": self.relative_errors, "rms_px": self.calibration.rms_px,
                "calibration": self.calibration.to_dict()}


def calibrate_on_twin(seed: int, *, board: CharucoBoard | None = None,
                      truth: CameraIntrinsics = TRUTH, n_views: int = N_VIEWS,
                      sensor: RgbSensorConfig | None = None,
                      model: str = "k1k2p1p2k3") -> TwinCalibration:
    """Render ``n_views`` views of the board and calibrate from them.

    Parameters
    ----------
    seed : int
        Seed of the poses, the background and the noise.
    board : CharucoBoard, optional
        The board (the default sheet's otherwise).
    truth : CameraIntrinsics
        The camera the views are drawn through.
    n_views : int
        Views drawn.
    sensor : RgbSensorConfig, optional
        Noise and blur (the twin's noise with :data:`BLUR_SIGMA_PX` otherwise).
    model : str
        Distortion model fitted.

    Returns
    -------
    TwinCalibration

    Raises
    ------
    relaxgrip.perception.camera_calibration.PoorCalibrationError
        If the views do not constrain the camera.
    """
    b = board if board is not None else CharucoBoard()
    cfg = sensor if sensor is not None else RgbSensorConfig(blur_sigma_px=BLUR_SIGMA_PX)
    rng = np.random.default_rng(seed)
    renderer = BoardRenderer(b, truth, cfg)
    detector = make_board_detector(b)
    views = []
    for k, pose in enumerate(board_poses(b, truth, n_views, rng)):
        gray = np.asarray(cv2.cvtColor(renderer.render(pose, rng), cv2.COLOR_RGB2GRAY),
                          dtype=np.uint8)
        view = detect_board(gray, b, f"view {k}", detector=detector)
        if view is not None:
            views.append(view)
    limits = CalibrationLimits(min_views=min(12, n_views))
    result = calibrate_camera(views, (truth.width_px, truth.height_px), b, model=model,
                              limits=limits)
    return TwinCalibration(seed, result, truth, n_views)
