"""The twin's view of a printed ChArUco board, through a camera with lens distortion.

Camera calibration is tested on these views: the intrinsics and distortion
that drew them are known, so what :mod:`relaxgrip.perception.camera_calibration`
recovers can be checked against them.

The board's black rectangles (:meth:`relaxgrip.board.CharucoBoard.black_rectangles`)
and the white sheet they are printed on are drawn as exact pixel areas
(:func:`relaxgrip.twin.raster.area_coverage`), as the marker tab of
:mod:`relaxgrip.twin.render_rgb` is: a camera pixel integrates the light on
its area.  Lens distortion bends straight edges, so every edge is cut into
pieces shorter than a pixel and a half in the image and each piece's ends are
projected through the distortion model (``cv2.projectPoints``); over so short
a piece the bent edge departs from its chord by a few thousandths of a pixel.
The optics' blur, the lighting gain and the pixel noise are the twin's
(:class:`relaxgrip.twin.sensors.RgbSensorConfig`).

:func:`board_poses` draws the views a careful user takes: the board in every
part of the image, near and far, tilted by up to 50 degrees in every direction.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from relaxgrip.board import CharucoBoard
from relaxgrip.errors import InputError
from relaxgrip.rig import CameraIntrinsics, rotation_z, transform_from
from relaxgrip.twin.raster import area_coverage
from relaxgrip.twin.sensors import RgbSensorConfig

FloatArray = NDArray[np.float64]
Image = NDArray[np.uint8]

__all__ = ["BoardRenderer", "board_poses", "monotonic_radius"]

#: Grey levels of the paper and of the ink (as the twin's marker tab).
_PAPER = 228.0
_INK = 24.0
#: The longest piece an edge is cut into, in the image (pixels).
_PIECE_PX = 1.5
#: Paper around the board's squares (m): the sheet's margin.
_SHEET_MARGIN_M = 0.012


def monotonic_radius(dist: Sequence[float], r_max: float = 3.0) -> float:
    """How far off axis (normalised radius ``r = sqrt(x^2 + y^2)``) the lens model stays
    one-to-one: the first ``r`` where the distorted radius stops growing.

    Beyond it the polynomial folds back, and points far outside the view
    would land inside the image.  Only the radial part counts (k1, k2, k3 and
    the rational model's k4-k6); tangential terms are small beside it.

    Parameters
    ----------
    dist : sequence of float
        OpenCV coefficients ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])``.
    r_max : float
        Largest radius looked at (``r_max`` itself if it never folds before).

    Returns
    -------
    float
    """
    k = [*dist, *([0.0] * 8)][:8]
    if len(dist) > 8:
        raise InputError("the board renderer takes at most 8 distortion coefficients")
    r = np.linspace(0.0, r_max, 3001)
    r2 = r * r
    radial = ((1 + k[0] * r2 + k[1] * r2**2 + k[4] * r2**3)
              / (1 + k[5] * r2 + k[6] * r2**2 + k[7] * r2**3))
    grows = np.diff(r * radial) > 0
    folds = np.flatnonzero(~grows)
    return float(r[folds[0]]) if folds.size else r_max


class BoardRenderer:
    """Renders a printed ChArUco board seen by a camera with lens distortion.

    Parameters
    ----------
    board : CharucoBoard
        The board.
    intrinsics : CameraIntrinsics
        The camera, distortion included (up to 8 coefficients).
    config : RgbSensorConfig
        Noise, blur and lighting gain.
    """

    def __init__(self, board: CharucoBoard, intrinsics: CameraIntrinsics,
                 config: RgbSensorConfig | None = None) -> None:
        self.board = board
        self.intrinsics = intrinsics
        self.config = config if config is not None else RgbSensorConfig()
        self._r_fold = monotonic_radius(intrinsics.dist)
        w, h = board.size_m
        m = _SHEET_MARGIN_M
        sheet = np.array([[-m, -m, w + m, h + m]])
        self._rects = np.concatenate([sheet, board.black_rectangles()])
        self._plane = np.r_[0, np.ones(len(self._rects) - 1, np.intp)]

    @property
    def sheet_corners_m(self) -> FloatArray:
        """The sheet's corners in the board frame, shape (4, 3)."""
        x0, y0, x1, y1 = self._rects[0]
        return np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])

    def project(self, board2cam: FloatArray, points_m: FloatArray) -> FloatArray:
        """Board-frame points ``(N, 3)`` to distorted pixels ``(N, 2)``.

        Raises
        ------
        InputError
            A point behind the camera or beyond where the lens model folds
            back (:func:`monotonic_radius`).
        """
        cam = points_m @ board2cam[:3, :3].T + board2cam[:3, 3]
        if not np.all(cam[:, 2] > 1e-3):
            raise InputError("the board reaches behind the camera")
        r = np.hypot(cam[:, 0], cam[:, 1]) / cam[:, 2]
        if float(r.max()) >= self._r_fold:
            raise InputError(f"the board reaches {math.degrees(math.atan(float(r.max()))):.0f}° "
                             "off axis, beyond where the lens model is one-to-one")
        return self.intrinsics.project(cam)

    def corners_px(self, board2cam: FloatArray) -> FloatArray:
        """The true image positions of the board's inner corners, ``(n_corners, 2)``."""
        return self.project(board2cam, self.board.corners_m)

    def render(self, board2cam: FloatArray, rng: np.random.Generator) -> Image:
        """One view of the board.

        Parameters
        ----------
        board2cam : ndarray, shape (4, 4)
            Pose of the board in the camera frame.
        rng : numpy.random.Generator
            Source of the background's texture and the pixel noise.

        Returns
        -------
        ndarray, shape (H, W, 3), uint8
            The RGB frame (the board is grey, the same in every channel).
        """
        h, w = self.intrinsics.shape
        ends, plane = self._edges(board2cam)
        px = self.project(board2cam, ends.reshape(-1, 3)).reshape(2, -1, 2)
        # Clockwise on the screen counts positive: a board seen from the front keeps the
        # board frame's (x right, y down) turn; seen from behind, every area changes sign.
        corners = self.project(board2cam, self.sheet_corners_m)
        (ax, ay), (bx, by), (cx, cy) = corners[:3].tolist()
        sign = 1.0 if (bx - ax) * (cy - by) - (by - ay) * (cx - bx) >= 0 else -1.0
        areas = area_coverage(px, sign, (h, w), plane=plane, planes=2)
        sheet, black = np.clip(areas[0], 0.0, 1.0), np.clip(areas[1], 0.0, 1.0)
        image = _background((h, w), rng) * (1.0 - sheet) + _PAPER * sheet - (_PAPER - _INK) * black
        cfg = self.config
        image *= cfg.lighting_gain
        if cfg.blur_sigma_px > 0:
            image = np.asarray(cv2.GaussianBlur(image, (0, 0), cfg.blur_sigma_px),
                               dtype=np.float64)
        if cfg.noise_dn > 0:
            image += rng.normal(0.0, cfg.noise_dn, size=image.shape)
        grey = np.clip(np.rint(image), 0, 255).astype(np.uint8)
        out: Image = np.repeat(grey[:, :, None], 3, axis=2)
        return out

    def _edges(self, board2cam: FloatArray) -> tuple[FloatArray, NDArray[np.intp]]:
        """Every rectangle's sides cut into pieces under :data:`_PIECE_PX` in the image:
        their ends ``(2, N, 3)`` in the board frame (clockwise in it) and planes ``(N,)``."""
        x0, y0, x1, y1 = self._rects.T
        # Sides: top (left to right), right (down), bottom (right to left), left (up).
        starts = np.stack([np.c_[x0, y0], np.c_[x1, y0], np.c_[x1, y1], np.c_[x0, y1]], axis=1)
        stops = np.roll(starts, -1, axis=1)
        # The finest scale of the view: pixels per metre where the board is nearest.
        cam = self.sheet_corners_m @ board2cam[:3, :3].T + board2cam[:3, 3]
        focal = max(self.intrinsics.fx_px, self.intrinsics.fy_px)
        px_per_m = 1.25 * focal / float(cam[:, 2].min())
        length = np.linalg.norm(stops - starts, axis=2)  # (R, 4)
        pieces = np.maximum(1, np.ceil(length * px_per_m / _PIECE_PX)).astype(np.intp)
        a, b = starts.reshape(-1, 2), stops.reshape(-1, 2)
        n = pieces.ravel()
        side = np.repeat(np.arange(n.size), n)
        k = np.arange(side.size) - np.repeat(np.cumsum(n) - n, n)
        t0, t1 = k / n[side], (k + 1) / n[side]
        p0 = a[side] + (b[side] - a[side]) * t0[:, None]
        p1 = a[side] + (b[side] - a[side]) * t1[:, None]
        zeros = np.zeros((side.size, 1))
        ends = np.stack([np.hstack([p0, zeros]), np.hstack([p1, zeros])])
        plane = np.repeat(np.repeat(self._plane, 4), n)
        return ends, plane


def _background(shape: tuple[int, int], rng: np.random.Generator) -> FloatArray:
    """A bench behind the sheet: dark grey with smooth blotches."""
    h, w = shape
    coarse = rng.normal(0.0, 1.0, size=(max(2, h // 40), max(2, w // 40)))
    field = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    out: FloatArray = 70.0 + 12.0 * np.asarray(field, dtype=np.float64)
    return out


def _rotation_about(axis: FloatArray, angle_rad: float) -> FloatArray:
    """Rotation matrix about a unit ``axis``."""
    out, _ = cv2.Rodrigues(np.asarray(axis, dtype=np.float64) * angle_rad)
    return np.asarray(out, dtype=np.float64)


def board_poses(board: CharucoBoard, intrinsics: CameraIntrinsics, n: int,
                rng: np.random.Generator, *, tilt_deg: tuple[float, float] = (10.0, 50.0),
                fill: tuple[float, float] = (0.45, 0.8), flat_share: float = 0.15,
                min_in_view: float = 0.7, margin_px: float = 8.0) -> list[FloatArray]:
    """Poses of the board for ``n`` views spread over the image.

    View ``i`` aims the board's centre at a random point of cell ``i mod 9``
    of a 3x3 grid over the image (reaching a twentieth of the image past its
    edges), at a distance where the board spans a random share ``fill`` of
    the image's width, tilted by a random angle in ``tilt_deg`` about a
    random axis in its plane (a share ``flat_share`` of the views within 10
    degrees of face-on), turned in its plane by up to 30 degrees.  As a user
    holding a ChArUco board does, a view may put part of the board outside
    the image, but not more than ``1 - min_in_view`` of its corners.  A pose
    that leaves more out (or puts any of the sheet beyond where the lens
    model is one-to-one) is drawn again; after 50 such draws, nearer the
    centre and smaller.

    Parameters
    ----------
    board : CharucoBoard
        The board.
    intrinsics : CameraIntrinsics
        The camera (distortion included).
    n : int
        Number of views.
    rng : numpy.random.Generator
        Source of every draw.
    tilt_deg : (float, float)
        Range of the tilt from face-on (degrees).
    fill : (float, float)
        Range of the board's width as a share of the image's.
    flat_share : float
        Share of the views nearly face-on (tilt under 10 degrees).
    min_in_view : float
        Least share of the board's inner corners in the image.
    margin_px : float
        How far inside the image's edges a corner must be to count as in it (pixels).

    Returns
    -------
    list of ndarray, shape (4, 4)
        ``board2cam`` per view.
    """
    renderer = BoardRenderer(board, intrinsics)
    h, w = intrinsics.shape
    bw, bh = board.size_m
    centre_m = np.array([0.5 * bw, 0.5 * bh, 0.0])
    poses = []
    for i in range(n):
        cell_x, cell_y = i % 3, (i // 3) % 3
        for attempt in range(300):
            shrink = 0.99 ** max(0, attempt - 50)
            flat = rng.random() < flat_share
            tilt = math.radians(rng.uniform(0.0, 10.0) if flat else rng.uniform(*tilt_deg))
            azimuth = rng.uniform(0.0, 2.0 * math.pi)
            spin = math.radians(rng.uniform(-30.0, 30.0))
            share = rng.uniform(*fill) * shrink
            u = (cell_x + rng.random()) / 3.0 * 1.1 - 0.05
            v = (cell_y + rng.random()) / 3.0 * 1.1 - 0.05
            # Towards the centre as attempts fail: a corner cell needs a small board.
            u_px = w * (0.5 + (u - 0.5) * shrink)
            v_px = h * (0.5 + (v - 0.5) * shrink)
            axis = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
            rot = _rotation_about(axis, tilt) @ rotation_z(spin)
            z = intrinsics.fx_px * bw / (share * w)
            ray = np.array([(u_px - intrinsics.cx_px) / intrinsics.fx_px,
                            (v_px - intrinsics.cy_px) / intrinsics.fy_px, 1.0])
            pose = transform_from(rot, z * ray - rot @ centre_m)
            try:
                renderer.project(pose, renderer.sheet_corners_m)
                px = renderer.corners_px(pose)
            except InputError:
                continue
            inside = ((px[:, 0] >= margin_px) & (px[:, 0] <= w - 1 - margin_px)
                      & (px[:, 1] >= margin_px) & (px[:, 1] <= h - 1 - margin_px))
            if inside.mean() >= min_in_view:
                poses.append(pose)
                break
        else:
            raise InputError(f"no view of the {board.describe()} board fits a "
                             f"{w}x{h} image: use a smaller board")
    return poses
