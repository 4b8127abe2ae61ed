"""Frames for display: the RGB frame with the tracked marker, the infrared frame in false colour.

Pure functions of images and geometry (no clock, no state): the dashboard
calls them on the latest frames and sends the JPEG bytes to its viewers.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from relaxgrip.perception.marker import MarkerState
from relaxgrip.rig import RigGeometry, transform_points

__all__ = ["IR_SCALE", "beam_pixels", "encode_jpeg", "ir_view", "rgb_view"]

#: Upscaling of the (small) infrared frame for display.
IR_SCALE = 2
#: Points nearer to the infrared camera than this are behind it (m).
_NEAR_M = 0.005


def encode_jpeg(image: NDArray[np.uint8], quality: int = 80) -> bytes:
    """JPEG bytes of a BGR or grey ``uint8`` image."""
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return bytes(buf.tobytes())


def rgb_view(image: NDArray[np.uint8], marker: MarkerState | None, rig: RigGeometry,
             axis_m: float | None = None) -> NDArray[np.uint8]:
    """The RGB frame (BGR for OpenCV) with the detected marker and its pose axes drawn.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3), uint8
        RGB frame as the backend gives it.
    marker : MarkerState or None
        The tracker's answer for that frame; its corners and pose are drawn
        when the marker was accepted.
    rig : RigGeometry
        RGB intrinsics and the marker's id and size.
    axis_m : float, optional
        Length of the drawn axes (m); the marker's size by default.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
        A new BGR image.
    """
    out = np.asarray(cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2BGR),
                     dtype=np.uint8)
    if marker is None or marker.pose is None:
        return out
    pose = marker.pose
    corners = pose.corners_px.reshape(1, 4, 2).astype(np.float32)
    ids = np.array([[rig.marker.marker_id]], dtype=np.int32)
    cv2.aruco.drawDetectedMarkers(out, (corners,), ids)
    intr = rig.rgb.intrinsics
    dist = intr.dist_coeffs if intr.dist_coeffs is not None else np.zeros(5)
    length = rig.marker.size_m if axis_m is None else axis_m
    cv2.drawFrameAxes(out, intr.matrix, dist, pose.rvec.reshape(3, 1),
                      pose.tvec_m.reshape(3, 1), length, 2)
    return out


def beam_pixels(rig: RigGeometry, finger: int, aperture_m: float) -> NDArray[np.float64]:
    """Infrared image positions of a finger's beam regions, ``(n_beams, 2)`` pixels; nan if unseen.

    The beams are the points of :attr:`relaxgrip.rig.FingerGeometry.beam_positions_m`
    on the finger's top face (the face the infrared camera reads).
    """
    beams = np.asarray(rig.finger.beam_positions_m, dtype=np.float64)
    pts = transform_points(rig.ir.gripper2cam, rig.top_points_gripper(finger, aperture_m, beams))
    out = np.full((pts.shape[0], 2), np.nan)
    front = pts[:, 2] > _NEAR_M
    if np.any(front):
        out[front] = rig.ir.intrinsics.project(pts[front])
    return out


def ir_view(temps_c: NDArray[np.generic], rig: RigGeometry, aperture_m: float,
            range_c: tuple[float, float] = (20.0, 65.0),
            beam_temps_c: tuple[tuple[float, ...], ...] | None = None) -> NDArray[np.uint8]:
    """The infrared frame in false colour (inferno), upscaled, with the beam regions marked.

    Parameters
    ----------
    temps_c : ndarray, shape (H, W)
        Apparent temperatures (°C).
    rig : RigGeometry
        Infrared camera and finger geometry.
    aperture_m : float
        Aperture when the frame was taken (m), for where the fingers are.
    range_c : (float, float)
        Temperatures mapped to the ends of the colour map (°C).
    beam_temps_c : tuple of tuple of float, optional
        Per finger, the temperature perception read at each beam (°C): written
        next to the regions.

    Returns
    -------
    ndarray, shape (IR_SCALE H, IR_SCALE W, 3), uint8
        A BGR image.
    """
    lo, hi = range_c
    t = np.nan_to_num(np.asarray(temps_c, dtype=np.float64), nan=lo)
    grey = np.clip((t - lo) / (hi - lo) * 255.0, 0.0, 255.0).astype(np.uint8)
    out = cv2.applyColorMap(grey, cv2.COLORMAP_INFERNO)
    h, w = grey.shape
    out = np.asarray(cv2.resize(out, (w * IR_SCALE, h * IR_SCALE),
                                interpolation=cv2.INTER_NEAREST), dtype=np.uint8)
    for j in (0, 1):
        pix = beam_pixels(rig, j, aperture_m)
        for i, (u, v) in enumerate(pix):
            if not (math.isfinite(u) and math.isfinite(v) and 0 <= u < w and 0 <= v < h):
                continue
            x, y = round(u * IR_SCALE), round(v * IR_SCALE)
            cv2.rectangle(out, (x - 4, y - 4), (x + 4, y + 4), (255, 255, 0), 1)
            if beam_temps_c is not None and i < len(beam_temps_c[j]) \
                    and math.isfinite(beam_temps_c[j][i]):
                cv2.putText(out, f"{beam_temps_c[j][i]:.0f}", (x + 6, y + 4),
                            cv2.FONT_HERSHEY_PLAIN, 0.8, (255, 255, 255), 1)
    return np.asarray(out, dtype=np.uint8)
