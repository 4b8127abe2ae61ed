"""ArUco marker tracking: detection, sub-pixel corners, pose, zero pose, and loss.

Detection is OpenCV's :class:`cv2.aruco.ArucoDetector` with
``CORNER_REFINE_SUBPIX``, run on a region of interest around the last
detection and on the full frame when that fails.  Pose is
:func:`cv2.solvePnPGeneric` with ``SOLVEPNP_IPPE_SQUARE``, which returns both
solutions of the planar-square ambiguity; the tracker keeps the one
closest to its previous pose.

``cornerSubPix`` is built for saddle points; on the L-shaped corners of a
marker it pulls every corner inwards by a tenth of a pixel or more, which
at the usual marker sizes is a degree of out-of-plane rotation.
:func:`refine_corners_by_edges` removes that bias: it locates the black
border's four edges to sub-pixel precision along many short profiles (the
first moment of each intensity step, exact for an area-sampled edge), fits
a line to each edge and intersects them.  Perspective keeps edges straight,
so the fit uses every edge pixel instead of the few around each corner.
With lens distortion the lines are fitted in undistorted coordinates.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import Frame
from relaxgrip.perception.frames import FrameError, check_rgb_frame
from relaxgrip.rig import CameraIntrinsics, MarkerMount

FloatArray = NDArray[np.float64]
GrayImage = NDArray[np.uint8]

__all__ = [
    "MarkerDetection",
    "MarkerPose",
    "MarkerState",
    "MarkerTracker",
    "PoseSolver",
    "TrackStatus",
    "detect_markers",
    "estimate_pose",
    "make_detector",
    "mean_rotation",
    "refine_corners_by_edges",
    "rotation_angle",
    "to_gray",
]

#: Samples per edge and their spacing across it (pixels) for the edge fit.
_EDGE_SAMPLES = 24
_PROFILE_HALF_PX = 3.0
_PROFILE_STEP_PX = 0.5
#: Fraction of each edge left out at both ends, where the corner bends the profile.
_EDGE_MARGIN = 0.12
_EDGE_S = np.linspace(_EDGE_MARGIN, 1.0 - _EDGE_MARGIN, _EDGE_SAMPLES)
_OFFSETS = np.arange(-_PROFILE_HALF_PX, _PROFILE_HALF_PX + 1e-9, _PROFILE_STEP_PX)
_INSIDE_MEAN = (_OFFSETS <= -2.0) / np.count_nonzero(_OFFSETS <= -2.0)
_OUTSIDE_MEAN = (_OFFSETS >= 2.0) / np.count_nonzero(_OFFSETS >= 2.0)
_TRAPEZOID = np.full(_OFFSETS.size, _PROFILE_STEP_PX)
_TRAPEZOID[[0, -1]] *= 0.5
_TRAPEZOID_SUM = float(_TRAPEZOID.sum())
#: Rows [1, s, offset] of every profile sample: times an edge's (origin, along, across)
#: they give its pixel positions in one matrix product.
_SAMPLE_DESIGN = np.column_stack([
    np.ones(_EDGE_S.size * _OFFSETS.size),
    np.repeat(_EDGE_S, _OFFSETS.size),
    np.tile(_OFFSETS, _EDGE_S.size),
])
_EDGE_DESIGN = np.column_stack([np.ones(_EDGE_S.size), _EDGE_S])
_NEXT = np.roll(np.eye(4), 1, axis=1)  # row k selects corner k+1
_PREV = np.roll(np.eye(4), -1, axis=1)  # row k selects corner k-1
_ROT90 = np.array([1.0, -1.0])


def to_gray(image: NDArray[np.uint8]) -> GrayImage:
    """Grey levels of an RGB ``(H, W, 3)`` or grey ``(H, W)`` uint8 image (the image if grey)."""
    if image.ndim == 2:
        return image
    return np.asarray(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY), dtype=np.uint8)


def make_detector(dictionary: cv2.aruco.Dictionary, roi: bool = False) -> cv2.aruco.ArucoDetector:
    """An ArUco detector with sub-pixel corner refinement.

    Parameters
    ----------
    dictionary : cv2.aruco.Dictionary
        Marker dictionary.
    roi : bool
        Tune for a small region around a known marker, where the marker
        spans a quarter or more of the region.

    Returns
    -------
    cv2.aruco.ArucoDetector
    """
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    if roi:
        # The marker fills a known share of the region: detect on a downscaled
        # copy (OpenCV's ArUco 3 pipeline) with one threshold scale, then
        # refine the corners on the full-resolution region.
        params.useAruco3Detection = True
        params.minMarkerLengthRatioOriginalImg = 0.2
        params.minSideLengthCanonicalImg = 32
        params.adaptiveThreshWinSizeMin = 7
        params.adaptiveThreshWinSizeMax = 7
        params.minMarkerPerimeterRate = 0.1
        params.maxMarkerPerimeterRate = 4.0
    return cv2.aruco.ArucoDetector(dictionary, params)


@dataclass(frozen=True)
class MarkerDetection:
    """One detected marker.

    Attributes
    ----------
    marker_id : int
        Its id in the dictionary.
    corners_px : ndarray, shape (4, 2)
        Corners in image pixels, OpenCV order (top-left, top-right,
        bottom-right, bottom-left in the marker's own frame).
    """

    marker_id: int
    corners_px: FloatArray


def detect_markers(
    gray: GrayImage, detector: cv2.aruco.ArucoDetector, offset_px: tuple[int, int] = (0, 0)
) -> list[MarkerDetection]:
    """Detect markers in a grey image, corners shifted by ``offset_px`` (x, y)."""
    corners, ids, _ = detector.detectMarkers(gray)
    if ids is None or len(corners) == 0:
        return []
    shift = np.asarray(offset_px, dtype=np.float64)
    return [
        MarkerDetection(int(i), c.reshape(4, 2).astype(np.float64) + shift)
        for i, c in zip(np.ravel(ids), corners, strict=True)
    ]


def refine_corners_by_edges(
    gray: GrayImage,
    corners_px: FloatArray,
    intrinsics: CameraIntrinsics | None = None,
    origin_px: tuple[int, int] = (0, 0),
) -> FloatArray | None:
    """Corners as intersections of lines fitted to the marker's four border edges.

    Parameters
    ----------
    gray : ndarray, shape (H, W), uint8
        Image (or region) the corners are given in.
    corners_px : ndarray, shape (4, 2)
        Approximate corners (within a pixel or two), in OpenCV order, in
        the pixel coordinates of ``gray``.
    intrinsics : CameraIntrinsics, optional
        With distortion coefficients, the edge lines are fitted in
        undistorted coordinates (where they are straight).
    origin_px : tuple of int
        Position of ``gray``'s top-left pixel in the full image (for a region
        of interest), needed to undistort.

    Returns
    -------
    ndarray, shape (4, 2), or None
        Refined corners in the same pixel coordinates; ``None`` when the
        marker is too small, too close to the image border, or an edge
        shows no clean dark-to-light step (occluded, saturated).
    """
    c = np.asarray(corners_px, dtype=np.float64)
    # Every profile sample lies within the corners' box grown by the profile's half-width.
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = c.tolist()
    h, w = gray.shape
    if min(x0, x1, x2, x3) < _PROFILE_HALF_PX or min(y0, y1, y2, y3) < _PROFILE_HALF_PX or (
        max(x0, x1, x2, x3) > w - 1 - _PROFILE_HALF_PX
        or max(y0, y1, y2, y3) > h - 1 - _PROFILE_HALF_PX
    ):
        return None
    vec = _NEXT @ c - c  # edge k runs from corner k to corner k+1
    length = np.sqrt((vec * vec).sum(axis=1))
    if length.min() < 12.0:
        return None
    normal = vec[:, ::-1] * (_ROT90 / length[:, None])  # (dy, -dx): outward, clockwise order
    frame = np.stack([c, vec, normal], axis=1)  # (4, 3, 2): origin, along, across
    maps = (_SAMPLE_DESIGN @ frame).astype(np.float32).reshape(4 * _EDGE_SAMPLES, -1, 2)
    prof = cv2.remap(gray, maps, None, cv2.INTER_LINEAR)  # type: ignore[call-overload]
    inside = prof @ _INSIDE_MEAN
    contrast = prof @ _OUTSIDE_MEAN - inside
    good = contrast > 20.0
    # First moment of the normalised step: for an area-sampled straight edge
    # the area under (I - I_in) / (I_out - I_in) ends exactly at the edge.
    area = (prof @ _TRAPEZOID - inside * _TRAPEZOID_SUM) / np.where(good, contrast, 1.0)
    r = (_OFFSETS[-1] - area).reshape(4, _EDGE_SAMPLES)
    edge_pts = (_EDGE_DESIGN @ frame[:, :2, :]).reshape(4, _EDGE_SAMPLES, 2)
    edge_pts += r[:, :, None] * normal[:, None, :]
    edge_pts = edge_pts.reshape(-1, 2)
    weight = good.reshape(4, _EDGE_SAMPLES).astype(np.float64)
    count = weight.sum(axis=1)
    if count.min() < _EDGE_SAMPLES // 2:
        return None
    distorted = intrinsics is not None and bool(intrinsics.dist)
    if distorted:
        assert intrinsics is not None
        shift = np.asarray(origin_px, dtype=np.float64)
        focal = np.array([intrinsics.fx_px, intrinsics.fy_px])
        centre_px = np.array([intrinsics.cx_px, intrinsics.cy_px])
        edge_pts = intrinsics.normalized(edge_pts + shift) * focal + centre_px
    # Total least squares line per edge: centroid and principal direction of the points.
    e = edge_pts.reshape(4, _EDGE_SAMPLES, 2)
    centroid = np.matmul(weight[:, None, :], e)[:, 0, :] / count[:, None]
    dev = e - centroid[:, None, :]
    cov = np.matmul((dev * weight[:, :, None]).transpose(0, 2, 1), dev)  # (4, 2, 2)
    angle = 0.5 * np.arctan2(2.0 * cov[:, 0, 1], cov[:, 0, 0] - cov[:, 1, 1])
    u = np.empty((4, 2))
    u[:, 0] = np.cos(angle)
    u[:, 1] = np.sin(angle)
    # Corner k is where edge k-1 meets edge k: p + t u = q + s v.
    p0, up = _PREV @ centroid, _PREV @ u
    cross = up[:, 0] * u[:, 1] - up[:, 1] * u[:, 0]
    if np.abs(cross).min() < 1e-6:
        return None
    rhs = centroid - p0
    t = (rhs[:, 0] * u[:, 1] - rhs[:, 1] * u[:, 0]) / cross
    out: FloatArray = p0 + t[:, None] * up
    if distorted:
        rays = np.column_stack([(out - centre_px) / focal, np.ones(4)])
        out = intrinsics.project(rays) - shift  # type: ignore[union-attr]
    if np.abs(out - c).max() > 3.0:
        return None  # the fit moved a corner by more than the detector's error: distrust it
    return out


@dataclass(frozen=True)
class MarkerPose:
    """A marker's pose in the camera frame.

    Attributes
    ----------
    rvec : ndarray, shape (3,)
        Rotation ``marker -> camera`` as a Rodrigues vector (rad).
    tvec_m : ndarray, shape (3,)
        Marker centre in the camera frame (m).
    corners_px : ndarray, shape (4, 2)
        Image corners the pose was computed from.
    reprojection_px : float
        RMS reprojection error of the corners (pixels).
    rotation : ndarray, shape (3, 3)
        Rotation matrix ``marker -> camera`` (the same rotation as ``rvec``).
    """

    rvec: FloatArray
    tvec_m: FloatArray
    corners_px: FloatArray
    reprojection_px: float
    rotation: FloatArray


class PoseSolver:
    """Pose of a square marker from its corners (``SOLVEPNP_IPPE_SQUARE``).

    Holds what does not change between frames (camera matrix, distortion,
    the square's corners), so that solving costs only OpenCV's own work.

    Parameters
    ----------
    marker_size_m : float
        Side of the black square (m).
    intrinsics : CameraIntrinsics
        Camera matrix and distortion.
    """

    def __init__(self, marker_size_m: float, intrinsics: CameraIntrinsics) -> None:
        h = marker_size_m / 2.0
        self._object = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
        self._matrix = intrinsics.matrix
        self._dist = intrinsics.dist_coeffs

    def solve(self, corners_px: FloatArray, previous: MarkerPose | None = None) -> MarkerPose:
        """Pose from corners in image pixels (OpenCV order).

        Of IPPE's two solutions (the second is the mirror image of a
        near-frontal square), the one whose rotation is closer to
        ``previous`` is kept; without ``previous``, the one with the lower
        reprojection error.
        """
        corners = np.ascontiguousarray(corners_px, dtype=np.float64)
        _, rvecs, tvecs, errors = cv2.solvePnPGeneric(
            self._object, corners.reshape(4, 1, 2), self._matrix, self._dist,
            flags=cv2.SOLVEPNP_IPPE_SQUARE,
        )
        rotations = [cv2.Rodrigues(r)[0] for r in rvecs]
        best = 0
        if previous is not None and len(rotations) > 1:
            # trace(R_i^T R_prev) = 1 + 2 cos(angle between them): largest is closest.
            best = int(np.argmax([float((r * previous.rotation).sum()) for r in rotations]))
        return MarkerPose(
            np.asarray(rvecs[best], dtype=np.float64).ravel(),
            np.asarray(tvecs[best], dtype=np.float64).ravel(),
            corners,
            float(np.ravel(errors)[best]),
            np.asarray(rotations[best], dtype=np.float64),
        )


def estimate_pose(
    corners_px: FloatArray,
    marker_size_m: float,
    intrinsics: CameraIntrinsics,
    previous: MarkerPose | None = None,
) -> MarkerPose:
    """Pose of a square marker from its corners; see :class:`PoseSolver`.

    Parameters
    ----------
    corners_px : ndarray, shape (4, 2)
        Corners in image pixels, OpenCV order.
    marker_size_m : float
        Side of the black square (m).
    intrinsics : CameraIntrinsics
        Camera matrix and distortion.
    previous : MarkerPose, optional
        Last accepted pose, to choose between IPPE's two solutions.

    Returns
    -------
    MarkerPose
    """
    return PoseSolver(marker_size_m, intrinsics).solve(corners_px, previous)


def rotation_angle(rotation: FloatArray) -> float:
    """Angle of a rotation matrix (rad), in [0, pi]."""
    return math.acos(min(1.0, max(-1.0, 0.5 * (float(np.trace(rotation)) - 1.0))))


def mean_rotation(rotations: list[FloatArray]) -> FloatArray:
    """Chordal mean of rotation matrices: the rotation closest to their average."""
    u, _, vt = np.linalg.svd(np.mean(rotations, axis=0))
    rot: FloatArray = u @ vt
    if np.linalg.det(rot) < 0:
        u[:, -1] *= -1.0
        rot = u @ vt
    return rot


class TrackStatus(enum.StrEnum):
    """What the tracker could make of a frame."""

    ZEROING = "zeroing"
    """Marker seen; the zero pose is still being averaged (no relative pose yet)."""
    TRACKING = "tracking"
    """Marker seen; relative pose available."""
    REJECTED = "rejected"
    """Marker seen, but it jumped implausibly far since the last frame: ignored."""
    LOST = "lost"
    """No marker in the frame."""
    INVALID = "invalid"
    """The frame itself was unusable (empty, wrong size or type)."""


@dataclass(frozen=True)
class MarkerState:
    """The tracker's answer for one frame.

    Attributes
    ----------
    t_s : float
        Capture time of the frame (s).
    status : TrackStatus
        See :class:`TrackStatus`.
    pose : MarkerPose or None
        Absolute pose from this frame, when the marker was accepted.
    delta_t_m : ndarray, shape (3,), or None
        Marker translation from the zero pose, camera frame (m).
    delta_r_rad : ndarray, shape (3,), or None
        Rotation from the zero pose, ``R R0^T`` as a Rodrigues vector in the
        camera frame (rad).
    lost_for_s : float
        Time since the marker was last accepted (s); 0 while tracking.
    search : {"roi", "full", "none"}
        Where the marker was found.
    message : str
        Why a frame was invalid or rejected; empty otherwise.
    """

    t_s: float
    status: TrackStatus
    pose: MarkerPose | None = None
    delta_t_m: FloatArray | None = None
    delta_r_rad: FloatArray | None = None
    lost_for_s: float = 0.0
    search: Literal["roi", "full", "none"] = "none"
    message: str = ""

    @property
    def ok(self) -> bool:
        """True when a relative pose is available."""
        return self.status is TrackStatus.TRACKING


@dataclass
class MarkerTracker:
    """Track one marker through a stream of RGB frames.

    Parameters
    ----------
    intrinsics : CameraIntrinsics
        The RGB camera.
    marker : MarkerMount
        Dictionary, id and size of the marker.
    zero_frames : int
        Accepted frames averaged into the zero pose (the unloaded finger).
    roi_margin : float
        Margin around the last corners' bounding box, as a fraction of its size.
    edge_refine : bool
        Refine corners with :func:`refine_corners_by_edges`.
    max_speed_m_s, max_rate_rad_s : float
        Fastest plausible marker motion; a pose further from the last
        accepted one than this allows (plus a floor of 1 mm / 0.05 rad) is
        rejected as a false detection.
    reacquire_after : int
        After this many consecutive rejections the new pose is accepted (the
        marker really moved, e.g. while it was hidden).
    """

    intrinsics: CameraIntrinsics
    marker: MarkerMount
    zero_frames: int = 15
    roi_margin: float = 0.3
    edge_refine: bool = True
    max_speed_m_s: float = 0.15
    max_rate_rad_s: float = 3.0
    reacquire_after: int = 5
    _full: cv2.aruco.ArucoDetector = field(init=False, repr=False)
    _roi: cv2.aruco.ArucoDetector = field(init=False, repr=False)

    def __post_init__(self) -> None:
        dictionary = self.marker.aruco_dictionary
        self._full = make_detector(dictionary)
        self._roi = make_detector(dictionary, roi=True)
        self._solver = PoseSolver(self.marker.size_m, self.intrinsics)
        self.reset()

    def reset(self) -> None:
        """Forget the zero pose and the last detection."""
        self._zero_samples: list[MarkerPose] = []
        self._zero: tuple[FloatArray, FloatArray] | None = None
        self._last: MarkerPose | None = None
        self._last_t: float | None = None
        self._rejections = 0

    def rezero(self) -> None:
        """Average a new zero pose from the next ``zero_frames`` accepted frames."""
        self._zero_samples = []
        self._zero = None

    @property
    def zero_pose(self) -> tuple[FloatArray, FloatArray] | None:
        """``(R0, t0)`` of the unloaded finger, once averaged."""
        return self._zero

    def update(self, frame: Frame) -> MarkerState:
        """Track the marker in one frame; never raises on a bad frame."""
        lost_for = 0.0 if self._last_t is None else max(0.0, frame.t_s - self._last_t)
        try:
            image = check_rgb_frame(frame.image, self.intrinsics)
        except FrameError as exc:
            return MarkerState(frame.t_s, TrackStatus.INVALID, lost_for_s=lost_for,
                               message=str(exc))
        found, search = self._find(image)
        if found is None:
            return MarkerState(frame.t_s, TrackStatus.LOST, lost_for_s=lost_for)
        pose = self._solver.solve(found, self._last)
        if self._implausible(pose, frame.t_s):
            self._rejections += 1
            if self._rejections <= self.reacquire_after:
                return MarkerState(frame.t_s, TrackStatus.REJECTED, lost_for_s=lost_for,
                                   search=search, message="implausible jump since last frame")
        self._rejections = 0
        self._last, self._last_t = pose, frame.t_s
        if self._zero is None:
            self._zero_samples.append(pose)
            if len(self._zero_samples) < self.zero_frames:
                return MarkerState(frame.t_s, TrackStatus.ZEROING, pose, search=search)
            rot0 = mean_rotation([p.rotation for p in self._zero_samples])
            t0 = np.mean([p.tvec_m for p in self._zero_samples], axis=0)
            self._zero = (rot0, t0)
        rot0, t0 = self._zero
        delta_r = np.asarray(cv2.Rodrigues(pose.rotation @ rot0.T)[0], dtype=np.float64).ravel()
        return MarkerState(frame.t_s, TrackStatus.TRACKING, pose, pose.tvec_m - t0, delta_r,
                           search=search)

    def _find(
        self, image: NDArray[np.uint8]
    ) -> tuple[FloatArray | None, Literal["roi", "full", "none"]]:
        if self._last is not None:
            found = self._search_roi(image, self._last.corners_px)
            if found is not None:
                return found, "roi"
        gray = to_gray(image)
        for det in detect_markers(gray, self._full):
            if det.marker_id == self.marker.marker_id:
                return self._refined(gray, det.corners_px, (0, 0)), "full"
        return None, "none"

    def _search_roi(self, image: NDArray[np.uint8], corners: FloatArray) -> FloatArray | None:
        h, w = image.shape[:2]
        xs, ys = corners[:, 0].tolist(), corners[:, 1].tolist()
        lo_x, hi_x, lo_y, hi_y = min(xs), max(xs), min(ys), max(ys)
        pad = self.roi_margin * max(hi_x - lo_x, hi_y - lo_y) + 4.0
        x0, y0 = max(int(lo_x - pad), 0), max(int(lo_y - pad), 0)
        x1, y1 = min(int(hi_x + pad) + 1, w), min(int(hi_y + pad) + 1, h)
        if x1 - x0 < 16 or y1 - y0 < 16:
            return None
        gray = to_gray(image[y0:y1, x0:x1])
        for det in detect_markers(gray, self._roi):
            if det.marker_id == self.marker.marker_id:
                return self._refined(gray, det.corners_px, (x0, y0))
        return None

    def _refined(self, gray: GrayImage, corners: FloatArray, origin: tuple[int, int]) -> FloatArray:
        if self.edge_refine:
            refined = refine_corners_by_edges(gray, corners, self.intrinsics, origin)
            if refined is not None:
                corners = refined
        return corners + np.asarray(origin, dtype=np.float64)

    def _implausible(self, pose: MarkerPose, t_s: float) -> bool:
        if self._last is None or self._last_t is None:
            return False
        dt = max(t_s - self._last_t, 0.0)
        step = pose.tvec_m - self._last.tvec_m
        step_m = math.sqrt(float(step @ step))
        cos_step = 0.5 * (float((pose.rotation * self._last.rotation).sum()) - 1.0)
        step_rad = math.acos(min(1.0, max(-1.0, cos_step)))
        return step_m > 1e-3 + self.max_speed_m_s * dt or step_rad > 0.05 + self.max_rate_rad_s * dt
