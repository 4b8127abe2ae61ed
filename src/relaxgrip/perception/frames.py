"""Checks on camera frames before perception touches them.

A frame from a real camera can be empty, truncated, the wrong size or the
wrong type.  :func:`check_rgb_frame` and :func:`check_ir_frame` return the
image ready to use or raise :class:`FrameError` with a one-line reason; the
perception pipeline turns that into an ``invalid`` state, never an exception
escaping the control loop.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.rig import CameraIntrinsics

__all__ = ["FrameError", "check_ir_frame", "check_rgb_frame"]


class FrameError(InputError):
    """A camera frame that cannot be used."""


def _check_shape(image: object, intrinsics: CameraIntrinsics, kind: str) -> NDArray[np.generic]:
    if not isinstance(image, np.ndarray):
        raise FrameError(f"{kind} frame is {type(image).__name__}, not an image array")
    if image.size == 0:
        raise FrameError(f"{kind} frame is empty")
    if image.shape[:2] != intrinsics.shape:
        h, w = intrinsics.shape
        raise FrameError(
            f"{kind} frame is {image.shape[1]}x{image.shape[0]}, expected {w}x{h}"
        )
    return image


def check_rgb_frame(image: object, intrinsics: CameraIntrinsics) -> NDArray[np.uint8]:
    """Return an RGB frame as ``(H, W, 3)`` uint8, or raise :class:`FrameError`.

    A single-channel ``(H, W)`` uint8 frame (a monochrome camera) is accepted
    as it is.
    """
    img = _check_shape(image, intrinsics, "RGB")
    if img.dtype != np.uint8:
        raise FrameError(f"RGB frame has dtype {img.dtype}, expected uint8")
    if img.ndim == 3 and img.shape[2] != 3:
        raise FrameError(f"RGB frame has {img.shape[2]} channels, expected 3")
    if img.ndim not in (2, 3):
        raise FrameError(f"RGB frame has {img.ndim} dimensions, expected 2 or 3")
    return img  # type: ignore[return-value]


def check_ir_frame(image: object, intrinsics: CameraIntrinsics) -> NDArray[np.float32]:
    """Return an infrared frame as ``(H, W)`` float32 °C, or raise :class:`FrameError`."""
    img = _check_shape(image, intrinsics, "IR")
    if img.ndim != 2:
        raise FrameError(f"IR frame has {img.ndim} dimensions, expected 2")
    if img.dtype.kind != "f":
        raise FrameError(f"IR frame has dtype {img.dtype}, expected temperatures as floats")
    out = img.astype(np.float32, copy=False)
    if not np.all(np.isfinite(out)):
        raise FrameError("IR frame holds non-finite temperatures")
    if float(out.min()) <= -273.15:
        raise FrameError(f"IR frame holds {float(out.min()):.1f} °C: below absolute zero")
    return out
