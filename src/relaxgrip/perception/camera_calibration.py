"""Camera calibration from views of a ChArUco board: intrinsics, distortion, and their checks.

:func:`detect_board` finds the board's chessboard corners in one image with
OpenCV's :class:`cv2.aruco.CharucoDetector` (the markers identify every
corner, so a board partly out of view or partly hidden by the finger's
marker tab still counts).  :func:`calibrate_camera` fits the pinhole camera
and its distortion to every view's corners with :func:`cv2.calibrateCamera`
(Zhang's method and Levenberg-Marquardt), drops corners far off the fit
(a corner the detector put a pixel off, as it does on a strongly tilted
board's far side) and fits again, then judges whether the views constrain
the result:

* **views**: at least :attr:`CalibrationLimits.min_views` with the board;
* **coverage**: the board's corners must reach most of the image, its
  corners included, where distortion is strongest and is otherwise
  extrapolated;
* **tilt**: face-on views leave the focal length and the board's distance
  interchangeable; views tilted by 20 degrees or more, about two different
  axes, separate them;
* **uncertainty**: the fit's own standard deviations of the focal lengths
  and principal point (``cv2.calibrateCameraExtended``);
* **RMS**: the reprojection error of the kept corners; a large one means a
  wrong board description, a board that is not flat, or motion blur.

A calibration failing any of them raises :class:`PoorCalibrationError`,
naming each failed check and what to do about it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from relaxgrip.board import CharucoBoard
from relaxgrip.errors import InputError
from relaxgrip.rig import CameraIntrinsics

FloatArray = NDArray[np.float64]
GrayImage = NDArray[np.uint8]

__all__ = [
    "DIST_MODELS",
    "BoardView",
    "CalibrationLimits",
    "CameraCalibration",
    "PoorCalibrationError",
    "ViewFit",
    "board_tilt",
    "calibrate_camera",
    "coverage_mask",
    "detect_board",
    "make_board_detector",
]

#: Distortion models: name -> (number of coefficients, ``cv2.calibrateCamera`` flags).
DIST_MODELS: dict[str, tuple[int, int]] = {
    "k1k2p1p2": (4, cv2.CALIB_FIX_K3),
    "k1k2p1p2k3": (5, 0),
    "rational": (8, cv2.CALIB_RATIONAL_MODEL),
}
#: Coverage is measured on a grid this many times coarser than the image (pixels a cell).
_COVERAGE_CELL_PX = 8
#: The image's corner regions whose coverage is reported: this share of its width and height.
_CORNER_SHARE = 0.2
#: Outlier corners: residuals over this many times the median, and over the floor (px).
_OUTLIER_FACTOR = 4.0
_OUTLIER_FLOOR_PX = 0.25
_OUTLIER_ROUNDS = 3


class PoorCalibrationError(InputError):
    """The views do not constrain the camera well enough; the message names each failed check."""


@dataclass(frozen=True)
class BoardView:
    """The board's corners found in one image.

    Attributes
    ----------
    name : str
        Where the image came from (a file name, ``live 7``).
    corners_px : ndarray, shape (N, 2)
        Chessboard corners (pixels).
    ids : ndarray of int, shape (N,)
        Their ids on the board (row by row from the top left).
    """

    name: str
    corners_px: FloatArray
    ids: NDArray[np.intp]

    @property
    def n_corners(self) -> int:
        """Corners found."""
        return int(self.ids.size)


def make_board_detector(board: CharucoBoard) -> cv2.aruco.CharucoDetector:
    """A ChArUco detector for ``board`` whose corner refinement runs to a thousandth of a pixel.

    OpenCV stops refining a chessboard corner once a step moves it less than
    ``cornerRefinementMinAccuracy`` (0.1 px by default): on the twin's views
    iterating on to 0.001 px takes the corners' error from 0.057 to 0.051 px RMS.
    """
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMinAccuracy = 0.001
    params.cornerRefinementMaxIterations = 100
    return cv2.aruco.CharucoDetector(board.cv_board, cv2.aruco.CharucoParameters(), params)


def detect_board(gray: GrayImage, board: CharucoBoard, name: str = "", *,
                 detector: cv2.aruco.CharucoDetector | None = None,
                 min_corners: int = 8) -> BoardView | None:
    """The board's chessboard corners in a grey image.

    Parameters
    ----------
    gray : ndarray, shape (H, W), uint8
        The image.
    board : CharucoBoard
        The board looked for.
    name : str
        The view's name.
    detector : cv2.aruco.CharucoDetector, optional
        A detector for ``board`` to reuse (:func:`make_board_detector`).
    min_corners : int
        Fewest corners a view needs.

    Returns
    -------
    BoardView or None
        None if fewer than ``min_corners`` corners were found, or they lie on
        fewer than three rows or three columns of the board (too nearly a
        line to give a pose).
    """
    det = detector if detector is not None else make_board_detector(board)
    corners, ids, _, _ = det.detectBoard(np.ascontiguousarray(gray))
    if ids is None or len(ids) < min_corners:
        return None
    ids_flat = np.asarray(ids, dtype=np.intp).ravel()
    per_row = board.squares_x - 1
    if len(set((ids_flat // per_row).tolist())) < 3 or len(set((ids_flat % per_row).tolist())) < 3:
        return None
    return BoardView(name, np.asarray(corners, dtype=np.float64).reshape(-1, 2), ids_flat)


def board_tilt(rvec: FloatArray) -> tuple[float, float]:
    """How far a board is tilted from face-on, and towards which image direction.

    Parameters
    ----------
    rvec : ndarray, shape (3,)
        The board's rotation in the camera frame (Rodrigues).

    Returns
    -------
    (float, float)
        Tilt (degrees, 0 face-on) and the direction in the image its normal
        leans to (degrees from the image's ``x`` towards ``y``).
    """
    normal = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3))[0][:, 2]
    tilt = math.degrees(math.acos(min(1.0, abs(float(normal[2])))))
    direction = math.degrees(math.atan2(float(normal[1]), float(normal[0])))
    return tilt, direction


def coverage_mask(views: Sequence[BoardView], image_size: tuple[int, int]) -> NDArray[np.bool_]:
    """Where the board has been: the union of every view's corner hull, on a coarse grid.

    Parameters
    ----------
    views : sequence of BoardView
        The views.
    image_size : (int, int)
        Width and height of the images (pixels).

    Returns
    -------
    ndarray of bool, shape (ceil(H / 8), ceil(W / 8))
        True where some view's corners enclose the cell.
    """
    w, h = image_size
    cell = _COVERAGE_CELL_PX
    mask = np.zeros((math.ceil(h / cell), math.ceil(w / cell)), np.uint8)
    for view in views:
        hull = cv2.convexHull(np.asarray(view.corners_px / cell, dtype=np.float32))
        cv2.fillConvexPoly(mask, np.round(hull).astype(np.int32), 1)
    covered: NDArray[np.bool_] = mask.astype(bool)
    return covered


@dataclass(frozen=True)
class CalibrationLimits:
    """What a calibration needs to be taken.

    Attributes
    ----------
    min_views : int
        Fewest views with the board.
    min_coverage : float
        Least share of the image the board's corners reach (union of the
        views' corner hulls).
    min_tilt_deg : float
        A view is tilted from this angle from face-on (degrees).
    min_tilted_views : int
        Fewest tilted views.
    min_tilt_axes_deg : float
        The tilted views must lean in directions at least this far apart
        (degrees, modulo 180): two axes of tilt.
    max_focal_std : float
        Largest standard deviation of ``fx`` and ``fy`` taken, relative to them.
    max_centre_std : float
        Largest standard deviation of ``cx`` and ``cy`` taken, relative to
        the image's width and height.
    max_rms_px : float
        Largest RMS reprojection error taken (pixels).
    """

    min_views: int = 12
    min_coverage: float = 0.6
    min_tilt_deg: float = 20.0
    min_tilted_views: int = 4
    min_tilt_axes_deg: float = 45.0
    max_focal_std: float = 0.005
    max_centre_std: float = 0.01
    max_rms_px: float = 1.0

    def __post_init__(self) -> None:
        if self.min_views < 3:
            raise InputError(f"a calibration needs at least 3 views, got {self.min_views}")
        if not 0.0 <= self.min_coverage <= 1.0:
            raise InputError(f"min_coverage must be within 0..1, got {self.min_coverage}")
        if not (0.0 <= self.min_tilt_deg < 90.0 and 0.0 <= self.min_tilt_axes_deg <= 90.0):
            raise InputError("tilt limits must be within 0..90 degrees")
        if not all(v > 0 and math.isfinite(v) for v in (self.max_focal_std, self.max_centre_std,
                                                        self.max_rms_px)):
            raise InputError("uncertainty and RMS limits must be > 0 and finite")


@dataclass(frozen=True)
class ViewFit:
    """One view in the fitted calibration.

    Attributes
    ----------
    name : str
        The view's name.
    n_corners : int
        Corners kept.
    n_dropped : int
        Corners dropped as outliers.
    rms_px : float
        RMS reprojection error of its kept corners (pixels).
    tilt_deg : float
        Tilt of the board from face-on (degrees).
    tilt_direction_deg : float
        Image direction the board's normal leans to (degrees).
    distance_m : float
        Distance of the board's origin from the camera (m).
    """

    name: str
    n_corners: int
    n_dropped: int
    rms_px: float
    tilt_deg: float
    tilt_direction_deg: float
    distance_m: float


@dataclass(frozen=True)
class CameraCalibration:
    """A fitted camera.

    Attributes
    ----------
    intrinsics : CameraIntrinsics
        Focal lengths, principal point and distortion.
    model : str
        The distortion model (a key of :data:`DIST_MODELS`).
    rms_px : float
        RMS reprojection error over the kept corners (pixels).
    std_px : tuple of float
        Standard deviations of ``fx, fy, cx, cy`` from the fit (pixels).
    coverage : float
        Share of the image the board's corners reached.
    views : tuple of ViewFit
        Per view, in the order given.
    board : CharucoBoard
        The board.
    problems : tuple of str
        The checks it fails (empty for a calibration to take).
    """

    intrinsics: CameraIntrinsics
    model: str
    rms_px: float
    std_px: tuple[float, float, float, float]
    coverage: float
    views: tuple[ViewFit, ...]
    board: CharucoBoard
    problems: tuple[str, ...] = field(default=())

    @property
    def n_dropped(self) -> int:
        """Corners dropped as outliers, over every view."""
        return sum(v.n_dropped for v in self.views)

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form (``--json``): lengths in pixels, the rig file's names."""
        intr = self.intrinsics
        return {
            "width_px": intr.width_px, "height_px": intr.height_px,
            "fx_px": intr.fx_px, "fy_px": intr.fy_px, "cx_px": intr.cx_px, "cy_px": intr.cy_px,
            "dist": list(intr.dist), "dist_model": self.model,
            "rms_px": self.rms_px,
            "std_px": dict(zip(("fx", "fy", "cx", "cy"), self.std_px, strict=True)),
            "coverage": self.coverage, "n_views": len(self.views),
            "n_corners": sum(v.n_corners for v in self.views), "n_dropped": self.n_dropped,
            "board": {"squares": [self.board.squares_x, self.board.squares_y],
                      "square_mm": self.board.square_m * 1e3,
                      "marker_mm": self.board.marker_m * 1e3,
                      "dictionary": self.board.dictionary},
            "views": [{"name": v.name, "n_corners": v.n_corners, "n_dropped": v.n_dropped,
                       "rms_px": v.rms_px, "tilt_deg": v.tilt_deg,
                       "tilt_direction_deg": v.tilt_direction_deg,
                       "distance_mm": v.distance_m * 1e3} for v in self.views],
            "problems": list(self.problems),
        }


def calibrate_camera(views: Sequence[BoardView], image_size: tuple[int, int],
                     board: CharucoBoard, *, model: str = "k1k2p1p2k3",
                     limits: CalibrationLimits | None = None,
                     check: bool = True) -> CameraCalibration:
    """Fit the camera to the board's views and check that they constrain it.

    Parameters
    ----------
    views : sequence of BoardView
        The board's corners in each image (all of one size).
    image_size : (int, int)
        Width and height of the images (pixels).
    board : CharucoBoard
        The board the corners are of.
    model : str
        Distortion model, a key of :data:`DIST_MODELS`.
    limits : CalibrationLimits, optional
        What the calibration needs (the defaults otherwise).
    check : bool
        Raise on a poorly constrained calibration; False returns it with
        :attr:`CameraCalibration.problems` filled (fewer than ``min_views``
        views are refused either way).

    Returns
    -------
    CameraCalibration

    Raises
    ------
    PoorCalibrationError
        Too few views; with ``check``, too little coverage or tilt, too
        uncertain, or too large an RMS error: the message names each.
    InputError
        An unknown model; a fit OpenCV cannot make or whose distortion
        describes no lens.
    """
    lim = limits if limits is not None else CalibrationLimits()
    if model not in DIST_MODELS:
        raise InputError(f"unknown distortion model {model!r}; known: {', '.join(DIST_MODELS)}")
    w, h = image_size
    mask = coverage_mask(views, image_size)
    coverage = float(mask.mean()) if mask.size else 0.0
    if len(views) < lim.min_views:
        raise PoorCalibrationError(
            f"poorly constrained calibration: too few views: {len(views)} with the board, at "
            f"least {lim.min_views} needed")
    if coverage < lim.min_coverage and check:
        raise PoorCalibrationError(
            "poorly constrained calibration: " + _coverage_problem(mask, coverage, lim))
    n_coeffs, flags = DIST_MODELS[model]
    keep = [np.ones(v.n_corners, bool) for v in views]
    for _ in range(_OUTLIER_ROUNDS):
        fit = _fit(views, keep, board, image_size, flags)
        residuals = _residuals(views, board, fit)
        norms = np.concatenate(residuals)
        limit = max(_OUTLIER_FACTOR * float(np.median(norms)), _OUTLIER_FLOOR_PX)
        new_keep = [r <= limit for r in residuals]
        # A view keeps at least the corners a pose needs, however far off the fit they are.
        new_keep = [k if k.sum() >= 8 else np.ones_like(k) for k in new_keep]
        if all(np.array_equal(a, b) for a, b in zip(new_keep, keep, strict=True)):
            break
        keep = new_keep
    else:  # the last round's corners, fitted
        fit = _fit(views, keep, board, image_size, flags)
        residuals = _residuals(views, board, fit)
    _, matrix, dist, rvecs, tvecs, std = fit
    kept_norms = np.concatenate([r[k] for r, k in zip(residuals, keep, strict=True)])
    rms_px = float(np.sqrt(np.mean(kept_norms**2)))
    coefficients = tuple(float(d) for d in np.ravel(dist)[:n_coeffs])
    try:
        intrinsics = CameraIntrinsics(w, h, float(matrix[0, 0]), float(matrix[1, 1]),
                                      float(matrix[0, 2]), float(matrix[1, 2]), coefficients)
    except InputError as exc:
        raise PoorCalibrationError(f"poorly constrained calibration: the fit describes no "
                                   f"camera ({exc}): take more views, nearer the image's "
                                   "corners") from None
    fits = []
    for view, r, k, rvec, tvec in zip(views, residuals, keep, rvecs, tvecs, strict=True):
        tilt, direction = board_tilt(np.asarray(rvec))
        fits.append(ViewFit(view.name, int(k.sum()), int((~k).sum()),
                            float(np.sqrt(np.mean(r[k] ** 2))), tilt, direction,
                            float(np.linalg.norm(tvec))))
    std_px = (float(std[0]), float(std[1]), float(std[2]), float(std[3]))
    problems = _problems(fits, std_px, intrinsics, rms_px, mask, coverage, lim)
    result = CameraCalibration(intrinsics, model, rms_px, std_px, coverage, tuple(fits), board,
                               tuple(problems))
    if problems and check:
        raise PoorCalibrationError("poorly constrained calibration: " + "; ".join(problems))
    return result


_Fit = tuple[float, FloatArray, FloatArray, list[FloatArray], list[FloatArray], FloatArray]


def _fit(views: Sequence[BoardView], keep: Sequence[NDArray[np.bool_]], board: CharucoBoard,
         image_size: tuple[int, int], flags: int) -> _Fit:
    """``cv2.calibrateCameraExtended`` on the kept corners of every view."""
    corners_m = board.corners_m.astype(np.float32)
    objects = [corners_m[v.ids[k]].reshape(-1, 1, 3) for v, k in zip(views, keep, strict=True)]
    images = [v.corners_px[k].astype(np.float32).reshape(-1, 1, 2)
              for v, k in zip(views, keep, strict=True)]
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    try:
        rms, matrix, dist, rvecs, tvecs, std, _, _ = cv2.calibrateCameraExtended(
            objects, images, image_size, None, None,  # type: ignore[call-overload]
            flags=flags, criteria=criteria)
    except cv2.error as exc:
        raise InputError(f"OpenCV could not calibrate from these views "
                         f"({' '.join(str(exc).split())[-160:]})") from None
    return (float(rms), np.asarray(matrix, dtype=np.float64), np.asarray(dist, dtype=np.float64),
            [np.asarray(r, dtype=np.float64).ravel() for r in rvecs],
            [np.asarray(t, dtype=np.float64).ravel() for t in tvecs],
            np.asarray(std, dtype=np.float64).ravel())


def _residuals(views: Sequence[BoardView], board: CharucoBoard, fit: _Fit) -> list[FloatArray]:
    """Every corner's reprojection error under the fit (pixels), view by view."""
    _, matrix, dist, rvecs, tvecs, _ = fit
    out = []
    for view, rvec, tvec in zip(views, rvecs, tvecs, strict=True):
        projected, _ = cv2.projectPoints(board.corners_m[view.ids], rvec, tvec, matrix, dist)
        out.append(np.linalg.norm(projected.reshape(-1, 2) - view.corners_px, axis=1))
    return out


def _coverage_problem(mask: NDArray[np.bool_], coverage: float, lim: CalibrationLimits) -> str:
    rows, cols = mask.shape
    ch, cw = max(1, round(_CORNER_SHARE * rows)), max(1, round(_CORNER_SHARE * cols))
    regions = {"top left": mask[:ch, :cw], "top right": mask[:ch, -cw:],
               "bottom left": mask[-ch:, :cw], "bottom right": mask[-ch:, -cw:]}
    empty = [name for name, region in regions.items() if region.mean() < 0.25]
    where = (f" (the {', '.join(empty)} corner{'s' if len(empty) > 1 else ''} of the image "
             "barely seen)") if empty else ""
    return (f"too little image coverage: the board reached {100 * coverage:.0f} % of the image, "
            f"at least {100 * lim.min_coverage:.0f} % needed{where}: hold it in every part of "
            "the view, its corners too")


def _problems(fits: Sequence[ViewFit], std_px: tuple[float, float, float, float],
              intr: CameraIntrinsics, rms_px: float, mask: NDArray[np.bool_], coverage: float,
              lim: CalibrationLimits) -> list[str]:
    """The checks a fitted calibration fails, each as a clause saying what to do."""
    problems = []
    if coverage < lim.min_coverage:
        problems.append(_coverage_problem(mask, coverage, lim))
    tilted = [f for f in fits if f.tilt_deg >= lim.min_tilt_deg]
    directions = [f.tilt_direction_deg % 180.0 for f in tilted]
    spread = max((_axis_gap(a, b) for i, a in enumerate(directions) for b in directions[i + 1:]),
                 default=0.0)
    if len(tilted) < lim.min_tilted_views or spread < lim.min_tilt_axes_deg:
        axes = "about one axis only" if tilted and spread < lim.min_tilt_axes_deg else ""
        problems.append(
            f"too little tilt: {len(tilted)} of {len(fits)} views tilted "
            f"{lim.min_tilt_deg:g}° or more{' ' + axes if axes else ''} (at least "
            f"{lim.min_tilted_views} needed, about two axes {lim.min_tilt_axes_deg:g}° or more "
            "apart): tilt the board 20-45° left, right, up and down")
    focal = max(std_px[0] / intr.fx_px, std_px[1] / intr.fy_px)
    if focal > lim.max_focal_std:
        problems.append(f"focal length uncertain by {100 * focal:.2f} % (at most "
                        f"{100 * lim.max_focal_std:g} %): take more views, tilted and near")
    centre = max(std_px[2] / intr.width_px, std_px[3] / intr.height_px)
    if centre > lim.max_centre_std:
        problems.append(f"principal point uncertain by {100 * centre:.2f} % of the image (at "
                        f"most {100 * lim.max_centre_std:g} %): take more views, tilted and "
                        "in every part of the image")
    if rms_px > lim.max_rms_px:
        worst = max(fits, key=lambda f: f.rms_px)
        problems.append(f"RMS reprojection error {rms_px:.2f} px (at most {lim.max_rms_px:g} "
                        f"px; worst view {worst.name}, {worst.rms_px:.2f} px): check the board's "
                        "squares, sizes and dictionary, that it is flat, and drop blurred views")
    return problems


def _axis_gap(a_deg: float, b_deg: float) -> float:
    """Angle between two axes given as directions modulo 180 degrees (0..90)."""
    d = abs(a_deg - b_deg) % 180.0
    return min(d, 180.0 - d)
