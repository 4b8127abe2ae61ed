"""The twin's RGB camera: the ArUco marker on its tab, objects ahead, sensor noise.

The marker's modules come from OpenCV (``generateImageMarker``) and are
projected through the camera intrinsics with the homography of its pose.
Its edges must carry sub-pixel information the way a real optical image
does (a plain warp gives jagged, biased edges), and the tab is drawn one of
two ways (``RgbSensorConfig.drawing``): ``"exact"`` gives each pixel the
exact area of the tab's white and of each black run it covers, as a camera
pixel integrates the light on its area (:mod:`relaxgrip.twin.raster`);
``"supersampled"`` warps a texture at ``supersample`` times the resolution
onto an upsampled copy of the region it covers and area-averages it back
down.  Objects are shaded discs, drawn with sub-pixel centres.
Pixel noise comes from a bank of pre-drawn noise, sliced at a random offset
per frame: a full frame of fresh Gaussian noise would cost more than the
rest of the rendering together.  The bank holds signed 8-bit values (noise
beyond ±127 DN, 60 standard deviations at the default, is clipped there):
one byte of noise per pixel channel to read, not two, for a pass whose cost
is its memory traffic.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import cv2
import numba
import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.rig import RigGeometry
from relaxgrip.twin.raster import area_coverage
from relaxgrip.twin.sensors import RgbSensorConfig

FloatArray = NDArray[np.float64]
Image = NDArray[np.uint8]

__all__ = ["RgbDrawing", "RgbObject", "RgbRenderer"]

#: Texture pixels per marker module per unit of supersampling (48 at the default 4x): a
#: texel is then about a supersampled pixel where the twin's camera sees the marker (13 px
#: a module), as a mipmap level would be chosen.  A texture much finer than the grid that
#: samples it aliases: along a 3 mm bend drawn without noise at 2x, a 48 px texture put
#: the marker's position off by 7.2 / 7.3 um SD (x / z), a 24 px one by 1.1 / 2.4 um
#: (4x from 48 px: 0.6 / 1.0 um).
_TEXELS_PER_MODULE_PER_SUPERSAMPLE = 12
#: White margin around the black square, in modules (ArUco's quiet zone).
_QUIET_MODULES = 1
#: Grey levels of the tab's white and of the printed ink; the tab's colour cast.
_TAB_WHITE = 228
_INK = 24
_TAB_TINT = (1.0, 0.99, 0.965)
_NOISE_PAD = 48
_NOISE_BANKS = 3
#: Add the noise to the scene and the tab apart (the same pixels, a pass fewer); off
#: only for the test that compares the two.
_FUSED = True
#: Frames whose random draws are made together (:meth:`RgbRenderer._draws`).
_DRAW_BLOCK = 64
#: Sub-pixel bits for OpenCV's drawing functions.
_SHIFT = 4
#: A filled circle as OpenCV draws it: centre and radius on the sub-pixel grid, colour.
_Circle = tuple[tuple[int, int], int, tuple[float, ...]]


@dataclass(frozen=True)
class RgbObject:
    """An object as the RGB camera sees it: a shaded sphere-like disc.

    Attributes
    ----------
    center_cam_m : tuple of float
        Centre in the camera frame (m).
    radius_m : float
        Radius (m).
    color_rgb : tuple of int
        Mean colour (0-255).
    """

    center_cam_m: tuple[float, float, float]
    radius_m: float
    color_rgb: tuple[int, int, int]


class _TabShape(NamedTuple):
    """The tab as closed outlines on the marker plane (metres), as directed edges
    between vertices, all running the same way round: plane 0 is the white
    outline (the black square and its quiet zone), plane 1 the boundary of the
    black modules' union, each straight run of it one edge.  The first four
    vertices are the outline's corners, clockwise on the screen."""

    vertices: FloatArray  # (V, 1, 2), as cv2.perspectiveTransform takes them
    ends: NDArray[np.intp]  # (2, E): each edge's first and last vertex
    planes: NDArray[np.intp]  # (E,)


class _TabBox(NamedTuple):
    """Where the tab lands: its texture-to-image homography, the marker-plane-to-image
    one, outline corners (px) and the image's box ``[x0, x1) x [y0, y1)`` drawn into."""

    tex_to_img: FloatArray
    plane_to_img: FloatArray
    corners: FloatArray
    x0: int
    y0: int
    x1: int
    y1: int

    @property
    def rows(self) -> slice:
        return slice(self.y0, self.y1)

    @property
    def cols(self) -> slice:
        return slice(self.x0, self.x1)


class RgbRenderer:
    """Renders RGB frames of the marker camera.

    Parameters
    ----------
    rig : RigGeometry
        Camera intrinsics and marker.
    config : RgbSensorConfig
        Noise, blur, lighting, occlusion.
    seed : int
        Seed of this camera's noise and lighting jitter; frame ``seq`` of a
        seed is always the same image.
    """

    def __init__(self, rig: RigGeometry, config: RgbSensorConfig, seed: int) -> None:
        self.rig = rig
        self.config = config
        self.seed = seed
        self.intrinsics = rig.rgb.intrinsics
        if self.intrinsics.dist:
            raise InputError(
                "the twin renders an undistorted pinhole camera; give its intrinsics without "
                "distortion coefficients"
            )
        self._texture, self._texture_to_marker = _tab_texture(
            rig, _TEXELS_PER_MODULE_PER_SUPERSAMPLE
            * (config.supersample if config.drawing == "supersampled" else 1))
        self._shape = _tab_shape(rig)
        th, tw = self._texture.shape[:2]
        self._texture_outline = np.array(
            [[[-0.5, -0.5], [tw - 0.5, -0.5], [tw - 0.5, th - 0.5], [-0.5, th - 0.5]]])
        self._matrix = self.intrinsics.matrix
        self._background = _background(self.intrinsics.shape)
        self._noise = _noise_bank(self.intrinsics.shape, config.noise_dn)
        self._scene_cache: tuple[tuple[_Circle, ...], Image] | None = None
        self._draw_cache: dict[int, list[tuple[float, int, int, int]]] = {}
        self._last_circles: tuple[_Circle, ...] | None = None
        self._last_seq: int | None = None  # the frame whose draws were asked for last

    def marker_corners_px(self, marker2cam: FloatArray) -> FloatArray:
        """Image positions of the marker's four corners (OpenCV order), (4, 2)."""
        corners = self.rig.marker.object_points_m @ marker2cam[:3, :3].T + marker2cam[:3, 3]
        return self.intrinsics.project(corners)

    def render(
        self, seq: int, marker2cam: FloatArray, objects: Sequence[RgbObject] = ()
    ) -> Image:
        """Render frame ``seq``.

        Parameters
        ----------
        seq : int
            Frame number: selects the frame's noise and lighting jitter.
        marker2cam : ndarray, shape (4, 4)
            Pose of the marker in the camera frame.
        objects : sequence of RgbObject
            Objects in front of the camera, in any order.

        Returns
        -------
        ndarray, shape (H, W, 3), uint8
            The RGB frame.
        """
        return self.prepare(seq, marker2cam, objects).image()

    def prepare(self, seq: int, marker2cam: FloatArray,
                objects: Sequence[RgbObject] = ()) -> RgbDrawing:
        """Frame ``seq`` ready to draw, whole (:meth:`RgbDrawing.image`) or a region of it
        (:meth:`RgbDrawing.region`), with the same pixels either way."""
        return RgbDrawing(self, seq, marker2cam, tuple(objects))

    def _draw(self, seq: int, marker2cam: FloatArray, objects: tuple[RgbObject, ...]) -> Image:
        """The whole frame, blurred or lit other than nominally (what no region can be)."""
        cfg = self.config
        jitter, bank, oy, ox = self._draws(seq)
        scene = self._scene(objects)
        gain = cfg.lighting_gain * (1.0 + cfg.lighting_flicker * jitter)
        h, w = self.intrinsics.shape
        noise = self._noise[bank, oy : oy + h, ox : ox + w]
        box = self._tab_box(marker2cam)
        img = scene.copy()
        if box is not None:
            self._paint_tab(img[box.rows, box.cols], box, marker2cam)
        if cfg.blur_sigma_px > 0:
            cv2.GaussianBlur(img, (0, 0), cfg.blur_sigma_px, dst=img)
        if gain != 1.0:
            cv2.convertScaleAbs(img, dst=img, alpha=max(gain, 0.0))
        if cfg.noise_dn > 0:
            _add_noise(img, noise, img)
        return img

    def _draws(self, seq: int) -> tuple[float, int, int, int]:
        """Frame ``seq``'s random draws: lighting jitter, noise bank, noise offset (y, x).

        Each frame draws from its own generator, seeded with the renderer's seed
        and ``seq``.  They are made for a block of frames at a time: a generator
        made between two frames' worth of image arithmetic, its code and data
        gone from the caches, took 0.125 ms of a 2 ms step; made one after the
        other, 0.02 ms.  Frames asked for far apart (every few seconds, as a
        dataset's sampling does) draw alone.
        """
        block = seq // _DRAW_BLOCK
        draws = self._draw_cache.get(block)
        previous, self._last_seq = self._last_seq, seq
        if draws is None:
            if previous is None or not 0 < seq - previous <= 2:
                # Frames asked for far apart (a dataset's, one in tens of ticks): this
                # one's draws alone, not a block of frames nobody may ask for.
                return _frame_draws(self.seed, seq)
            draws = [_frame_draws(self.seed, s)
                     for s in range(block * _DRAW_BLOCK, (block + 1) * _DRAW_BLOCK)]
            if len(self._draw_cache) >= 2:
                self._draw_cache.pop(next(iter(self._draw_cache)))
            self._draw_cache[block] = draws
        return draws[seq - block * _DRAW_BLOCK]

    def _scene(self, objects: tuple[RgbObject, ...]) -> Image:
        """The background with ``objects`` drawn, far ones first (read-only).

        Objects keep still through a hold: a scene whose circles fall on the
        same sixteenth of a pixel (OpenCV's sub-pixel grid, so the same pixels)
        in two frames running is kept and used from then on.  Through a hold
        the controller's closure moves them by thousandths of a pixel a frame.
        """
        circles = tuple(c for obj in sorted(objects, key=lambda o: -o.center_cam_m[2])
                        for c in self._circles(obj))
        cached = self._scene_cache
        if cached is not None and cached[0] == circles:
            return cached[1]
        if not circles:
            return self._background
        img = self._background.copy()
        for centre, radius, colour in circles:
            cv2.circle(img, centre, radius, colour, -1, cv2.LINE_AA, _SHIFT)
        img.flags.writeable = False
        if circles == self._last_circles:
            self._scene_cache = (circles, img)
        self._last_circles = circles
        return img

    def _circles(self, obj: RgbObject) -> tuple[_Circle, ...]:
        """The object's shaded disc as OpenCV circles on the sub-pixel grid (none if unseen)."""
        x, y, z = obj.center_cam_m
        if z <= obj.radius_m + 0.005:
            return ()  # touching or behind the lens: nothing sensible to draw
        cam = self.intrinsics  # CameraIntrinsics.project's arithmetic, on plain floats
        u, v = x / z * cam.fx_px + cam.cx_px, y / z * cam.fy_px + cam.cy_px
        r_px = self.intrinsics.fx_px * obj.radius_m / math.sqrt(z * z - obj.radius_m**2)
        h, w = self.intrinsics.shape
        if r_px < 0.5 or u + r_px < 0 or u - r_px > w or v + r_px < 0 or v - r_px > h:
            return ()
        base = tuple(0.75 * c for c in obj.color_rgb)
        lit = tuple(min(255.0, 1.05 * c + 10.0) for c in obj.color_rgb)
        scale = 1 << _SHIFT

        def circle(cu: float, cv: float, radius: float, colour: tuple[float, ...]) -> _Circle:
            return (round(cu * scale), round(cv * scale)), max(1, round(radius * scale)), colour

        return (circle(u, v, r_px, base),
                circle(u - 0.25 * r_px, v - 0.25 * r_px, 0.55 * r_px, lit))

    def _tab_box(self, marker2cam: FloatArray) -> _TabBox | None:
        """Where the tab lands in the image, with a margin; None if nowhere."""
        plane_to_img = self._matrix @ marker2cam[:3, [0, 1, 3]]
        tex_to_img = plane_to_img @ self._texture_to_marker
        if marker2cam[2, 3] <= 0.0:
            return None  # behind the camera
        corners = cv2.perspectiveTransform(self._texture_outline, tex_to_img)[0]
        xs, ys = corners[:, 0].tolist(), corners[:, 1].tolist()
        h, w = self.intrinsics.shape
        x0 = max(math.floor(min(xs)) - 2, 0)
        y0 = max(math.floor(min(ys)) - 2, 0)
        x1 = min(math.ceil(max(xs)) + 3, w)
        y1 = min(math.ceil(max(ys)) + 3, h)
        if x1 <= x0 or y1 <= y0:
            return None
        return _TabBox(tex_to_img, plane_to_img, corners, x0, y0, x1, y1)

    def _paint_tab(self, roi: Image, box: _TabBox, marker2cam: FloatArray) -> None:
        """Draw the marker tab onto ``roi``, the image's pixels in ``box``: the tab
        premultiplied by its coverage of each pixel, composited over the scene
        with the outline's coverage."""
        if self.config.drawing == "exact":
            # The grey levels made and composited a pixel at a time, the same values.
            _composite_areas(roi, self._exact_areas(box))
        else:
            _composite(roi, *self._supersampled_tab(box))
        if self.config.occlusion > 0:
            self._occlude(roi, marker2cam, (box.x0, box.y0))

    def _exact_tab(self, box: _TabBox) -> tuple[Image, Image]:
        """The tab's premultiplied grey and coverage in ``box``, each pixel the exact
        area of the white and of the black it covers."""
        areas = self._exact_areas(box)
        tab, coverage = np.empty(areas.shape[1:], np.uint8), np.empty(areas.shape[1:], np.uint8)
        _grey_levels(areas, tab, coverage)
        return tab, coverage

    def _exact_areas(self, box: _TabBox) -> FloatArray:
        """The area of each pixel in ``box`` that the tab's outline covers, and that its
        black covers: shape (2, H, W)."""
        shape = self._shape
        px = cv2.perspectiveTransform(shape.vertices, box.plane_to_img)[:, 0]
        px -= (box.x0, box.y0)
        # Projected with the marker facing the camera the outlines run clockwise on the
        # screen; seen from behind, the other way, and every area changes sign.
        (ax, ay), (bx, by), (cx, cy) = px[:3].tolist()
        sign = 1.0 if (bx - ax) * (cy - by) - (by - ay) * (cx - bx) >= 0 else -1.0
        return area_coverage(px[shape.ends], sign, (box.y1 - box.y0, box.x1 - box.x0),
                             plane=shape.planes, planes=2)

    def _supersampled_tab(self, box: _TabBox) -> tuple[Image, Image]:
        """The tab's premultiplied grey and coverage in ``box``, warped at
        ``supersample`` times the resolution.

        The tab is achromatic, so it is warped as one grey channel (a third of
        the cost of colour) onto black: area-averaged back down, that is the
        tab premultiplied by its coverage of each pixel; the coverage is the
        tab outline's antialiased fill.
        """
        ss = self.config.supersample
        x0, y0 = box.x0, box.y0
        size = (box.x1 - x0, box.y1 - y0)
        # Supersampled pixel I covers image x in [x0 - 1/2 + I/ss, x0 - 1/2 + (I+1)/ss].
        to_up = np.array(
            [[ss, 0.0, ss * (0.5 - x0) - 0.5], [0.0, ss, ss * (0.5 - y0) - 0.5], [0.0, 0.0, 1.0]]
        )
        up = cv2.warpPerspective(
            self._texture, to_up @ box.tex_to_img, (ss * size[0], ss * size[1]),
            flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0,
        )
        tab: Image = np.asarray(cv2.resize(up, size, interpolation=cv2.INTER_AREA))
        coverage = np.zeros((size[1], size[0]), np.uint8)
        _fill(coverage, box.corners - (x0, y0), 255)
        return tab, coverage

    def _occlude(self, roi: Image, marker2cam: FloatArray, origin: tuple[int, int]) -> None:
        """Cover the left ``occlusion`` fraction of the marker (a cable, a finger beam)."""
        half = 0.5 * self.rig.marker.size_m
        quiet = half * (1.0 + 2.0 * _QUIET_MODULES / _module_count(self.rig))
        edge = -half + 2.0 * half * self.config.occlusion
        patch = np.array([[-quiet - 1e-3, quiet + 1e-3, 0.0], [edge, quiet + 1e-3, 0.0],
                          [edge, -quiet - 1e-3, 0.0], [-quiet - 1e-3, -quiet - 1e-3, 0.0]])
        cam = patch @ marker2cam[:3, :3].T + marker2cam[:3, 3]
        _fill(roi, self.intrinsics.project(cam) - origin, (55, 52, 50))


class RgbDrawing:
    """One frame of an :class:`RgbRenderer`, drawn when and where it is read.

    The nominal frame (pixel noise, no blur, nominal lighting) is the scene
    plus noise but where the tab is, and there the tab painted over the scene
    plus the same noise: each pixel depends on its own inputs alone, so a
    region is drawn on its own with the pixels the whole frame has there.
    The tab (the box it lands in, painted and noised once per frame) is kept
    for every region that reads it.  Any other frame is drawn whole on the
    first read, and regions are cut from it.
    """

    __slots__ = ("_box", "_full", "_marker2cam", "_noise", "_objects", "_renderer", "_scene",
                 "_seq", "_tab")

    def __init__(self, renderer: RgbRenderer, seq: int, marker2cam: FloatArray,
                 objects: tuple[RgbObject, ...]) -> None:
        self._renderer = renderer
        self._seq = seq
        self._marker2cam = marker2cam
        self._objects = objects
        self._full: Image | None = None
        self._tab: Image | None = None
        self._scene: Image | None = None
        self._noise: Image | None = None
        self._box: _TabBox | None = None
        cfg = renderer.config
        if _FUSED and cfg.noise_dn > 0 and cfg.blur_sigma_px == 0:
            jitter, bank, oy, ox = renderer._draws(seq)
            if cfg.lighting_gain * (1.0 + cfg.lighting_flicker * jitter) == 1.0:
                h, w = renderer.intrinsics.shape
                self._scene = renderer._scene(objects)
                self._noise = renderer._noise[bank, oy : oy + h, ox : ox + w]
                self._box = renderer._tab_box(marker2cam)

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(H, W, 3)`` of the frame."""
        h, w = self._renderer.intrinsics.shape
        return h, w, 3

    def image(self) -> Image:
        """The whole frame (drawn on the first call)."""
        if self._full is None:
            if self._scene is None:
                self._full = self._renderer._draw(self._seq, self._marker2cam, self._objects)
            else:
                self._full = self.region(0, self.shape[0], 0, self.shape[1])
        return self._full

    def region(self, y0: int, y1: int, x0: int, x1: int) -> Image:
        """The frame's pixels ``[y0:y1, x0:x1]`` (bounds clipped to the frame), a new array
        unless the whole frame is drawn already."""
        h, w, _ = self.shape
        y0, y1 = max(0, min(y0, h)), max(0, min(y1, h))
        x0, x1 = max(0, min(x0, w)), max(0, min(x1, w))
        y1, x1 = max(y0, y1), max(x0, x1)
        if self._full is not None or self._scene is None or self._noise is None:
            return self.image()[y0:y1, x0:x1]
        out: Image = np.empty((y1 - y0, x1 - x0, 3), np.uint8)
        if out.size == 0:
            return out
        _add_noise(self._scene[y0:y1, x0:x1], self._noise[y0:y1, x0:x1], out)
        box = self._box
        if box is not None:
            ty0, ty1 = max(y0, box.y0), min(y1, box.y1)
            tx0, tx1 = max(x0, box.x0), min(x1, box.x1)
            if ty0 < ty1 and tx0 < tx1:
                tab = self._painted_tab(box)
                out[ty0 - y0 : ty1 - y0, tx0 - x0 : tx1 - x0] = \
                    tab[ty0 - box.y0 : ty1 - box.y0, tx0 - box.x0 : tx1 - box.x0]
        return out

    def _painted_tab(self, box: _TabBox) -> Image:
        """The box the tab lands in: the tab painted over the scene, noise added."""
        if self._tab is None:
            assert self._scene is not None
            assert self._noise is not None
            rows, cols = box.rows, box.cols
            roi = self._scene[rows, cols].copy()
            self._renderer._paint_tab(roi, box, self._marker2cam)
            _add_noise(roi, self._noise[rows, cols], roi)
            self._tab = roi
        return self._tab


def _frame_draws(seed: int, seq: int) -> tuple[float, int, int, int]:
    """Frame ``seq``'s lighting jitter (a standard normal), noise bank and offset."""
    rng = np.random.default_rng([seed, 12, seq])
    jitter = float(rng.standard_normal())
    bank = int(rng.integers(_NOISE_BANKS))
    oy, ox = (int(v) for v in rng.integers(0, _NOISE_PAD, size=2))
    return jitter, bank, oy, ox


#: The tab's colour cast per channel, and the scale from a coverage level to its share
#: of the pixel, as the compositing's float32 arithmetic uses them.
_TINT = np.array(_TAB_TINT, dtype=np.float32)
_PER_LEVEL = np.float32(1.0 / 255.0)


def _composite(roi: Image, tab: Image, coverage: Image) -> None:
    """``roi = scene (1 - coverage / 255) + tab * tint`` in float32, clipped and truncated.

    ``roi`` (H, W, 3) is the scene, written in place; ``tab`` and ``coverage`` are
    (H, W) grey levels.
    """
    _composite_rows(_rows(roi), tab, coverage, _TINT, _PER_LEVEL)


def _composite_areas(roi: Image, areas: FloatArray) -> None:
    """:func:`_composite` of the tab whose outline and black cover ``areas`` (2, H, W) of
    each pixel: its grey levels as :func:`_grey_levels` makes them."""
    _composite_area_rows(_rows(roi), areas, float(_TAB_WHITE), float(_INK - _TAB_WHITE),
                         _TINT, _PER_LEVEL)


def _grey_levels(areas: FloatArray, tab: Image, coverage: Image) -> None:
    """The tab's premultiplied grey, ``|white outline + (ink - white) black|``, and its
    coverage, ``|255 outline|``, rounded to 8 bits as OpenCV's ``addWeighted`` (in
    float64) then ``convertScaleAbs`` (in float32, halves to even) make them."""
    _grey_level_rows(areas, float(_TAB_WHITE), float(_INK - _TAB_WHITE), tab, coverage)


def _add_noise(image: Image, noise: Image, out: Image) -> None:
    """``out = image + noise``, saturated to 8 bits, ``noise`` signed 8-bit values held
    in ``uint8`` (two's complement): OpenCV's ``add`` of the positive part then
    ``subtract`` of the negative; ``out`` may be ``image``."""
    _add_noise_rows(_rows(image), _rows(noise), _rows(out))


def _rows(image: Image) -> Image:
    """An (H, W, C) image as H rows of W C values: a view, so that writes reach it."""
    h, w, c = image.shape
    if image.strides[1:] != (c, 1):
        raise ValueError(f"image rows must be contiguous, got strides {image.strides}")
    # With each row's bytes in one run, numpy merges the last two axes without a copy
    # (as_strided would too, at ten times the cost of the call).
    rows: Image = image.reshape(h, w * c)
    return rows


# Compiled (numba), a row at a time: the per-pixel work is a few operations, which
# as whole-array passes cost more in memory traffic than in arithmetic.


@numba.njit(cache=True, nogil=True, inline="always")
def _blend_channel(scene: np.uint8, grey: np.float32, transmit: np.float32,
                   tint: np.float32) -> np.uint8:  # pragma: no cover - compiled
    value = np.float32(scene) * transmit + grey * tint
    # Below 0 only by rounding (a fully covered pixel transmits -6e-8).
    return np.uint8(max(min(value, np.float32(255.0)), np.float32(0.0)))


# The helpers take and return numbers, not arrays: an array passed to one, even inlined,
# is reference-counted at every call, which kept the pixels' loop out of vector registers
# (92 against 28 us for a 106 x 126 px tab).


@numba.njit(cache=True, nogil=True)
def _composite_rows(roi: Image, tab: Image, coverage: Image, tint: NDArray[np.float32],
                    per_level: np.float32) -> None:  # pragma: no cover - compiled
    t0, t1, t2 = tint[0], tint[1], tint[2]
    for i in range(roi.shape[0]):
        row, grey, cover = roi[i], tab[i], coverage[i]
        for j in range(grey.shape[0]):
            level = np.float32(grey[j])
            transmit = np.float32(1.0) - np.float32(cover[j]) * per_level
            row[3 * j] = _blend_channel(row[3 * j], level, transmit, t0)
            row[3 * j + 1] = _blend_channel(row[3 * j + 1], level, transmit, t1)
            row[3 * j + 2] = _blend_channel(row[3 * j + 2], level, transmit, t2)


@numba.njit(cache=True, nogil=True, inline="always")
def _grey_level(outline: float, black: float, white: float,
                ink_less_white: float) -> tuple[np.float32, np.float32]:  # pragma: no cover
    """The tab's grey and coverage levels (0-255, whole numbers in float32) of a pixel whose
    area ``outline`` the tab covers and ``black`` its black: addWeighted's sum in float64,
    then convertScaleAbs's float32 with halves to even (115.49999999999999 becomes 115.5,
    then 116)."""
    grey = abs(np.float32(outline * white + black * ink_less_white))
    cover = abs(np.float32(outline) * np.float32(255.0))
    return min(np.rint(grey), np.float32(255.0)), min(np.rint(cover), np.float32(255.0))


@numba.njit(cache=True, nogil=True)
def _grey_level_rows(areas: FloatArray, white: float, ink_less_white: float, tab: Image,
                     coverage: Image) -> None:  # pragma: no cover - compiled
    for i in range(areas.shape[1]):
        for j in range(areas.shape[2]):
            grey, cover = _grey_level(areas[0, i, j], areas[1, i, j], white, ink_less_white)
            tab[i, j], coverage[i, j] = np.uint8(grey), np.uint8(cover)


@numba.njit(cache=True, nogil=True)
def _composite_area_rows(roi: Image, areas: FloatArray, white: float, ink_less_white: float,
                         tint: NDArray[np.float32],
                         per_level: np.float32) -> None:  # pragma: no cover - compiled
    t0, t1, t2 = tint[0], tint[1], tint[2]
    for i in range(roi.shape[0]):
        row, outline, black = roi[i], areas[0, i], areas[1, i]
        for j in range(outline.shape[0]):
            grey, cover = _grey_level(outline[j], black[j], white, ink_less_white)
            transmit = np.float32(1.0) - cover * per_level
            row[3 * j] = _blend_channel(row[3 * j], grey, transmit, t0)
            row[3 * j + 1] = _blend_channel(row[3 * j + 1], grey, transmit, t1)
            row[3 * j + 2] = _blend_channel(row[3 * j + 2], grey, transmit, t2)


@numba.njit(cache=True, nogil=True)
def _add_noise_rows(image: Image, noise: Image, out: Image) -> None:  # pragma: no cover - compiled
    for i in range(image.shape[0]):
        a, z, o = image[i], noise[i], out[i]
        for k in range(a.shape[0]):
            # The signed value's two parts; 8-bit arithmetic wraps: a sum below an
            # addend overflowed, a difference above the minuend went under.
            up = z[k] if z[k] < 128 else np.uint8(0)
            down = np.uint8(-z[k]) if z[k] >= 128 else np.uint8(0)
            total = np.uint8(a[k] + up)
            total = total if total >= a[k] else np.uint8(255)
            rest = np.uint8(total - down)
            o[k] = rest if rest <= total else np.uint8(0)


def _fill(image: Image, polygon_px: FloatArray, colour: float | tuple[float, ...]) -> None:
    """Antialiased convex polygon with sub-pixel vertices (pixel centres at integers)."""
    vertices = np.round(np.asarray(polygon_px) * (1 << _SHIFT)).astype(np.int32)
    cv2.fillConvexPoly(image, vertices, colour, cv2.LINE_AA, _SHIFT)


def _module_count(rig: RigGeometry) -> int:
    """Modules along the marker's black square: its bits and the one-module border."""
    return int(rig.marker.aruco_dictionary.markerSize) + 2


def _tab_shape(rig: RigGeometry) -> _TabShape:
    """The tab's white outline (the black square and its quiet zone) and the boundary
    of its black modules, as edges on the marker plane (x right, y up, metres).

    The black is drawn as its union's boundary, not module by module or run by
    run: an edge two black modules share would add and take away the same
    area, and the rasteriser's cost is the edges' length in pixels (the
    boundary is 46 modules long for the default marker, its rows' runs 80).
    """
    marker = rig.marker
    dictionary = marker.aruco_dictionary
    modules = _module_count(rig)
    bits = cv2.aruco.generateImageMarker(dictionary, marker.marker_id, modules, borderBits=1)
    module_m = marker.size_m / modules
    half = 0.5 * marker.size_m
    quiet = half + _QUIET_MODULES * module_m
    # Top-left, top-right, bottom-right, bottom-left: clockwise on the screen.
    vertices = [[-quiet, quiet], [quiet, quiet], [quiet, -quiet], [-quiet, -quiet]]
    ends = [[0, 1], [1, 2], [2, 3], [3, 0]]
    black = np.pad(bits < 128, 1)  # a white module all round
    index: dict[tuple[int, int], int] = {}

    def vertex(row: int, col: int) -> int:
        """The lattice point ``row`` module lines down and ``col`` across from the
        black square's top-left corner."""
        if (row, col) not in index:
            index[row, col] = len(vertices)
            vertices.append([-half + col * module_m, half - row * module_m])
        return index[row, col]

    def runs(side: NDArray[np.bool_]) -> list[tuple[int, int]]:
        """The runs ``[a, b)`` of True in one lattice line's modules (padding dropped)."""
        changes = np.flatnonzero(np.diff(np.r_[0, side[1:-1].astype(np.int8), 0]))
        return [(int(a), int(b)) for a, b in zip(changes[::2], changes[1::2], strict=True)]

    # Lattice line k runs between padded modules k and k + 1.  Clockwise round the
    # black: rightwards along a line with black below it, leftwards with black above,
    # down a line with black to its left, up one with black to its right.
    for k in range(modules + 1):
        above, below = black[k], black[k + 1]
        left, right = black[:, k], black[:, k + 1]
        ends += [[vertex(k, a), vertex(k, b)] for a, b in runs(below & ~above)]
        ends += [[vertex(k, b), vertex(k, a)] for a, b in runs(above & ~below)]
        ends += [[vertex(a, k), vertex(b, k)] for a, b in runs(left & ~right)]
        ends += [[vertex(b, k), vertex(a, k)] for a, b in runs(right & ~left)]
    planes = np.r_[np.zeros(4, np.intp), np.ones(len(ends) - 4, np.intp)]
    return _TabShape(np.array(vertices, dtype=np.float64).reshape(-1, 1, 2),
                     np.array(ends, dtype=np.intp).T, planes)


def _tab_texture(rig: RigGeometry, px_per_module: int) -> tuple[Image, FloatArray]:
    """The marker with its white quiet zone at ``px_per_module``, and the map from texture
    pixels to the marker plane."""
    marker = rig.marker
    dictionary = marker.aruco_dictionary
    modules = _module_count(rig)
    side = modules * px_per_module
    gray = cv2.aruco.generateImageMarker(dictionary, marker.marker_id, side, borderBits=1)
    pad = _QUIET_MODULES * px_per_module
    gray = cv2.copyMakeBorder(gray, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255)
    texture = (_INK + (_TAB_WHITE - _INK) * (gray / 255.0)).round().astype(np.uint8)
    # Texture pixel centres are integers; the black square spans [pad - 1/2, pad + side - 1/2].
    metres_per_px = marker.size_m / side
    centre = pad + 0.5 * side - 0.5
    texture_to_marker = np.array(
        [[metres_per_px, 0.0, -centre * metres_per_px],
         [0.0, -metres_per_px, centre * metres_per_px],  # marker y points up
         [0.0, 0.0, 1.0]]
    )
    return texture, texture_to_marker


@lru_cache(maxsize=4)
def _background(shape: tuple[int, int]) -> Image:
    """The finger's open skeleton seen from its root: dark, with lighter beams (read-only)."""
    rng = np.random.default_rng(10)
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    base = 62.0 + 18.0 * (y / h) - 10.0 * ((x - w / 2) / w) ** 2
    for _ in range(4):
        x_beam = rng.uniform(0.05, 0.95) * w
        slope = rng.uniform(-0.3, 0.3)
        width = rng.uniform(8.0, 22.0)
        dist = np.abs(x - (x_beam + slope * (y - h / 2))) / width
        base += rng.uniform(12.0, 30.0) * np.exp(-0.5 * dist**2)
    base += cv2.GaussianBlur(rng.normal(0.0, 6.0, size=(h, w)), (0, 0), 3.0)
    tint = np.array([1.0, 0.97, 0.92])
    out: Image = np.clip(base[..., None] * tint, 0, 255).astype(np.uint8)
    out.flags.writeable = False
    return out


@lru_cache(maxsize=4)
def _noise_bank(shape: tuple[int, int], sigma_dn: float) -> Image:
    """Pre-drawn Gaussian pixel noise, rounded to signed 8-bit values (clipped at ±127)
    and held as their two's complement in ``uint8``, the type :func:`_add_noise` reads.

    The bank is shared by every renderer (read-only); each frame takes its
    noise from a bank and offset drawn from its own seed.
    """
    rng = np.random.default_rng(11)
    h, w = shape
    size = (_NOISE_BANKS, h + _NOISE_PAD, w + _NOISE_PAD, 3)
    if sigma_dn <= 0:
        return np.zeros((_NOISE_BANKS, _NOISE_PAD, _NOISE_PAD, 3), np.uint8)
    noise = np.rint(rng.normal(0.0, sigma_dn, size=size).astype(np.float32))
    bank: Image = np.clip(noise, -127, 127).astype(np.int8).view(np.uint8)
    bank.flags.writeable = False
    return bank
