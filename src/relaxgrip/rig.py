"""Geometry of a gripper rig: cameras, marker, fingers, and the frames that join them.

The twin renders its camera frames from this description and perception
interprets frames with it, so the two can never disagree about where a camera
looks.  A real rig is described by the same dataclasses (loaded from a TOML
file by the hardware layer).

Frames (right-handed; lengths in m; transforms are 4×4 homogeneous matrices
named ``a2b``: they map points given in frame ``a`` to frame ``b``):

* **gripper** ``G``: origin at the base, midway between the finger roots;
  ``x`` forward along the fingers, ``y`` towards finger 1, ``z`` up.
* **finger** ``F_j``: origin at finger ``j``'s root on its centre line; ``x``
  along the finger to the tip, ``z`` outwards, away from the object (the
  direction in which a grasp deflects the finger), ``y = z × x``.
* **RGB camera** ``C`` (OpenCV): ``x`` right, ``y`` down, ``z`` along the
  optical axis.  It sits at the root of the marker finger and moves with it,
  looking along the finger through its open skeleton.
* **marker** ``M`` (OpenCV ArUco): origin at the marker centre, ``x`` right
  and ``y`` up in the marker image, ``z`` out of the marker towards the camera.
* **infrared camera** ``I`` (OpenCV): fixed on the gripper base, looking
  forward and down on both fingers.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from relaxgrip.errors import InputError

FloatArray = NDArray[np.float64]

__all__ = [
    "ARUCO_DICTIONARIES",
    "MAX_DIST_COEFF",
    "MAX_FOCAL_PX",
    "CameraIntrinsics",
    "FingerGeometry",
    "IrCameraMount",
    "MarkerMount",
    "RgbCameraMount",
    "RigGeometry",
    "bend_profile_m",
    "invert_transform",
    "rotation_x",
    "rotation_y",
    "rotation_z",
    "transform_from",
    "transform_points",
]

#: Largest focal length accepted (pixels): a field of view of 0.04° across 640 pixels.
MAX_FOCAL_PX = 1e6
#: The largest distortion coefficient taken: calibrated lenses, even OpenCV's 8-coefficient
#: rational model, give coefficients of tens at most; beyond this the polynomial describes no lens.
MAX_DIST_COEFF = 1000.0
#: How far off axis an image edge may undistort to (tan 89°): a pinhole camera sees less than 90°.
MAX_NORMALIZED = math.tan(math.radians(89.0))

#: Dictionary names accepted for markers (OpenCV's ``DICT_*`` constants, without the prefix).
ARUCO_DICTIONARIES: tuple[str, ...] = tuple(
    sorted(name[5:] for name in dir(cv2.aruco) if name.startswith("DICT_"))
)


def rotation_x(angle_rad: float) -> FloatArray:
    """Rotation matrix about ``x`` by ``angle_rad`` (right-hand rule)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(angle_rad: float) -> FloatArray:
    """Rotation matrix about ``y`` by ``angle_rad`` (right-hand rule)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(angle_rad: float) -> FloatArray:
    """Rotation matrix about ``z`` by ``angle_rad`` (right-hand rule)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def transform_from(rotation: ArrayLike, translation_m: ArrayLike) -> FloatArray:
    """4×4 homogeneous transform ``[R t; 0 1]``."""
    out = np.eye(4)
    out[:3, :3] = np.asarray(rotation, dtype=np.float64)
    out[:3, 3] = np.asarray(translation_m, dtype=np.float64)
    return out


def invert_transform(a2b: FloatArray) -> FloatArray:
    """Inverse of a rigid transform: ``b2a``."""
    rot = a2b[:3, :3]
    return transform_from(rot.T, -rot.T @ a2b[:3, 3])


def transform_points(a2b: FloatArray, points_m: ArrayLike) -> FloatArray:
    """Apply ``a2b`` to points of shape ``(..., 3)``."""
    p = np.asarray(points_m, dtype=np.float64)
    out: FloatArray = p @ a2b[:3, :3].T + a2b[:3, 3]
    return out


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics with optional OpenCV distortion.

    Attributes
    ----------
    width_px, height_px : int
        Image size (pixels).
    fx_px, fy_px : float
        Focal lengths (pixels).
    cx_px, cy_px : float
        Principal point (pixels; pixel centres at integer coordinates).
    dist : tuple of float
        OpenCV distortion coefficients ``(k1, k2, p1, p2[, k3, ...])``; empty
        for none.
    """

    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    dist: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.width_px < 1 or self.height_px < 1:
            raise InputError(f"image size must be positive, got {self.width_px}x{self.height_px}")
        for name in ("fx_px", "fy_px"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 1.0 <= value <= MAX_FOCAL_PX):
                raise InputError(f"{name} must be 1 to {MAX_FOCAL_PX:.0e} pixels, got {value}")
        for name, size in (("cx_px", self.width_px), ("cy_px", self.height_px)):
            value = getattr(self, name)
            if not (math.isfinite(value) and -size <= value <= 2 * size):
                raise InputError(f"{name} must lie within the image or one image size off it "
                                 f"({-size} to {2 * size} px), got {value}")
        if len(self.dist) not in (0, 4, 5, 8, 12, 14):
            raise InputError(
                f"distortion needs 4, 5, 8, 12 or 14 coefficients, got {len(self.dist)}"
            )
        if not all(math.isfinite(d) and abs(d) <= MAX_DIST_COEFF for d in self.dist):
            raise InputError(f"distortion coefficients must be finite and within "
                             f"±{MAX_DIST_COEFF:g}, got {_coefficients(self.dist)}")
        if self.dist and not self._edges_undistort():
            raise InputError(f"distortion {_coefficients(self.dist)} undistorts the image's "
                             "edges to no pinhole view (non-finite, folded or over 89° off "
                             "axis): check the coefficients")

    def _edges_undistort(self) -> bool:
        """Whether the image's corners and edge midpoints undistort to a pinhole view.

        They must come out finite, less than 89° off axis, and in their order
        (the left edge left of the right one, the top above the bottom);
        otherwise the edge fit and the pose would work on non-finite or
        collapsed points.
        """
        w, h = self.width_px - 1.0, self.height_px - 1.0
        border = np.array([[0, 0], [w / 2, 0], [w, 0], [w, h / 2], [w, h], [w / 2, h], [0, h],
                           [0, h / 2]])
        with np.errstate(all="ignore"):
            x, y = self.normalized(border).T
        # left edge (0, 6, 7) left of the right edge (2, 3, 4); top (0, 1, 2) above bottom (4, 5, 6)
        return bool(np.all(np.isfinite(x)) and np.all(np.isfinite(y))
                    and float(np.abs(np.concatenate([x, y])).max()) <= MAX_NORMALIZED
                    and float(x[[0, 6, 7]].max()) < float(x[[2, 3, 4]].min())
                    and float(y[[0, 1, 2]].max()) < float(y[[4, 5, 6]].min()))

    @classmethod
    def centred(
        cls, width_px: int, height_px: int, fx_px: float, fy_px: float | None = None
    ) -> CameraIntrinsics:
        """Intrinsics with the principal point at the image centre."""
        return cls(
            width_px, height_px, fx_px, fx_px if fy_px is None else fy_px,
            (width_px - 1) / 2.0, (height_px - 1) / 2.0,
        )

    @property
    def matrix(self) -> FloatArray:
        """Camera matrix ``K`` (3×3)."""
        return np.array(
            [[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]]
        )

    @property
    def dist_coeffs(self) -> FloatArray | None:
        """Distortion coefficients for OpenCV, or ``None``."""
        return np.asarray(self.dist, dtype=np.float64) if self.dist else None

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)`` of a frame."""
        return self.height_px, self.width_px

    def project(self, points_cam_m: ArrayLike) -> FloatArray:
        """Project camera-frame points ``(..., 3)`` to pixels ``(..., 2)``."""
        p = np.asarray(points_cam_m, dtype=np.float64)
        flat = p.reshape(-1, 3)
        if self.dist:
            px, _ = cv2.projectPoints(flat, np.zeros(3), np.zeros(3), self.matrix, self.dist_coeffs)
            out: FloatArray = px.reshape(*p.shape[:-1], 2).astype(np.float64)
            return out
        uv = flat[:, :2] / flat[:, 2:3]
        out = uv * np.array([self.fx_px, self.fy_px]) + np.array([self.cx_px, self.cy_px])
        return out.reshape(*p.shape[:-1], 2)

    def normalized(self, pixels: ArrayLike) -> FloatArray:
        """Undistorted normalised image coordinates ``(x/z, y/z)`` of pixels ``(..., 2)``."""
        px = np.asarray(pixels, dtype=np.float64)
        flat = px.reshape(-1, 1, 2)
        if self.dist:
            out: FloatArray = cv2.undistortPoints(flat, self.matrix, self.dist_coeffs).astype(
                np.float64
            )
        else:
            centre = np.array([self.cx_px, self.cy_px])
            out = (flat - centre) / np.array([self.fx_px, self.fy_px])
        return out.reshape(px.shape)


@dataclass(frozen=True)
class FingerGeometry:
    """Outer shape of a finger, as the cameras see it.

    Attributes
    ----------
    length_m : float
        Root to tip (m).
    thickness_m : float
        Contact face to back face (m).
    height_m : float
        Extent of the finger along the gripper's ``z``: contact face height (m).
    beam_positions_m : tuple of float
        Where the SMP beams' temperatures are read along the finger (m from
        the root): the centres of the infrared regions of interest.
    contact_m : float
        Where an object is usually held along the finger (m from the root; the
        paper's sphere at 80 mm): the finger's temperature is read with each
        beam weighted by how much the finger bends there under a load at this
        point (:attr:`bending_weights`).
    """

    length_m: float = 0.110
    thickness_m: float = 0.012
    height_m: float = 0.020
    beam_positions_m: tuple[float, ...] = (0.011, 0.033, 0.055, 0.077, 0.099)
    contact_m: float = 0.080

    def __post_init__(self) -> None:
        if min(self.length_m, self.thickness_m, self.height_m) <= 0:
            raise InputError("finger length, thickness and height must be > 0")
        if not self.beam_positions_m or not all(
            0.0 <= x <= self.length_m for x in self.beam_positions_m
        ):
            raise InputError("beam positions must lie on the finger, within [0, length]")
        if not 0.0 < self.contact_m <= self.length_m:
            raise InputError(f"contact position {self.contact_m} m is outside the finger "
                             f"(0, {self.length_m}]")

    @property
    def bending_weights(self) -> tuple[float, ...]:
        """Each beam's weight in the finger's temperature (they sum to 1).

        A load at :attr:`contact_m` bends a section at ``x`` by a moment
        ``F (contact_m - x)`` and that section's share of the contact's
        deflection goes as ``(contact_m - x)^2`` (over its bending stiffness):
        the sections near the root set how the finger relaxes, those beyond
        the contact none.  A mean of all the beams lags the root when heaters
        warm the finger (its tip trails by 5 K in a 40 -> 55 °C ramp), and the
        relaxation models read it as a cooler finger.  Beams beyond the
        contact weigh nothing; if every beam is, they weigh alike.
        """
        moments = [max(0.0, self.contact_m - x) ** 2 for x in self.beam_positions_m]
        total = sum(moments)
        if total <= 0.0:
            return (1.0 / len(moments),) * len(moments)
        return tuple(m / total for m in moments)


@dataclass(frozen=True)
class MarkerMount:
    """The ArUco marker on its tab inside the finger.

    The tab stands in the finger's open skeleton facing the camera, tilted
    about the bending axis so the camera sees the marker obliquely: an
    oblique view makes the finger's bending rotation visible to first order,
    where a face-on square only shows it through perspective.

    Attributes
    ----------
    dictionary : str
        OpenCV dictionary name without ``DICT_`` (e.g. ``"4X4_50"``).
    marker_id : int
        Marker id in the dictionary.
    size_m : float
        Side of the black square (m).
    position_m : float
        Where the tab is fixed along the finger (m from the root).
    tilt_deg : float
        Tab tilt about the finger's bending axis (degrees; 0 faces the camera).
    max_travel_m : float
        Farthest the bent finger carries the marker from its zero pose (m):
        perception rejects a marker of this id further away, however long it
        stays (another marker printed with the same id).  The twin's finger
        moves it 11 mm under the 12 N force limit and 15 mm under 20 N, hot
        and loaded at the tip; a softer finger needs more.
    """

    dictionary: str = "4X4_50"
    marker_id: int = 0
    size_m: float = 0.012
    position_m: float = 0.060
    tilt_deg: float = 30.0
    max_travel_m: float = 0.020

    def __post_init__(self) -> None:
        if self.dictionary not in ARUCO_DICTIONARIES:
            raise InputError(
                f"unknown ArUco dictionary {self.dictionary!r}; "
                f"known: {', '.join(ARUCO_DICTIONARIES)}"
            )
        if not self.size_m > 0:
            raise InputError(f"marker size must be > 0 m, got {self.size_m}")
        if not abs(self.tilt_deg) < 75.0:
            raise InputError(f"marker tilt must be within ±75°, got {self.tilt_deg}")
        # Finite: a rig is stored as JSON in recordings, where inf is no number.
        if not 0.0 < self.max_travel_m < math.inf:
            raise InputError(f"marker travel must be > 0 m and finite, got {self.max_travel_m}")

    @property
    def aruco_dictionary(self) -> cv2.aruco.Dictionary:
        """The OpenCV dictionary object."""
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, "DICT_" + self.dictionary))

    @property
    def object_points_m(self) -> FloatArray:
        """Marker corners in the marker frame, in OpenCV's order for ``SOLVEPNP_IPPE_SQUARE``."""
        h = self.size_m / 2.0
        return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])

    def marker2finger(self, deflection_m: float = 0.0, slope_rad: float = 0.0) -> FloatArray:
        """Pose of the marker in its finger's frame for a bent finger.

        Parameters
        ----------
        deflection_m : float
            Finger deflection ``z`` at the tab (m).
        slope_rad : float
            Slope angle of the finger at the tab (rad): the beam's ``x`` axis
            turns towards ``+z`` by this angle.

        Returns
        -------
        ndarray, shape (4, 4)
            ``marker2finger``.
        """
        bend = rotation_y(-slope_rad)
        return transform_from(bend @ self._rest, [self.position_m, 0.0, deflection_m])

    @functools.cached_property
    def _rest(self) -> FloatArray:
        """The marker's orientation on the unbent finger (the renderer asks every frame)."""
        # Unbent, the marker faces the root: its x along the finger's z,
        # its y along the finger's y, its normal towards -x.
        facing = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
        rest: FloatArray = rotation_y(math.radians(self.tilt_deg)) @ facing
        rest.flags.writeable = False
        return rest


@dataclass(frozen=True)
class RgbCameraMount:
    """The RGB camera at the root of the marker finger.

    Attributes
    ----------
    intrinsics : CameraIntrinsics
        Default 640×480, fx = fy = 600 px.
    rate_hz : float
        Frame rate (Hz).
    position_m : tuple of float
        Optical centre in the finger frame (m).
    toe_in_deg : float
        Rotation of the optical axis from the finger's ``x`` towards the
        object side (degrees), so that the grasp region is in view.
    """

    intrinsics: CameraIntrinsics = field(
        default_factory=lambda: CameraIntrinsics.centred(640, 480, 600.0)
    )
    rate_hz: float = 30.0
    position_m: tuple[float, float, float] = (-0.025, 0.0, 0.0)
    toe_in_deg: float = 10.0

    @property
    def cam2finger(self) -> FloatArray:
        """Camera frame to finger frame (read-only: every frame's render and pose use it)."""
        return _camera_mount(tuple(self.position_m), self.toe_in_deg)[0]

    @property
    def finger2cam(self) -> FloatArray:
        """Finger frame to camera frame (read-only)."""
        return _camera_mount(tuple(self.position_m), self.toe_in_deg)[1]


@functools.lru_cache(maxsize=16)
def _camera_mount(position_m: tuple[float, ...], toe_in_deg: float
                  ) -> tuple[FloatArray, FloatArray]:
    """The RGB camera's ``cam2finger`` and ``finger2cam`` for its mount, built once."""
    # Looking along the finger: camera z = finger x, camera x = finger z.
    along = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
    # Turning towards the object (-z of the finger) is a rotation about the finger's y.
    toe = rotation_y(math.radians(toe_in_deg))
    cam2finger = transform_from(toe @ along, position_m)
    finger2cam = invert_transform(cam2finger)
    for m in (cam2finger, finger2cam):
        m.flags.writeable = False
    return cam2finger, finger2cam


@dataclass(frozen=True)
class IrCameraMount:
    """The infrared camera on the gripper base, looking down on both fingers' top faces.

    Attributes
    ----------
    intrinsics : CameraIntrinsics
        Default 256×192 with a 90° horizontal field of view.
    rate_hz : float
        Frame rate (Hz).
    position_m : tuple of float
        Optical centre in the gripper frame (m).
    pitch_down_deg : float
        Downward tilt of the optical axis from the gripper's ``x`` (degrees).
    """

    intrinsics: CameraIntrinsics = field(
        default_factory=lambda: CameraIntrinsics.centred(256, 192, 128.0)
    )
    rate_hz: float = 1.0
    position_m: tuple[float, float, float] = (-0.070, 0.0, 0.060)
    pitch_down_deg: float = 25.0

    @property
    def cam2gripper(self) -> FloatArray:
        """Camera frame to gripper frame."""
        # Looking forward: camera z = gripper x, camera x = -gripper y (right in the
        # image is finger 0's side), camera y = -gripper z (down).
        forward = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        pitch = rotation_y(math.radians(self.pitch_down_deg))
        return transform_from(pitch @ forward, self.position_m)

    @property
    def gripper2cam(self) -> FloatArray:
        """Gripper frame to camera frame."""
        return invert_transform(self.cam2gripper)


@dataclass(frozen=True)
class RigGeometry:
    """Everything perception needs to know about where things are.

    Attributes
    ----------
    finger : FingerGeometry
        Shape of each finger.
    marker : MarkerMount
        The marker on finger ``marker_finger``.
    rgb : RgbCameraMount
        RGB camera at the root of finger ``marker_finger``.
    ir : IrCameraMount
        Infrared camera on the base.
    open_aperture_m : float
        Gap between the contact faces at motor position 0 (m).
    marker_finger : int
        Finger (0 or 1) that carries the marker and the RGB camera.
    ir_follow_bend : bool
        Read the infrared windows on the fingers as bent by the load
        (:func:`bend_profile_m` from the marker's deflection and slope), not
        where the unloaded fingers are.  A real finger moves its distal beams
        5 mm at 5 N and 40 °C, 12 mm at 8 N and 55 °C: more than the
        windows' room on the 12 mm face, so a rig reads them beside the
        finger without it.  On by default, as the twin draws the bend
        (``IrSensorConfig.draw_bend``) and a rig file reads it (``[ir]
        follow_bend``); off only for frames of fingers drawn unbent.
    marker_zero_m : tuple of float, optional
        Where the marker was measured to be in the RGB camera frame with the
        fingers unloaded and the heaters off (m; the rig file's ``[zero_pose]``,
        ``relaxgrip zero-pose``); None: where the mounts put it
        (:meth:`marker2cam`).  Perception takes it as the marker's home
        (:attr:`marker_home_m`).
    """

    finger: FingerGeometry = field(default_factory=FingerGeometry)
    marker: MarkerMount = field(default_factory=MarkerMount)
    rgb: RgbCameraMount = field(default_factory=RgbCameraMount)
    ir: IrCameraMount = field(default_factory=IrCameraMount)
    open_aperture_m: float = 0.150
    marker_finger: int = 0
    ir_follow_bend: bool = True
    marker_zero_m: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.marker_zero_m is not None:
            zero = tuple(float(v) for v in self.marker_zero_m)
            if len(zero) != 3 or not all(math.isfinite(v) for v in zero) or zero[2] <= 0.0:
                raise InputError(f"the marker's zero pose must be a point in front of the RGB "
                                 f"camera (x, y, z > 0 m), got {self.marker_zero_m}")
            object.__setattr__(self, "marker_zero_m", zero)
        if self.marker_finger not in (0, 1):
            raise InputError(f"marker_finger must be 0 or 1, got {self.marker_finger}")
        if not 0.0 < self.marker.position_m <= self.finger.length_m:
            raise InputError(
                f"marker position {self.marker.position_m} m is outside the finger "
                f"(0, {self.finger.length_m}]"
            )

    @property
    def marker_home_m(self) -> tuple[float, float, float]:
        """Where the unloaded finger's marker is in the RGB camera frame (m): as measured
        (:attr:`marker_zero_m`), else as the mounts put it."""
        if self.marker_zero_m is not None:
            return self.marker_zero_m
        x, y, z = (float(v) for v in self.marker2cam()[:3, 3])
        return x, y, z

    def aperture_m(self, motor_position_mm: float) -> float:
        """Gap between the undeflected contact faces at an encoder position (m)."""
        return self.open_aperture_m - motor_position_mm * 1e-3

    def finger2gripper(self, j: int, aperture_m: float) -> FloatArray:
        """Finger ``j``'s frame in the gripper frame at a given aperture."""
        side = -1.0 if j == 0 else 1.0
        # Outward (finger z) is -y for finger 0 and +y for finger 1; finger y = z × x.
        rot = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, side], [0.0, -side, 0.0]])
        offset = side * (0.5 * aperture_m + 0.5 * self.finger.thickness_m)
        return transform_from(rot, [0.0, offset, 0.0])

    def marker2cam(self, deflection_m: float = 0.0, slope_rad: float = 0.0) -> FloatArray:
        """Marker pose in the RGB camera frame for a bent marker finger."""
        out: FloatArray = self.rgb.finger2cam @ self.marker.marker2finger(deflection_m, slope_rad)
        return out

    def top_points_gripper(
        self, j: int, aperture_m: float, along_m: ArrayLike, across_m: ArrayLike = 0.0,
        bend_m: ArrayLike = 0.0,
    ) -> FloatArray:
        """Points on finger ``j``'s top face, the face the infrared camera reads, in ``G``.

        The top face is where the base-mounted thermal camera sees the SMP
        beams without the grasped object in the way (an object between the
        fingers would hide their contact faces).

        Parameters
        ----------
        j : int
            Finger.
        aperture_m : float
            Current aperture (m).
        along_m : array_like
            Positions along the finger (m from the root).
        across_m : array_like
            Positions across the top face from its centre line, towards the
            finger's outside (m), within ``±thickness_m / 2``.
        bend_m : array_like
            The finger's deflection outwards at ``along_m`` (m; 0: unbent),
            e.g. :func:`bend_profile_m`.

        Returns
        -------
        ndarray, shape (..., 3)
            Points (m), broadcast over ``along_m``, ``across_m`` and ``bend_m``.
        """
        along, across, bend = np.broadcast_arrays(
            np.asarray(along_m, dtype=np.float64), np.asarray(across_m, dtype=np.float64),
            np.asarray(bend_m, dtype=np.float64))
        side = -1.0 if j == 0 else 1.0
        y = side * (0.5 * aperture_m + 0.5 * self.finger.thickness_m + across + bend)
        return np.stack([along, y, np.full_like(along, 0.5 * self.finger.height_m)], axis=-1)


def bend_profile_m(along_m: ArrayLike, marker_m: float, deflection_m: float,
                   slope_rad: float) -> FloatArray:
    """A bent finger's deflection outwards along it, from its deflection and slope at one
    point (the marker's tab).

    Root to the tab: the cubic of a clamped beam (no deflection or slope at
    the root) with the tab's deflection and slope, exact for a uniform finger
    loaded beyond the tab; beyond the tab: the tangent there, exact beyond the
    load.  On the twin's finger it is within 4 % of the deflection at every
    beam loaded at 80 mm (the default contact) and within 9 % loaded at
    100 mm, uniform in temperature or graded.

    Parameters
    ----------
    along_m : array_like
        Positions along the finger (m from the root).
    marker_m : float
        Where deflection and slope are known (m from the root, > 0).
    deflection_m, slope_rad : float
        Deflection (m, outwards) and slope (rad) there.
    """
    x = np.asarray(along_m, dtype=np.float64)
    u = np.clip(x, 0.0, marker_m) / marker_m
    d, sl = deflection_m, slope_rad * marker_m
    cubic = (3.0 * d - sl) * u**2 + (sl - 2.0 * d) * u**3
    out: FloatArray = np.where(x > marker_m, d + slope_rad * (x - marker_m), cubic)
    return out


def _coefficients(dist: tuple[float, ...]) -> str:
    """``0,0,1000,0``: distortion coefficients as a user writes them."""
    return ",".join(f"{d:g}" for d in dist)
