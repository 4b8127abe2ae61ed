"""Checks on camera frames before perception touches them.

A frame from a real camera can be empty, truncated, the wrong size or the
wrong type.  :func:`check_rgb_frame` and :func:`check_ir_frame` return the
image ready to use or raise :class:`FrameError` with a one-line reason; the
perception pipeline turns that into an ``invalid`` state, never an exception
escaping the control loop.

A microbolometer has dead pixels, which many cores report as NaN: an
infrared frame with a few non-finite pixels is used, each read from its
finite neighbours, and refused only when there are more of them than a
working sensor has.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.rig import CameraIntrinsics

__all__ = [
    "DEAD_FILL_PASSES",
    "MAX_DEAD_FRACTION",
    "FrameError",
    "check_ir_frame",
    "check_rgb_frame",
    "fill_dead_pixels",
]

#: Most non-finite (dead) pixels an infrared frame may hold, as a fraction of its pixels:
#: microbolometer cores are specified with an operability (share of working pixels) of
#: 99 % or better, so more than 1 % is a failing sensor or a corrupt frame, not dead pixels.
MAX_DEAD_FRACTION = 0.01
#: Passes of the neighbour fill: a dead pixel further than this from any finite one (in a
#: dead block wider than twice this, or half as wide in a corner) is not filled, and the
#: frame is refused.
DEAD_FILL_PASSES = 2


class FrameError(InputError):
    """A camera frame that cannot be used."""


def _check_shape(image: object, intrinsics: CameraIntrinsics, kind: str) -> NDArray[np.generic]:
    if not isinstance(image, np.ndarray):
        raise FrameError(f"{kind} frame is {type(image).__name__}, not an image array")
    if image.size == 0:
        raise FrameError(f"{kind} frame is empty")
    if image.ndim < 2:  # a driver's flat buffer, not reshaped to rows and columns
        raise FrameError(f"{kind} frame has {image.ndim} dimensions, not an image's rows and "
                         f"columns")
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
    """Return an infrared frame as ``(H, W)`` float32 °C, or raise :class:`FrameError`.

    A finite float32 frame is returned as it is (not copied).  Non-finite
    pixels (NaN or ±inf: dead pixels) are read from their neighbours in a
    copy, see :func:`fill_dead_pixels`; the caller's array is not changed.

    Raises
    ------
    FrameError
        If the frame is not an ``(H, W)`` float image of the camera's size,
        holds more than :data:`MAX_DEAD_FRACTION` of non-finite pixels or a
        dead block too wide to fill, or a temperature at or below absolute zero.
    """
    img = _check_shape(image, intrinsics, "IR")
    if img.ndim != 2:
        raise FrameError(f"IR frame has {img.ndim} dimensions, expected 2")
    if img.dtype.kind != "f":
        raise FrameError(f"IR frame has dtype {img.dtype}, expected temperatures as floats")
    out = img.astype(np.float32, copy=False)
    finite = np.isfinite(out)
    if not np.all(finite):
        out = fill_dead_pixels(out, ~finite)
    if float(out.min()) <= -273.15:
        raise FrameError(f"IR frame holds {float(out.min()):.1f} °C: below absolute zero")
    return out


def fill_dead_pixels(image: NDArray[np.float32], dead: NDArray[np.bool_]) -> NDArray[np.float32]:
    """A copy of an infrared frame with each dead pixel the mean of its live neighbours.

    Parameters
    ----------
    image : ndarray, shape (H, W), float32
        Temperatures (°C); the values of dead pixels are not read.
    dead : ndarray, shape (H, W), bool
        The pixels to fill.

    Returns
    -------
    ndarray, shape (H, W), float32
        Each dead pixel replaced by the mean of the live pixels among its eight
        neighbours; a dead pixel with none takes the mean of its neighbours
        filled in the pass before, for :data:`DEAD_FILL_PASSES` passes.

    Raises
    ------
    FrameError
        If more than :data:`MAX_DEAD_FRACTION` of the pixels are dead, or a dead
        pixel is further than :data:`DEAD_FILL_PASSES` pixels from a live one.
    """
    n_dead = int(np.count_nonzero(dead))
    limit = int(MAX_DEAD_FRACTION * dead.size)
    if n_dead > limit:
        raise FrameError(f"IR frame holds {n_dead} non-finite temperatures, more than the "
                         f"{limit} dead pixels ({MAX_DEAD_FRACTION:.0%}) a working sensor has")
    out = np.where(dead, np.float32(0.0), image).astype(np.float32, copy=False)
    live = (~dead).astype(np.float32)
    todo = dead.copy()
    for _ in range(DEAD_FILL_PASSES):
        # Sums and counts of the live 3x3 neighbours (a dead pixel itself counts 0 in both).
        sums = cv2.boxFilter(out, -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
        counts = cv2.boxFilter(live, -1, (3, 3), normalize=False,
                               borderType=cv2.BORDER_CONSTANT)
        fill = todo & (counts > 0)
        out[fill] = sums[fill] / counts[fill]
        live[fill] = 1.0
        todo &= ~fill
        if not todo.any():
            return out
    raise FrameError(f"IR frame holds non-finite temperatures more than {DEAD_FILL_PASSES} "
                     f"pixels from any finite one (a dead block wider than "
                     f"{2 * DEAD_FILL_PASSES} px)")
