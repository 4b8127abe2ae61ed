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

import copy
import enum
import math
from dataclasses import dataclass, field
from typing import Any, Literal

import cv2
import numba
import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from relaxgrip.backend import Frame
from relaxgrip.errors import InputError
from relaxgrip.perception.frames import FrameError, check_rgb_frame
from relaxgrip.rig import CameraIntrinsics, MarkerMount

FloatArray = NDArray[np.float64]
GrayImage = NDArray[np.uint8]
Search = Literal["edges", "roi", "full", "none"]

__all__ = [
    "MarkerDetection",
    "MarkerPose",
    "MarkerState",
    "MarkerTracker",
    "PoseSolver",
    "TrackStatus",
    "detect_markers",
    "detection_pose",
    "estimate_pose",
    "locate_marker",
    "make_detector",
    "mean_rotation",
    "refine_corners_by_edges",
    "rotation_angle",
    "to_gray",
    "warm_up",
]

#: Samples per edge and their spacing across it (pixels) for the edge fit.
_EDGE_SAMPLES = 24
_PROFILE_HALF_PX = 3.0
_PROFILE_STEP_PX = 0.5
#: The tracker's edge fit: a first pass that moves a corner this far (px) is repeated
#: until a pass moves none by ``_CONVERGED_PX``, in ``_EDGE_PASSES`` passes at most.
_FIRST_PASS_PX = 0.5
_CONVERGED_PX = 0.05
_EDGE_PASSES = 4
#: Fraction of each edge left out at both ends, where the corner bends the profile.
_EDGE_MARGIN = 0.12
_EDGE_S = np.linspace(_EDGE_MARGIN, 1.0 - _EDGE_MARGIN, _EDGE_SAMPLES)
_OFFSETS = np.arange(-_PROFILE_HALF_PX, _PROFILE_HALF_PX + 1e-9, _PROFILE_STEP_PX)
_TRAPEZOID = np.full(_OFFSETS.size, _PROFILE_STEP_PX)
_TRAPEZOID[[0, -1]] *= 0.5
_TRAPEZOID_SUM = float(_TRAPEZOID.sum())
#: Columns: mean inside the marker (offsets <= -2 px), mean outside (>= 2 px), trapezoid
#: integral: the weights of the three moments of every profile.
_PROFILE_MOMENTS = np.column_stack([
    (_OFFSETS <= -2.0) / np.count_nonzero(_OFFSETS <= -2.0),
    (_OFFSETS >= 2.0) / np.count_nonzero(_OFFSETS >= 2.0),
    _TRAPEZOID,
])
_EDGE_DESIGN = np.column_stack([np.ones(_EDGE_S.size), _EDGE_S])  # rows [1, s] on an edge
_NEXT = np.roll(np.eye(4), 1, axis=1)  # row k selects corner k+1
_ROT90 = np.array([1.0, -1.0])
#: Half turn about x: maps the marker frame to the one IPPE sees with the corners reversed.
_HALF_TURN_X = np.diag([1.0, -1.0, -1.0])


def _pixels(frame: Frame, y0: int, y1: int, x0: int, x1: int) -> NDArray[np.uint8]:
    """The RGB (or grey) pixels ``[y0:y1, x0:x1]`` of a checked frame."""
    return np.asarray(frame.region(y0, y1, x0, x1), dtype=np.uint8)


def to_gray(image: NDArray[np.uint8]) -> GrayImage:
    """Grey levels of an RGB ``(H, W, 3)`` or grey ``(H, W)`` uint8 image (the image if grey)."""
    if image.ndim == 2:
        return image
    # OpenCV's binding is slow on strided views (a region of a frame): copy first.
    return np.asarray(cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY),
                      dtype=np.uint8)


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
    modules: int | None = None,
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
    modules : int, optional
        The marker's side in modules (its bits plus the black border).  The
        edge profile reads ``_PROFILE_HALF_PX`` inside the edge: where a
        border module is narrower than that, it reads the data modules and
        the fit is biased (an 18 px 4x4 marker: 4.8 % off in distance against
        2.2 % for the detector's corners), so such a marker is not refined.

    Returns
    -------
    ndarray, shape (4, 2), or None
        Refined corners in the same pixel coordinates; ``None`` when the
        marker is too small, too close to the image border, or an edge
        shows no clean dark-to-light step (occluded, saturated).
    """
    c = np.ascontiguousarray(corners_px, dtype=np.float64)
    h, w = gray.shape
    min_length = max(12.0, 0.0 if modules is None else modules * (_PROFILE_HALF_PX + 0.5))
    frame = _edge_frames(c, h, w, _PROFILE_HALF_PX, min_length)
    if frame is None:
        return None
    maps = _sample_maps(frame, _EDGE_S, _OFFSETS)
    prof = cv2.remap(gray, maps, None, cv2.INTER_LINEAR)  # type: ignore[call-overload]
    r = np.empty((4, _EDGE_SAMPLES))
    weight = np.empty((4, _EDGE_SAMPLES))
    if _edge_offsets(prof, _PROFILE_MOMENTS, _TRAPEZOID_SUM, _OFFSETS[-1], r,
                     weight) < _EDGE_SAMPLES // 2:
        return None
    if intrinsics is not None and intrinsics.dist:
        return _refine_distorted(frame, r, weight, c, intrinsics, origin_px)
    out = np.empty((4, 2))
    # The fit moved a corner by more than the detector's error, or two lines are
    # parallel: distrust it.
    return out if _fit_corners(frame, r, weight, _EDGE_S, c, out) else None


# The edge fit compiled (numba): it runs once or twice on every frame, on a few hundred
# numbers, where numpy's per-call cost was most of its time.


@numba.njit(cache=True, nogil=True)
def _edge_frames(corners: FloatArray, rows: int, cols: int, half_px: float,
                 min_length: float) -> FloatArray | None:  # pragma: no cover - compiled
    """Each edge's (origin, along (the full edge), across (the unit normal)): shape (4, 3,
    2); None when a corner is not finite, a profile would leave the image or an edge is
    shorter than ``min_length``.  Edge k runs from corner k to k+1; its normal (dy, -dx)
    points out for OpenCV's clockwise corner order."""
    for k in range(4):
        x, y = corners[k, 0], corners[k, 1]
        if not (math.isfinite(x) and math.isfinite(y)):
            return None
        # Every profile sample lies within the corners' box grown by the half-width.
        if x < half_px or y < half_px or x > cols - 1 - half_px or y > rows - 1 - half_px:
            return None
    frame = np.empty((4, 3, 2))
    for k in range(4):
        ax, ay = corners[k, 0], corners[k, 1]
        dx, dy = corners[(k + 1) % 4, 0] - ax, corners[(k + 1) % 4, 1] - ay
        length = math.hypot(dx, dy)
        if length < min_length:
            return None
        frame[k, 0, 0], frame[k, 0, 1] = ax, ay
        frame[k, 1, 0], frame[k, 1, 1] = dx, dy
        frame[k, 2, 0], frame[k, 2, 1] = dy / length, -dx / length
    return frame


@numba.njit(cache=True, nogil=True)
def _sample_maps(frame: FloatArray, along: FloatArray,
                 offsets: FloatArray) -> NDArray[np.float32]:  # pragma: no cover - compiled
    """Where each profile samples: row ``k S + i`` of edge k at ``along[i]``, one column
    per offset across it, (x, y) as ``cv2.remap`` takes them."""
    n = along.size
    maps = np.empty((4 * n, offsets.size, 2), np.float32)
    for k in range(4):
        for i in range(n):
            for j in range(offsets.size):
                for a in range(2):
                    maps[k * n + i, j, a] = np.float32(
                        frame[k, 0, a] + along[i] * frame[k, 1, a] + offsets[j] * frame[k, 2, a])
    return maps


@numba.njit(cache=True, nogil=True)
def _edge_offsets(prof: GrayImage, moments: FloatArray, trapezoid_sum: float,
                  last_offset: float, r: FloatArray,
                  weight: FloatArray) -> float:  # pragma: no cover - compiled
    """Each profile's edge offset along its normal into ``r`` and 1 or 0 (a clean
    dark-to-light step or not) into ``weight``, both (4, S); returns the fewest good
    profiles of an edge."""
    n = r.shape[1]
    fewest = float(n)
    for k in range(4):
        good_count = 0.0
        for i in range(n):
            row = prof[k * n + i]
            inside = outside = integral = 0.0
            for j in range(row.size):
                value = float(row[j])
                inside += value * moments[j, 0]
                outside += value * moments[j, 1]
                integral += value * moments[j, 2]
            contrast = outside - inside
            good = contrast > 20.0
            # First moment of the normalised step: for an area-sampled straight edge
            # the area under (I - I_in) / (I_out - I_in) ends exactly at the edge.
            area = (integral - inside * trapezoid_sum) / (contrast if good else 1.0)
            r[k, i] = last_offset - area
            weight[k, i] = 1.0 if good else 0.0
            good_count += weight[k, i]
        fewest = min(fewest, good_count)
    return fewest


@numba.njit(cache=True, nogil=True)
def _fit_corners(frame: FloatArray, r: FloatArray, weight: FloatArray, along: FloatArray,
                 guess: FloatArray, out: FloatArray) -> bool:  # pragma: no cover - compiled
    """A weighted least-squares line per edge in its own frame (offset = a + b along),
    corner k where line k-1 meets line k, into ``out``; False where two lines are
    parallel or a corner moved more than 3 px from ``guess``."""
    lines = np.empty((4, 4))  # per edge: point x, y; direction x, y
    for k in range(4):
        s0 = s1 = s2 = t0 = t1 = 0.0
        for i in range(along.size):
            wk, s = weight[k, i], along[i]
            s0 += wk
            s1 += wk * s
            s2 += wk * s * s
            t0 += wk * r[k, i]
            t1 += wk * r[k, i] * s
        slope = (s0 * t1 - s1 * t0) / (s0 * s2 - s1 * s1)
        offset = (t0 - slope * s1) / s0
        nx, ny = frame[k, 2, 0], frame[k, 2, 1]
        lines[k, 0] = frame[k, 0, 0] + offset * nx
        lines[k, 1] = frame[k, 0, 1] + offset * ny
        lines[k, 2] = frame[k, 1, 0] + slope * nx
        lines[k, 3] = frame[k, 1, 1] + slope * ny
    if not _intersect(lines, out):
        return False
    for k in range(4):
        if abs(out[k, 0] - guess[k, 0]) > 3.0 or abs(out[k, 1] - guess[k, 1]) > 3.0:
            return False
    return True


@numba.njit(cache=True, nogil=True)
def _intersect(lines: FloatArray, out: FloatArray) -> bool:  # pragma: no cover - compiled
    """Corner k where line k-1 meets line k into ``out`` (4, 2); lines (4, 4) as point
    x, y and direction x, y.  False where two lines are parallel."""
    for k in range(4):
        px, py, ux, uy = lines[k - 1, 0], lines[k - 1, 1], lines[k - 1, 2], lines[k - 1, 3]
        qx, qy, vx, vy = lines[k, 0], lines[k, 1], lines[k, 2], lines[k, 3]
        cross = ux * vy - uy * vx
        if abs(cross) < 1e-9 * (ux * ux + uy * uy):
            return False
        t = ((qx - px) * vy - (qy - py) * vx) / cross
        out[k, 0], out[k, 1] = px + t * ux, py + t * uy
    return True


def _refine_distorted(
    frame: FloatArray,
    r: FloatArray,
    weight: FloatArray,
    corners: FloatArray,
    intrinsics: CameraIntrinsics,
    origin_px: tuple[int, int],
) -> FloatArray | None:
    """The line fit of :func:`refine_corners_by_edges` where edges are straight: undistorted."""
    shift = np.asarray(origin_px, dtype=np.float64)
    focal = np.array([intrinsics.fx_px, intrinsics.fy_px])
    centre_px = np.array([intrinsics.cx_px, intrinsics.cy_px])

    def undistort(px: FloatArray) -> FloatArray:
        out: FloatArray = intrinsics.normalized(px + shift) * focal + centre_px
        return out

    pts = (_EDGE_DESIGN @ frame[:, :2, :]) + r[:, :, None] * frame[:, 2, None, :]
    pts = undistort(pts.reshape(-1, 2)).reshape(4, _EDGE_SAMPLES, 2)
    c = undistort(corners)
    vec = _NEXT @ c - c
    length = np.sqrt((vec * vec).sum(axis=1))
    normal = vec[:, ::-1] * (_ROT90 / length[:, None])
    rel = pts - c[:, None, :]
    along = np.einsum("ksj,kj->ks", rel, vec) / (length * length)[:, None]
    offset_r = np.einsum("ksj,kj->ks", rel, normal)
    s0, s1 = weight.sum(axis=1), (weight * along).sum(axis=1)
    s2 = (weight * along * along).sum(axis=1)
    t0, t1 = (weight * offset_r).sum(axis=1), (weight * along * offset_r).sum(axis=1)
    slope = (s0 * t1 - s1 * t0) / (s0 * s2 - s1 * s1)
    offset = (t0 - slope * s1) / s0
    point = c + offset[:, None] * normal
    direction = vec + slope[:, None] * normal
    fitted = np.empty((4, 2))
    if not _intersect(np.ascontiguousarray(np.hstack([point, direction])), fitted):
        return None
    rays = np.column_stack([(fitted - centre_px) / focal, np.ones(4)])
    out: FloatArray = intrinsics.project(rays) - shift
    if not np.all(np.abs(out - corners) <= 3.0):  # nan is no refinement either
        return None
    return out


@dataclass(frozen=True)
class MarkerPose:
    """A marker's pose in the camera frame.

    Attributes
    ----------
    rotation : ndarray, shape (3, 3)
        Rotation ``marker -> camera``.
    tvec_m : ndarray, shape (3,)
        Marker centre in the camera frame (m).
    corners_px : ndarray, shape (4, 2)
        Image corners the pose was computed from.
    reprojection_px : float
        RMS reprojection error of the corners (pixels).
    """

    rotation: FloatArray
    tvec_m: FloatArray
    corners_px: FloatArray
    reprojection_px: float

    @property
    def rvec(self) -> FloatArray:
        """The rotation as a Rodrigues vector (rad), computed stably near a half turn."""
        if not _finite(self.rotation):
            return np.full(3, np.nan)  # no pose (PoseSolver.solve)
        out: FloatArray = Rotation.from_matrix(self.rotation).as_rotvec()
        return out

    @property
    def valid(self) -> bool:
        """Whether this is a pose: finite, in front of the camera."""
        return _finite(self.rotation) and _finite(self.tvec_m) and bool(self.tvec_m[2] > 0.0)


class PoseSolver:
    """Pose of a square marker from its corners (``SOLVEPNP_IPPE_SQUARE``).

    A marker facing the camera is turned almost exactly half a turn from the
    camera frame, where the Rodrigues vector is singular, and OpenCV's IPPE
    returns its solutions through that vector: occasionally a fraction of a
    pixel off.  The solver therefore solves for the marker frame turned by a
    half turn about its own ``x`` (the corners given in reverse order), whose
    rotation from the camera is small, and turns the result back exactly, as
    matrices.

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
        self.intrinsics = intrinsics
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
        if not _finite(corners):
            return _no_pose(corners)
        image = corners[::-1].reshape(4, 1, 2)
        _, rvecs, tvecs, errors = cv2.solvePnPGeneric(
            self._object, image, self._matrix, self._dist, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not rvecs or not _finite(np.concatenate((*rvecs, *tvecs))):
            # IPPE's homography decomposition occasionally fails on a near-frontal
            # square and returns nan for both solutions (one frame of about 1.4e5 in
            # a dataset's RCFN sequences, OpenCV 5.0), or none at all (a focal length
            # of 10^6 px); Levenberg-Marquardt does not.
            try:
                _, rvecs, tvecs, errors = cv2.solvePnPGeneric(
                    self._object, image, self._matrix, self._dist, flags=cv2.SOLVEPNP_ITERATIVE)
            except cv2.error:  # degenerate intrinsics (a focal length of 10^300 px)
                rvecs = ()
        if not rvecs:  # no pose: a non-finite one, which the tracker rejects
            return _no_pose(corners)
        best = 0
        rotation = cv2.Rodrigues(rvecs[0])[0] @ _HALF_TURN_X
        if previous is not None and len(rvecs) > 1:
            # trace(R_i^T R_prev) = 1 + 2 cos(angle between them): larger is closer.
            other = cv2.Rodrigues(rvecs[1])[0] @ _HALF_TURN_X
            if np.vdot(other, previous.rotation) > np.vdot(rotation, previous.rotation):
                best, rotation = 1, other
        pose = MarkerPose(
            np.asarray(rotation, dtype=np.float64),
            np.asarray(tvecs[best], dtype=np.float64).ravel(),
            corners,
            float(errors[best][0]),
        )
        # A failed solve can come back finite: zero vectors and a nan error.
        return pose if pose.valid and math.isfinite(pose.reprojection_px) else _no_pose(corners)


def _finite(values: FloatArray) -> bool:
    """Whether every value is finite (numpy's ``isfinite().all()`` costs 3 us on a few)."""
    return all(map(math.isfinite, values.ravel().tolist()))


def _no_pose(corners: FloatArray) -> MarkerPose:
    """The pose of corners that give none: non-finite, which the tracker rejects."""
    return MarkerPose(np.full((3, 3), np.nan), np.full(3, np.nan), corners, math.inf)


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


def locate_marker(
    image: NDArray[np.uint8],
    detector: cv2.aruco.ArucoDetector,
    solver: PoseSolver,
) -> MarkerPose | None:
    """The first marker detected on the whole frame, edge-fitted corners, and its pose.

    No tracking and no region of interest: what a detector-only pipeline
    (the paper's) does on every frame.  ``None`` if no marker is found.
    """
    gray = to_gray(np.asarray(image, dtype=np.uint8))
    found = detect_markers(gray, detector)
    return detection_pose(gray, found[0], solver) if found else None


def detection_pose(gray: NDArray[np.uint8], detection: MarkerDetection,
                   solver: PoseSolver) -> MarkerPose:
    """A detected marker's pose, from its edge-fitted corners where its edges fit (else the
    detector's corners)."""
    corners = refine_corners_by_edges(gray, detection.corners_px, solver.intrinsics)
    return solver.solve(detection.corners_px if corners is None else corners)


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
    """Marker seen, but it jumped implausibly far since the last frame, lies beyond the
    finger's reach, or cannot be told from another marker of its id: ignored."""
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
    search : {"edges", "roi", "full", "none"}
        How the marker was found: followed by its edges from the last frames,
        detected in the region of interest, in the full frame, or not at all.
    message : str
        Why a frame was invalid or rejected; on the frame a marker is
        re-acquired after an implausible jump, how far it jumped; empty otherwise.
    """

    t_s: float
    status: TrackStatus
    pose: MarkerPose | None = None
    delta_t_m: FloatArray | None = None
    delta_r_rad: FloatArray | None = None
    lost_for_s: float = 0.0
    search: Search = "none"
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
        marker really moved, e.g. while it was hidden).  A pose accepted after
        rejected jumps says how far it jumped, and a zero pose still being
        averaged starts again from it.  A pose further than the mount's
        ``max_travel_m`` from the zero pose is rejected however long it stays:
        it is another marker of the same id, not the finger.
    home_m : tuple of float, optional
        Where the unbent finger's marker is in the camera frame (m): the
        translation of :meth:`relaxgrip.rig.RigGeometry.marker2cam`.  Of
        several detections of the tracked id, the tracker keeps the one nearest
        the last accepted corners; before any is accepted, the one nearest
        where this projects.  Without it, a frame showing several is rejected
        until one can be told apart.  Before the zero pose is taken, a marker
        further than the mount's ``max_travel_m`` from it is rejected too: it is
        another marker of the id (or the rig file puts the marker or the camera
        that far from where they are; ``relaxgrip check-rig`` shows it).
    verify_every : int
        Between detections the corners are followed by the edge fit alone,
        started from where the last frames put them (a marker moves a pixel
        or so between frames); the ArUco detector confirms the marker in the
        region of interest at least every ``verify_every`` frames, and on
        every frame where the edge fit fails.  1 runs the detector on every
        frame.  Needs ``edge_refine``.
    """

    intrinsics: CameraIntrinsics
    marker: MarkerMount
    zero_frames: int = 15
    roi_margin: float = 0.5
    edge_refine: bool = True
    max_speed_m_s: float = 0.15
    max_rate_rad_s: float = 3.0
    reacquire_after: int = 5
    verify_every: int = 5
    home_m: tuple[float, float, float] | None = None
    _full: cv2.aruco.ArucoDetector = field(init=False, repr=False)
    _roi: cv2.aruco.ArucoDetector = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._home_px: FloatArray | None = None
        if self.home_m is not None:
            home = np.asarray(self.home_m, dtype=np.float64)
            if home.shape != (3,) or not (np.all(np.isfinite(home)) and home[2] > 0):
                raise InputError(f"home_m must be a point in front of the camera (x, y, z > 0 "
                                 f"m), got {self.home_m}")
            self._home_px = self.intrinsics.project(home[None, :])[0]
        dictionary = self.marker.aruco_dictionary
        self._full = make_detector(dictionary)
        self._roi = make_detector(dictionary, roi=True)
        self._solver = PoseSolver(self.marker.size_m, self.intrinsics)
        self._modules = int(self.marker.aruco_dictionary.markerSize) + 2
        self.reset()

    def __deepcopy__(self, memo: dict[int, Any]) -> MarkerTracker:
        """A copy with detectors of its own: OpenCV's cannot be copied (nor pickled).

        A copy of a whole loop mid-grasp (the fault matrix's, an error budget's)
        goes on tracking as the original would.
        """
        new = type(self).__new__(type(self))
        memo[id(self)] = new
        for name, value in self.__dict__.items():
            if name not in ("_full", "_roi"):
                setattr(new, name, copy.deepcopy(value, memo))
        new._full = make_detector(self.marker.aruco_dictionary)
        new._roi = make_detector(self.marker.aruco_dictionary, roi=True)
        return new

    def reset(self) -> None:
        """Forget the zero pose and the last detection."""
        self._zero_samples: list[MarkerPose] = []
        self._zero: tuple[FloatArray, FloatArray] | None = None
        self._last: MarkerPose | None = None
        self._last_t: float | None = None
        self._previous_corners: FloatArray | None = None
        self._rejections = 0
        self._followed = 0  # frames since the detector last confirmed the marker

    def rezero(self) -> None:
        """Average a new zero pose from the next ``zero_frames`` accepted frames."""
        self._zero_samples = []
        self._zero = None

    @property
    def zero_pose(self) -> tuple[FloatArray, FloatArray] | None:
        """``(R0, t0)`` of the unloaded finger, once averaged."""
        return self._zero

    @property
    def zero_samples(self) -> int:
        """Accepted frames taken towards the zero pose since the last reset or rezero.

        0 before the first one; the zero pose is their average once there are
        ``zero_frames`` of them, and the count stops there.
        """
        return len(self._zero_samples)

    def update(self, frame: Frame) -> MarkerState:
        """Track the marker in one frame; never raises on a bad frame."""
        if not math.isfinite(frame.t_s) or (self._last_t is not None
                                            and frame.t_s < self._last_t):
            # A frame from before the last one (or of no time) would rewind the
            # clock the jump test measures speeds on.
            return MarkerState(frame.t_s, TrackStatus.INVALID,
                               message=f"frame time {frame.t_s} is before the last frame's")
        lost_for = 0.0 if self._last_t is None else max(0.0, frame.t_s - self._last_t)
        try:
            # Checked without its pixels: a frame drawn on demand draws only what is read.
            check_rgb_frame(frame.layout(), self.intrinsics)
        except FrameError as exc:
            return MarkerState(frame.t_s, TrackStatus.INVALID, lost_for_s=lost_for,
                               message=str(exc))
        found, search, reason = self._find(frame)
        if found is None:
            if reason:
                return MarkerState(frame.t_s, TrackStatus.REJECTED, lost_for_s=lost_for,
                                   search=search, message=reason)
            return MarkerState(frame.t_s, TrackStatus.LOST, lost_for_s=lost_for)
        pose = self._solver.solve(found, self._last)
        if not pose.valid:
            return MarkerState(frame.t_s, TrackStatus.REJECTED, lost_for_s=lost_for,
                               search=search, message="no finite pose from the corners")
        reason = self._beyond_reach(pose)
        if reason:  # not counted towards re-acquisition: no wait makes it the finger's
            return MarkerState(frame.t_s, TrackStatus.REJECTED, lost_for_s=lost_for,
                               search=search, message=reason)
        implausible = self._implausible(pose, frame.t_s)
        if implausible:
            self._rejections += 1
            if self._rejections <= self.reacquire_after:
                return MarkerState(frame.t_s, TrackStatus.REJECTED, lost_for_s=lost_for,
                                   search=search, message="implausible jump since last frame")
        if self._rejections and self._last is not None:
            # Accepted after frames rejected as jumps (now plausible, the speed bound having
            # grown with the time since the last pose, or after reacquire_after of them).
            step = pose.tvec_m - self._last.tvec_m
            rejected = self._rejections - 1 if implausible else self._rejections
            reason = (f"re-acquired {1e3 * math.sqrt(float(step @ step)):.1f} mm from the "
                      f"last pose after {rejected} rejected frames")
            if self._zero is None:  # the samples so far are of the marker where it was
                self._zero_samples = []
        # The corners' velocity is known only from frames tracked one after the other: after
        # a full-frame search or a re-acquisition the last corners are from elsewhere.
        continuous = search != "full" and self._rejections == 0
        self._rejections = 0
        self._previous_corners = (self._last.corners_px if continuous and self._last is not None
                                  else None)
        self._last, self._last_t = pose, frame.t_s
        if self._zero is None:
            self._zero_samples.append(pose)
            if len(self._zero_samples) < self.zero_frames:
                return MarkerState(frame.t_s, TrackStatus.ZEROING, pose, search=search,
                                   message=reason)
            rot0 = mean_rotation([p.rotation for p in self._zero_samples])
            t0 = np.mean([p.tvec_m for p in self._zero_samples], axis=0)
            self._zero = (rot0, t0)
        rot0, t0 = self._zero
        delta_r = np.asarray(cv2.Rodrigues(pose.rotation @ rot0.T)[0], dtype=np.float64).ravel()
        return MarkerState(frame.t_s, TrackStatus.TRACKING, pose, pose.tvec_m - t0, delta_r,
                           search=search, message=reason)

    def _find(self, frame: Frame) -> tuple[FloatArray | None, Search, str]:
        """The marker's corners, how they were found, and why none were if one was seen.

        Between full-frame searches only the marker's neighbourhood is read
        (:meth:`Frame.region`).
        """
        if self._last is not None:
            if self.edge_refine and self._followed + 1 < self.verify_every:
                followed = self._follow_edges(frame, self._last.corners_px)
                if followed is not None:
                    self._followed += 1
                    return followed, "edges", ""
            found = self._search_roi(frame, self._last.corners_px)
            if found is not None:
                self._followed = 0
                return found, "roi", ""
        gray = to_gray(np.asarray(frame.image, dtype=np.uint8))
        det, reason = self._pick(detect_markers(gray, self._full))
        if det is None:
            return None, ("full" if reason else "none"), reason
        self._followed = 0
        return self._refined(gray, det.corners_px, (0, 0)), "full", ""

    def _pick(self, found: list[MarkerDetection], origin: tuple[int, int] = (0, 0)
              ) -> tuple[MarkerDetection | None, str]:
        """The tracked marker among detections whose corners are relative to ``origin``.

        Of several with the tracked id (a second marker printed with it, 25 mm
        away on the next finger or the bench), the one whose centre is nearest
        the last accepted corners' centre, or where ``home_m`` projects before
        any was accepted; with neither, none, and the reason.
        """
        mine = [d for d in found if d.marker_id == self.marker.marker_id]
        if len(mine) < 2:
            return (mine[0] if mine else None), ""
        if self._last is not None:
            ref = self._last.corners_px.mean(axis=0) - np.asarray(origin, dtype=np.float64)
        elif self._home_px is not None:
            ref = self._home_px - np.asarray(origin, dtype=np.float64)
        else:
            return None, (f"{len(mine)} markers with id {self.marker.marker_id} in view and "
                          f"none tracked yet: give home_m to tell the finger's apart")

        def distance_px(det: MarkerDetection) -> float:
            return float(np.linalg.norm(det.corners_px.mean(axis=0) - ref))

        return min(mine, key=distance_px), ""

    def _follow_edges(self, frame: Frame, corners: FloatArray) -> FloatArray | None:
        """Re-fit the edges around where the marker is expected, without the detector."""
        predicted = corners
        if self._previous_corners is not None:  # constant velocity
            predicted = 2.0 * corners - self._previous_corners
        h, w = self.intrinsics.shape
        xs, ys = predicted[:, 0].tolist(), predicted[:, 1].tolist()
        pad = _PROFILE_HALF_PX + 4.0
        x0, y0 = max(int(min(xs) - pad), 0), max(int(min(ys) - pad), 0)
        x1, y1 = min(int(max(xs) + pad) + 1, w), min(int(max(ys) + pad) + 1, h)
        if x1 - x0 < 16 or y1 - y0 < 16:  # predicted out of the frame
            return None
        gray = to_gray(_pixels(frame, y0, y1, x0, x1))
        shift = np.array([x0, y0], dtype=np.float64)
        fitted = self._fit_edges(gray, predicted - shift, (x0, y0))
        return None if fitted is None else fitted + shift

    def _fit_edges(self, gray: GrayImage, guess: FloatArray, origin: tuple[int, int]
                   ) -> FloatArray | None:
        """The edge fit from ``guess``; again from its result while it still moves.

        The edge profiles reach ``_PROFILE_HALF_PX`` either side of the guess,
        so a guess a few pixels off (a constant-velocity prediction, a corner
        the region-of-interest detector placed 3 px off) fits a biased line
        that moves the corner only part of the way.  A first pass that moved a
        corner by half a pixel or more is a better guess, not the answer: the
        fit is repeated until a pass moves no corner by a twentieth of a pixel
        (four passes at most).  A first pass under half a pixel is kept.
        """
        for passes in range(_EDGE_PASSES):
            fitted = refine_corners_by_edges(gray, guess, self.intrinsics, origin, self._modules)
            if fitted is None:
                return None
            moved = max(abs(a - b) for a, b in zip(fitted.ravel().tolist(),
                                                   guess.ravel().tolist(), strict=True))
            guess = fitted
            if moved < (_FIRST_PASS_PX if passes == 0 else _CONVERGED_PX):
                break
        return guess

    def _search_roi(self, frame: Frame, corners: FloatArray) -> FloatArray | None:
        h, w = self.intrinsics.shape
        xs, ys = corners[:, 0].tolist(), corners[:, 1].tolist()
        lo_x, hi_x, lo_y, hi_y = min(xs), max(xs), min(ys), max(ys)
        pad = self.roi_margin * max(hi_x - lo_x, hi_y - lo_y) + 4.0
        x0, y0 = max(int(lo_x - pad), 0), max(int(lo_y - pad), 0)
        x1, y1 = min(int(hi_x + pad) + 1, w), min(int(hi_y + pad) + 1, h)
        if x1 - x0 < 16 or y1 - y0 < 16:
            return None
        gray = to_gray(_pixels(frame, y0, y1, x0, x1))
        det, _ = self._pick(detect_markers(gray, self._roi), (x0, y0))
        return None if det is None else self._refined(gray, det.corners_px, (x0, y0))

    def _refined(self, gray: GrayImage, corners: FloatArray, origin: tuple[int, int]) -> FloatArray:
        if self.edge_refine:
            refined = self._fit_edges(gray, corners, origin)
            if refined is not None:
                corners = refined
        return corners + np.asarray(origin, dtype=np.float64)

    def _implausible(self, pose: MarkerPose, t_s: float) -> bool:
        """Whether ``pose`` is further from the last accepted one than the marker moves."""
        if self._last is None or self._last_t is None:
            return False
        dt = max(t_s - self._last_t, 0.0)
        step = pose.tvec_m - self._last.tvec_m
        step_m = math.sqrt(float(step @ step))
        cos_step = 0.5 * (float((pose.rotation * self._last.rotation).sum()) - 1.0)
        step_rad = math.acos(min(1.0, max(-1.0, cos_step)))
        return step_m > 1e-3 + self.max_speed_m_s * dt or step_rad > 0.05 + self.max_rate_rad_s * dt

    def _beyond_reach(self, pose: MarkerPose) -> str:
        """Why ``pose`` cannot be the finger's marker (further than the mount's
        ``max_travel_m`` from the zero pose, from the first frame taken towards it while
        that is averaged, or before any from ``home_m``); empty if it can be."""
        if self._zero is not None:
            home, what = self._zero[1], "its zero pose"
        elif self._zero_samples:
            home, what = self._zero_samples[0].tvec_m, "its zero pose"
        elif self.home_m is not None:
            home, what = np.asarray(self.home_m), "where the rig puts the unbent finger's"
        else:
            return ""
        step = pose.tvec_m - home
        travel_m = math.sqrt(float(step @ step))
        if travel_m <= self.marker.max_travel_m:
            return ""
        return (f"marker {1e3 * travel_m:.1f} mm from {what}, beyond the "
                f"{1e3 * self.marker.max_travel_m:g} mm a bent finger reaches (the rig's "
                f"marker max_travel_mm): another marker of id {self.marker.marker_id}?")


def warm_up() -> None:
    """Load the corner refinement's compiled code now rather than at the first marker.

    The first refinement loads its machine code from numba's cache (about a
    quarter of a second); in wall-clock time, on an MCU whose watchdog wants
    a command every 200 ms, that first frame must not be the one to pay it.
    A drawn marker of known corners is refined once.
    """
    side, pad = 60, 20
    marker = cv2.aruco.generateImageMarker(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), 0, side)
    gray = np.full((side + 2 * pad, side + 2 * pad), 255, dtype=np.uint8)
    gray[pad:pad + side, pad:pad + side] = marker
    lo, hi = pad - 0.5, pad + side - 0.5
    corners = np.array([[lo, lo], [hi, lo], [hi, hi], [lo, hi]], dtype=np.float64)
    refine_corners_by_edges(gray, corners, modules=6)
