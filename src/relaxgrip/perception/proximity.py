"""Visual proximity: how far ahead an object stands, from its size in the RGB frame.

During the approach the object grows in the marker camera's view.  A target
is described by what the operator (or the task) knows of it: its width and
its colour.  The estimator segments pixels of that colour (the angle between
pixel and target colour in RGB space, so shading does not matter, and a
brightness ratio, so that a white cup is not confused with a grey background),
keeps the largest blob outside the marker tab, and turns its angular width
into a range: a sphere or cylinder of width ``W`` spanning ``theta`` is at
``W / (2 sin(theta / 2))``.  The blob's centre ray at that range gives the
object's position; its distance ahead of the grasp position along the
fingers is the approach cue.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import Frame
from relaxgrip.errors import InputError
from relaxgrip.perception.frames import check_rgb_frame
from relaxgrip.rig import RigGeometry, transform_points

FloatArray = NDArray[np.float64]

__all__ = ["Proximity", "ProximityEstimator", "ProximityTarget"]

#: Segmentation runs at this fraction of the resolution (the approach cue
#: needs centimetres, not sub-pixels).
_SCALE = 0.5


@dataclass(frozen=True)
class ProximityTarget:
    """What is known of the object to approach.

    Attributes
    ----------
    width_m : float
        Width of the object across the view (m).
    color_rgb : tuple of int
        Its colour under nominal light (0-255 per channel).
    max_angle_deg : float
        Largest angle between a pixel's colour and the target colour, as RGB
        vectors, that still counts as the target.
    brightness : tuple of float
        Accepted range of pixel brightness relative to the target's.
    grasp_position_m : float
        Where along the fingers the object's centre should end up (m from the root).
    """

    width_m: float
    color_rgb: tuple[int, int, int]
    max_angle_deg: float = 8.0
    brightness: tuple[float, float] = (0.6, 1.35)
    grasp_position_m: float = 0.080

    def __post_init__(self) -> None:
        if not self.width_m > 0:
            raise InputError(f"target width must be > 0 m, got {self.width_m}")
        if sum(self.color_rgb) <= 0:
            raise InputError("target colour must not be black")


@dataclass(frozen=True)
class Proximity:
    """The proximity cue from one frame.

    Attributes
    ----------
    t_s : float
        Frame time (s).
    found : bool
        Whether the target was seen.
    range_m : float
        Distance from the camera to the object's centre (m); nan if not found.
    ahead_m : float
        How far the object's centre is beyond its grasp position along the
        fingers (m); 0 when it is where the grasp wants it; nan if not found.
    bbox_px : tuple of int
        ``(x, y, w, h)`` of the blob in full-resolution pixels.
    position_m : float
        Where the object's centre is along the fingers (m from their root):
        ``ahead_m`` plus the grasp position; nan if not found.
    """

    t_s: float
    found: bool
    range_m: float = math.nan
    ahead_m: float = math.nan
    bbox_px: tuple[int, int, int, int] = (0, 0, 0, 0)
    position_m: float = math.nan


class ProximityEstimator:
    """Estimate the target's distance from RGB frames.

    Parameters
    ----------
    rig : RigGeometry
        The RGB camera and its mount.
    target : ProximityTarget
        The object to look for.
    min_area_px : int
        Smallest blob, in full-resolution pixels, taken for the target.
    """

    def __init__(self, rig: RigGeometry, target: ProximityTarget, min_area_px: int = 200) -> None:
        self.rig = rig
        self.target = target
        self.min_area_px = min_area_px
        colour = np.asarray(target.color_rgb, dtype=np.float32)
        self._unit = colour / float(np.linalg.norm(colour))
        self._norm = float(np.linalg.norm(colour))
        self._cos_max = math.cos(math.radians(target.max_angle_deg))

    def estimate(
        self, frame: Frame, motor_position_mm: float, exclude_px: FloatArray | None = None
    ) -> Proximity:
        """Find the target in a frame.

        Parameters
        ----------
        frame : Frame
            RGB frame.
        motor_position_mm : float
            Encoder position (sets where the marker finger, and so the camera, is).
        exclude_px : ndarray, shape (n, 2), optional
            Outline to mask out (the marker tab, whose white might match a white target).

        Returns
        -------
        Proximity

        Raises
        ------
        FrameError
            On an unusable frame.
        """
        intr = self.rig.rgb.intrinsics
        image = check_rgb_frame(frame.image, intr)
        if image.ndim != 3:
            return Proximity(frame.t_s, False)
        small = cv2.resize(image, None, fx=_SCALE, fy=_SCALE, interpolation=cv2.INTER_AREA)
        pixels = small.reshape(-1, 3).astype(np.float32)
        along = pixels @ self._unit
        norm = np.sqrt(np.einsum("ij,ij->i", pixels, pixels)) + 1e-6
        lo, hi = self.target.brightness
        ok = (along >= self._cos_max * norm) & (norm >= lo * self._norm) & (norm <= hi * self._norm)
        mask = ok.reshape(small.shape[:2]).astype(np.uint8)
        blocked = np.zeros_like(mask)
        if exclude_px is not None and len(exclude_px) >= 3:
            hull = cv2.convexHull(np.round(np.asarray(exclude_px) * _SCALE).astype(np.int32))
            cv2.fillConvexPoly(blocked, hull, 1)
            blocked = cv2.dilate(blocked, np.ones((5, 5), np.uint8))
            mask[blocked > 0] = 0
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        if n <= 1:
            return Proximity(frame.t_s, False)
        best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
        x, y, w, h, area = (int(v) for v in stats[best])
        if area / (_SCALE * _SCALE) < self.min_area_px:
            return Proximity(frame.t_s, False)
        left_px, right_px, v_px = self._extent(labels == best, (x, y, w, h), blocked > 0)
        rays = intr.normalized(np.array([[left_px, v_px], [right_px, v_px]]))
        rays3 = np.column_stack([rays, np.ones(2)])
        rays3 /= np.linalg.norm(rays3, axis=1, keepdims=True)
        theta = math.acos(min(1.0, float(rays3[0] @ rays3[1])))
        if theta <= 0.0:
            return Proximity(frame.t_s, False)
        range_m = 0.5 * self.target.width_m / math.sin(0.5 * theta)
        centre_ray = rays3[0] + rays3[1]
        centre_cam = range_m * centre_ray / np.linalg.norm(centre_ray)
        aperture = self.rig.aperture_m(motor_position_mm)
        finger2gripper = self.rig.finger2gripper(self.rig.marker_finger, aperture)
        centre_g = transform_points(finger2gripper @ self.rig.rgb.cam2finger, centre_cam)
        position_m = float(centre_g[0])
        bbox = (round(x / _SCALE), round(y / _SCALE), round(w / _SCALE), round(h / _SCALE))
        return Proximity(frame.t_s, True, range_m, position_m - self.target.grasp_position_m,
                         bbox, position_m)

    def _extent(
        self, blob: NDArray[np.bool_], bbox: tuple[int, int, int, int], blocked: NDArray[np.bool_]
    ) -> tuple[float, float, float]:
        """Left and right silhouette edges through the blob's centre, full-resolution pixels.

        A free blob is measured across its middle row.  One cut by the frame
        edge (the object close up) or by an excluded region (the marker tab in
        front of it) is measured by a circle fitted to its free outline.
        """
        x, y, w, h = bbox
        rows, cols = blob.shape
        near_block = cv2.dilate(blocked.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        touches = bool(np.any(near_block & blob))
        if not touches and x > 0 and y > 0 and x + w < cols and y + h < rows:
            middle = y + h // 2
            hit = np.flatnonzero(blob[middle])
            # Reduced pixel c covers full-resolution x in [c / s - 1/2, (c + 1) / s - 1/2].
            return (hit[0] / _SCALE - 0.5, (hit[-1] + 1) / _SCALE - 0.5,
                    (middle + 0.5) / _SCALE - 0.5)
        contours, _ = cv2.findContours(blob.astype(np.uint8), cv2.RETR_EXTERNAL,
                                       cv2.CHAIN_APPROX_NONE)
        points = max(contours, key=len).reshape(-1, 2)
        free = ~near_block[points[:, 1], points[:, 0]]
        free &= (points[:, 0] > 0) & (points[:, 1] > 0) & (points[:, 0] < cols - 1)
        free &= points[:, 1] < rows - 1
        outline = points.astype(np.float64)
        inner = outline[free]
        if len(inner) < 8:
            inner = outline
        # Algebraic (Kasa) circle fit: x^2 + y^2 + D x + E y + F = 0.
        design = np.column_stack([inner, np.ones(len(inner))])
        sol, *_ = np.linalg.lstsq(design, -(inner**2).sum(axis=1), rcond=None)
        cx, cy = -0.5 * sol[0], -0.5 * sol[1]
        radius = math.sqrt(max(cx * cx + cy * cy - sol[2], 0.0)) + 0.5  # outline is on the blob
        to_full = 1.0 / _SCALE
        return ((cx - radius + 0.5) * to_full - 0.5, (cx + radius + 0.5) * to_full - 0.5,
                (cy + 0.5) * to_full - 0.5)
