"""Thermal features from infrared frames: finger beam temperatures, statistics, objects.

Perception reads only what a real gripper has: the infrared frame and the
encoder position of the closing motor.  From the encoder it knows the
aperture, and from :class:`relaxgrip.rig.RigGeometry` where each finger's
top face lands in the image.  Everything that depends on the aperture
(beam windows and their weights, face masks, background samples) is computed
once per 0.1 mm of aperture and cached: the aperture changes slowly, and
perception runs on every frame.

Beam temperatures are read in a small window centred, to a fraction of a
pixel, on the projection of the beam's position (bilinear weights).  The
camera sees the faces obliquely, so a pixel can span several millimetres of
finger; rounding the window to whole pixels would read the temperature a few
millimetres away, which on a graded finger is a bias of up to a kelvin.  The
optics blur the face's outline into the background, so a window must also
keep ``edge_clearance_px`` from the outline: near it (the tip, seen nearly
edge-on) the window shrinks, down to a single interpolated point, and a beam
with no room even for that reads nan.

Finger temperatures are corrected for their emissivity by inverting the
broadband graybody relation ``T_app^4 = ε T^4 + (1 - ε) T_refl^4`` (kelvin),
with the background estimate as the reflected surroundings.  Objects are
reported in apparent temperature: their emissivity is unknown.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import Frame
from relaxgrip.errors import InputError
from relaxgrip.perception.face_bend import FaceBendReader, FaceMidline
from relaxgrip.perception.frames import check_ir_frame
from relaxgrip.rig import RigGeometry, bend_profile_m, transform_points
from relaxgrip.validate import ABSOLUTE_ZERO_C, check_finite

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.intp]

__all__ = [
    "FingerThermal",
    "ThermalFeatures",
    "ThermalObject",
    "ThermalPerception",
    "covered_beams",
    "uncovered_mean_c",
]

#: Aperture resolution of the cached image regions (m).
_APERTURE_STEP_M = 1.0e-4
#: Slope resolution of the cached regions of a bent finger (rad).
_SLOPE_STEP_RAD = 1.0e-3
#: Apertures (and bends) whose regions are kept.
_CACHE_SIZE = 64
#: Fraction of the face height used for the face statistics.
_FACE_WIDTH_FRACTION = 0.8
#: Dilation of the face masks outside which objects and background are looked for (pixels).
_FACE_DILATE_PX = 2
#: Stride of the background samples in both directions (pixels).
_BACKGROUND_STRIDE_PX = 5
#: Longest piece of a face edge drawn as one straight line (m); short, so lens
#: distortion bends the outline.
_SEGMENT_M = 0.005
#: Points nearer to the lens than this count as behind it (m).
_NEAR_M = 0.005
#: Projections beyond this many pixels are treated as not seen (fixed-point overflow).
_MAX_PX = 1.0e6
_SHIFT = 4


@dataclass(frozen=True)
class FingerThermal:
    """Temperatures of one finger's top face.

    Attributes
    ----------
    beam_temps_c : tuple of float
        Temperature at each of ``rig.finger.beam_positions_m`` (°C); nan where
        that region is out of view or too close to the face's outline.
    mean_c, max_c, min_c : float
        Over the face pixels in view (°C); nan if none is.
    std_k : float
        Standard deviation over the face pixels in view (K); nan if none is.
    gradient_k_per_m : float
        Least-squares slope of beam temperature against beam position, root
        to tip (K/m), over the valid beams; nan with fewer than two.
    """

    beam_temps_c: tuple[float, ...]
    mean_c: float
    max_c: float
    min_c: float
    std_k: float
    gradient_k_per_m: float


@dataclass(frozen=True)
class ThermalObject:
    """A region warmer or cooler than the background, away from the fingers.

    Attributes
    ----------
    kind : {"warm", "cool"}
        Warmer or cooler than the background.
    temp_c : float
        Mean apparent temperature of the region (°C; emissivity 1, since the
        object's emissivity is unknown).
    peak_c : float
        Apparent maximum for a warm region, minimum for a cool one (°C).
    centroid_px : tuple of float
        Centroid ``(x, y)`` (pixels).
    area_px : int
        Area (pixels).
    bbox_px : tuple of int
        Bounding box ``(x, y, w, h)`` (pixels).
    """

    kind: Literal["warm", "cool"]
    temp_c: float
    peak_c: float
    centroid_px: tuple[float, float]
    area_px: int
    bbox_px: tuple[int, int, int, int]


@dataclass(frozen=True)
class ThermalFeatures:
    """Everything perception reads from one infrared frame.

    Attributes
    ----------
    t_s : float
        Capture time of the frame (s).
    fingers : tuple of FingerThermal
        Finger 0 and finger 1.
    background_c : float
        Background estimate: median of the pixels away from the fingers (°C).
    objects : tuple of ThermalObject
        Warm and cool regions, largest first.
    beam_weights : tuple of float, optional
        Each beam's weight in the finger's temperature
        (:attr:`relaxgrip.rig.FingerGeometry.bending_weights`); None weighs
        them alike.
    midlines : (FaceMidline, FaceMidline), optional
        Each finger's bend along its top face, row by row
        (:class:`relaxgrip.perception.face_bend.FaceBendReader`); None if not
        read.
    """

    t_s: float
    fingers: tuple[FingerThermal, FingerThermal]
    background_c: float
    objects: tuple[ThermalObject, ...]
    beam_weights: tuple[float, ...] | None = None
    midlines: tuple[FaceMidline, FaceMidline] | None = None

    @cached_property
    def finger_temperature_c(self) -> float:
        """Mean of both fingers' :func:`uncovered_mean_c` (°C); nan if neither is in view.

        Worked out once per frame: perception holds a frame's features through
        the thirty camera frames that follow it.
        """
        temps = [uncovered_mean_c(f, self.background_c, self.beam_weights) for f in self.fingers]
        seen = [t for t in temps if math.isfinite(t)]
        return sum(seen) / len(seen) if seen else math.nan


#: Below this spread between the warmest beam and the background nothing is told covered (K).
_MIN_CONTRAST_K = 5.0


def covered_beams(beams_c: Sequence[float], background_c: float,
                  within: float = 0.5) -> tuple[bool, ...]:
    """Which beams an object hides: those further below the warmest beam than ``within`` of the
    contrast between it and the background (0.5: closer to the background than to the warmest).

    Nothing is covered when the finger is within :data:`_MIN_CONTRAST_K` of the
    background (a cold finger cannot be told from a cold object) or when the
    background is unknown; a beam out of view (nan) is not covered either.
    """
    finite = [b for b in beams_c if math.isfinite(b)]
    if not finite or not math.isfinite(background_c):
        return (False,) * len(beams_c)
    warmest = max(finite)
    if warmest - background_c < _MIN_CONTRAST_K:
        return (False,) * len(beams_c)
    line = warmest - within * (warmest - background_c)
    return tuple(math.isfinite(b) and b < line for b in beams_c)


def uncovered_mean_c(finger: FingerThermal, background_c: float,
                     weights: Sequence[float] | None = None) -> float:
    """The finger's temperature: the mean of its beams no object covers, even in part (°C).

    A grasped object hides part of the face from the infrared camera and shows
    its own temperature there (a room-temperature ball reads 26-30 °C over the
    distal beams of a 55 °C finger), by an amount that changes with the
    contact position and the finger's bending, so the face's mean is not the
    finger's temperature.  A beam counts as covered a quarter of the contrast
    below the warmest (a half-covered beam of a 40 °C finger reads 35 °C; the
    heated profile spans under a tenth of the contrast).  With ``weights`` (one
    per beam) it is their weighted mean; the face's mean stands in when no
    beam of weight is in view.
    """
    covered = covered_beams(finger.beam_temps_c, background_c, within=0.25)
    if weights is None:
        weights = (1.0,) * len(finger.beam_temps_c)
    seen = [(w, b) for w, b, c in zip(weights, finger.beam_temps_c, covered, strict=True)
            if math.isfinite(b) and not c and w > 0.0]
    total = sum(w for w, _ in seen)
    return sum(w * b for w, b in seen) / total if total > 0.0 else finger.mean_c


@dataclass(frozen=True)
class _Regions:
    """Image regions of one aperture, as flat pixel indices into the frame."""

    #: Pixels read: the beam windows, then the face of finger 0, then of finger 1.
    gather: IndexArray
    #: Weight of each window pixel (each window's weights sum to 1).
    roi_weights: FloatArray
    #: Start of each window in ``gather`` (windows of finger 0, then of finger 1).
    roi_starts: IndexArray
    #: Beam index of each window, per finger.
    roi_slots: tuple[tuple[int, ...], tuple[int, ...]]
    #: End of the face pixels of finger 0 in ``gather``.
    face_split: int
    #: Sampled pixels away from both fingers.
    background: IndexArray
    #: ``(H, W)``: where objects are looked for (away from both fingers).
    search: NDArray[np.bool_]


class ThermalPerception:
    """Reads finger temperatures and warm or cool objects from infrared frames.

    Parameters
    ----------
    rig : RigGeometry
        Camera and finger geometry.
    emissivity : float
        Emissivity of the finger skin, in (0, 1].
    roi_half_px : int
        Half-size of the square window averaged at each beam (pixels): at most
        ``2 roi_half_px + 1`` pixels wide, smaller near the face's outline.
    object_threshold_k : float
        How far from the background a pixel must be to belong to an object (K).
    min_object_px : int
        Smallest object kept (pixels).
    edge_clearance_px : float
        Least distance between a beam window and the face's projected outline
        (pixels): about three standard deviations of the optics' blur, so that
        no background is averaged in.  The face statistics also leave out a
        band this wide along the outline.
    loaded_fingers : sequence of int
        The fingers the grasp's load bends, read bent with
        ``rig.ir_follow_bend``: both (the default), which carry equal and
        opposite forces in a grasp; the marker finger alone when an object is
        pressed against it and the other finger does not bend (a rigid jaw,
        the single-finger contacts of
        :mod:`relaxgrip.experiments.stiffness_modulation`).  Read bent, an
        unbent finger's windows would fall on the object.
    """

    def __init__(
        self,
        rig: RigGeometry,
        emissivity: float = 0.95,
        roi_half_px: int = 1,
        object_threshold_k: float = 1.0,
        min_object_px: int = 12,
        edge_clearance_px: float = 2.0,
        loaded_fingers: Sequence[int] = (0, 1),
    ) -> None:
        if not (math.isfinite(emissivity) and 0.0 < emissivity <= 1.0):
            raise InputError(f"emissivity must be in (0, 1], got {emissivity}")
        if roi_half_px < 0:
            raise InputError(f"roi_half_px must be >= 0, got {roi_half_px}")
        if not (math.isfinite(object_threshold_k) and object_threshold_k > 0):
            raise InputError(f"object_threshold_k must be > 0 K, got {object_threshold_k}")
        if min_object_px < 1:
            raise InputError(f"min_object_px must be >= 1, got {min_object_px}")
        if not (math.isfinite(edge_clearance_px) and edge_clearance_px >= 0):
            raise InputError(f"edge_clearance_px must be >= 0, got {edge_clearance_px}")
        loaded = tuple(loaded_fingers)
        if len(set(loaded)) != len(loaded) or not set(loaded) <= {0, 1}:
            raise InputError(f"loaded_fingers must be distinct fingers 0 or 1, got {loaded!r}")
        self.rig = rig
        self.loaded_fingers = loaded
        self.emissivity = float(emissivity)
        self.roi_half_px = int(roi_half_px)
        self.object_threshold_k = float(object_threshold_k)
        self.min_object_px = int(min_object_px)
        self.edge_clearance_px = float(edge_clearance_px)
        self._beams_m = np.asarray(rig.finger.beam_positions_m, dtype=np.float64)
        #: Where the face's outline is drawn along the finger (m from the root).
        self._along_m = np.linspace(0.0, rig.finger.length_m,
                                    max(1, math.ceil(rig.finger.length_m / _SEGMENT_M)) + 1)
        self._cache: dict[tuple[int, int, int], _Regions] = {}
        self._faces = FaceBendReader(rig)

    def extract(self, frame: Frame, motor_position_mm: float,
                bend: tuple[float, float] | None = None) -> ThermalFeatures:
        """Thermal features of one frame.

        Parameters
        ----------
        frame : Frame
            Infrared frame: ``(H, W)`` float apparent temperatures (°C).  Dead
            pixels (non-finite) are read from their neighbours
            (:func:`relaxgrip.perception.frames.check_ir_frame`): a NaN would
            otherwise spread through the window, face and background statistics
            that contain it.
        motor_position_mm : float
            Encoder position of the closing motor when the frame was taken (mm).
        bend : (deflection_m, slope_rad), optional
            The marker finger's bend at the marker's tab, as the marker reads
            it: with ``rig.ir_follow_bend`` the :attr:`loaded_fingers` are
            read bent so (:func:`~relaxgrip.rig.bend_profile_m`; in a grasp
            the fingers carry equal and opposite forces), to 0.1 mm and
            1 mrad.  Ignored otherwise, and None reads them unbent.

        Returns
        -------
        ThermalFeatures
            Finger temperatures (emissivity-corrected), background, objects,
            and the fingers' face midlines (looked for where ``bend`` puts the
            loaded fingers).

        Raises
        ------
        FrameError
            If the frame is empty, the wrong size or type, or has more dead
            pixels, or a wider dead block, than a working sensor.
        InputError
            If ``motor_position_mm`` is not finite.
        """
        img = check_ir_frame(frame.image, self.rig.ir.intrinsics)
        aperture = self.rig.aperture_m(check_finite(motor_position_mm, "motor_position_mm"))
        regions = self._regions(aperture, bend if self.rig.ir_follow_bend else None)
        flat = img.reshape(-1)

        samples = flat[regions.background] if regions.background.size else flat.copy()
        background_c = _median(samples)

        values = self._correct(flat[regions.gather], background_c)
        n_roi_px = regions.roi_weights.size
        if regions.roi_starts.size:
            roi_means = np.add.reduceat(values[:n_roi_px] * regions.roi_weights, regions.roi_starts)
        else:
            roi_means = np.zeros(0)
        faces = (values[n_roi_px : regions.face_split], values[regions.face_split :])
        fingers: list[FingerThermal] = []
        start = 0
        for j in (0, 1):
            slots = regions.roi_slots[j]
            beams = np.full(self._beams_m.size, np.nan)
            beams[list(slots)] = roi_means[start : start + len(slots)]
            start += len(slots)
            fingers.append(_finger_thermal(beams, self._beams_m, slots, faces[j]))

        return ThermalFeatures(
            t_s=float(frame.t_s),
            fingers=(fingers[0], fingers[1]),
            background_c=background_c,
            objects=self._objects(img, regions.search, background_c),
            beam_weights=self.rig.finger.bending_weights,
            midlines=self._faces.read(img, aperture, bend, self.loaded_fingers),
        )

    def _correct(self, apparent_c: NDArray[np.float32], background_c: float) -> FloatArray:
        """Invert the graybody relation: true temperatures of finger pixels (°C)."""
        # float32 keeps T^4 to ~1e-7 relative: ~1e-5 K, far below the NETD.
        eps = self.emissivity
        fourth = apparent_c + np.float32(-ABSOLUTE_ZERO_C)
        fourth *= fourth
        fourth *= fourth
        fourth -= np.float32((1.0 - eps) * (background_c - ABSOLUTE_ZERO_C) ** 4)
        fourth *= np.float32(1.0 / eps)
        np.maximum(fourth, 0.0, out=fourth)
        np.sqrt(fourth, out=fourth)
        np.sqrt(fourth, out=fourth)
        out: FloatArray = fourth.astype(np.float64)
        out += ABSOLUTE_ZERO_C
        return out

    def _objects(
        self, img: NDArray[np.float32], search: NDArray[np.bool_], background_c: float
    ) -> tuple[ThermalObject, ...]:
        """Connected regions beyond the threshold from the background, largest first."""
        thr = self.object_threshold_k
        warm = img > np.float32(background_c + thr)
        warm &= search
        cool = img < np.float32(background_c - thr)
        cool &= search
        found = self._components(img, warm, "warm") + self._components(img, cool, "cool")
        found.sort(key=lambda o: (-o.area_px, o.kind, o.centroid_px))
        return tuple(found)

    def _components(
        self, img: NDArray[np.float32], mask: NDArray[np.bool_], kind: Literal["warm", "cool"]
    ) -> list[ThermalObject]:
        binary = mask.view(np.uint8)
        x0, y0, w, h = cv2.boundingRect(binary)
        if w * h < self.min_object_px:
            return []  # also when no pixel is set
        crop = binary[y0 : y0 + h, x0 : x0 + w]
        _, labels, stats, centroids = cv2.connectedComponentsWithStats(
            crop, connectivity=8, ltype=cv2.CV_32S
        )
        out: list[ThermalObject] = []
        for label, (bx, by, bw, bh, area) in enumerate(stats.tolist()):
            if label == 0 or area < self.min_object_px:
                continue
            sel = labels[by : by + bh, bx : bx + bw] == label
            vals = img[y0 + by : y0 + by + bh, x0 + bx : x0 + bx + bw][sel]
            peak = np.maximum.reduce(vals) if kind == "warm" else np.minimum.reduce(vals)
            cx, cy = centroids[label].tolist()
            out.append(
                ThermalObject(
                    kind=kind,
                    temp_c=float(np.add.reduce(vals, dtype=np.float64)) / area,
                    peak_c=float(peak),
                    centroid_px=(cx + x0, cy + y0),
                    area_px=area,
                    bbox_px=(bx + x0, by + y0, bw, bh),
                )
            )
        return out

    def _regions(self, aperture_m: float, bend: tuple[float, float] | None) -> _Regions:
        """The image regions of an aperture and a bend, cached per 0.1 mm (and 1 mrad)."""
        deflection, slope = (0.0, 0.0) if bend is None else bend
        if not (math.isfinite(deflection) and math.isfinite(slope)):
            deflection, slope = 0.0, 0.0
        key = (round(aperture_m / _APERTURE_STEP_M), round(deflection / _APERTURE_STEP_M),
               round(slope / _SLOPE_STEP_RAD))
        regions = self._cache.get(key)
        if regions is None:
            if len(self._cache) >= _CACHE_SIZE:
                del self._cache[next(iter(self._cache))]
            profile = bend_profile_m(self._along_m, self.rig.marker.position_m,
                                     key[1] * _APERTURE_STEP_M, key[2] * _SLOPE_STEP_RAD)
            regions = self._compute_regions(key[0] * _APERTURE_STEP_M, profile)
            self._cache[key] = regions
        return regions

    def _compute_regions(self, aperture_m: float, bend_m: FloatArray) -> _Regions:
        """Beam windows, face masks and background samples at one aperture, the fingers
        bent by ``bend_m`` at :attr:`_along_m`."""
        h, w = self.rig.ir.intrinsics.shape
        clearance = self.edge_clearance_px
        erode_px = math.ceil(clearance)
        erode = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * erode_px + 1, 2 * erode_px + 1))

        indices: list[IndexArray] = []
        weights: list[FloatArray] = []
        slots: list[tuple[int, ...]] = []
        faces: list[IndexArray] = []
        near_fingers = np.zeros((h, w), dtype=np.uint8)
        unbent = np.zeros_like(bend_m)
        for j in (0, 1):
            bent = bend_m if j in self.loaded_fingers else unbent
            outline, inner_outline = self._outlines(j, aperture_m, bent)
            valid: list[int] = []
            for i, centre in enumerate(self._beam_pixels(j, aperture_m, bent)):
                window = self._window(centre, outline)
                if window is not None:
                    valid.append(i)
                    indices.append(window[0])
                    weights.append(window[1])
            slots.append(tuple(valid))

            whole = _fill(outline, (h, w))
            inner = _fill(inner_outline, (h, w))
            if erode_px:
                eroded = cv2.erode(whole, erode, borderType=cv2.BORDER_CONSTANT, borderValue=0)
                inner &= eroded.astype(np.uint8, copy=False)
            faces.append(np.flatnonzero(inner))
            near_fingers |= whole

        dilate = cv2.getStructuringElement(
            cv2.MORPH_ELLIPSE, (2 * _FACE_DILATE_PX + 1, 2 * _FACE_DILATE_PX + 1)
        )
        search: NDArray[np.bool_] = cv2.dilate(near_fingers, dilate) == 0
        stride = _BACKGROUND_STRIDE_PX
        grid = np.zeros((h, w), dtype=bool)
        grid[stride // 2 :: stride, stride // 2 :: stride] = True

        sizes = [idx.size for idx in indices]
        roi = np.concatenate(indices) if indices else np.zeros(0, dtype=np.intp)
        starts = np.cumsum([0, *sizes])[:-1]
        return _Regions(
            gather=np.concatenate([roi, faces[0], faces[1]]).astype(np.intp),
            roi_weights=np.concatenate(weights) if weights else np.zeros(0),
            roi_starts=starts.astype(np.intp),
            roi_slots=(slots[0], slots[1]),
            face_split=roi.size + faces[0].size,
            background=np.flatnonzero(grid & search).astype(np.intp),
            search=search,
        )

    def _beam_pixels(self, j: int, aperture_m: float, bend_m: FloatArray) -> FloatArray:
        """Sub-pixel image positions of finger ``j``'s beams, ``(n_beams, 2)``; nan if unseen."""
        bend = np.interp(self._beams_m, self._along_m, bend_m)
        pts = transform_points(
            self.rig.ir.gripper2cam,
            self.rig.top_points_gripper(j, aperture_m, self._beams_m, bend_m=bend),
        )
        out = np.full((pts.shape[0], 2), np.nan)
        front = pts[:, 2] > _NEAR_M
        if np.any(front):
            out[front] = self.rig.ir.intrinsics.project(pts[front])
        out[~np.all(np.abs(out) < _MAX_PX, axis=1)] = np.nan
        return out

    def _window(
        self, centre_px: FloatArray, outline: FloatArray | None
    ) -> tuple[IndexArray, FloatArray] | None:
        """Pixels and bilinear weights of the window around a beam, or ``None`` if none fits.

        The window is a ``(2 r + 1)^2`` grid of points one pixel apart centred
        on ``centre_px``, each bilinearly interpolated: a ``(2 r + 2)^2`` block
        of pixels with separable weights.  ``r`` is the largest half-size up to
        ``roi_half_px`` whose points all keep ``edge_clearance_px`` from the outline.
        """
        if outline is None or not np.all(np.isfinite(centre_px)):
            return None
        u, v = float(centre_px[0]), float(centre_px[1])
        room = cv2.pointPolygonTest(outline.astype(np.float32), (u, v), True)
        h, w = self.rig.ir.intrinsics.shape
        x0, y0 = math.floor(u), math.floor(v)
        for r in range(self.roi_half_px, -1, -1):
            if room < self.edge_clearance_px + r * math.sqrt(2.0):
                continue
            if x0 - r < 0 or y0 - r < 0 or x0 + r + 1 >= w or y0 + r + 1 >= h:
                continue
            n = 2 * r + 1
            wx = np.ones(n + 1)
            wx[0], wx[-1] = 1.0 - (u - x0), u - x0
            wy = np.ones(n + 1)
            wy[0], wy[-1] = 1.0 - (v - y0), v - y0
            cols = np.arange(x0 - r, x0 + r + 2)
            rows = np.arange(y0 - r, y0 + r + 2)
            idx = (rows[:, None] * w + cols[None, :]).reshape(-1).astype(np.intp)
            return idx, (wy[:, None] * wx[None, :]).reshape(-1) / (n * n)
        return None

    def _outlines(
        self, j: int, aperture_m: float, bend_m: FloatArray
    ) -> tuple[FloatArray | None, FloatArray | None]:
        """Projected outline of finger ``j``'s top face, and of its central part.

        Each is an ``(N, 2)`` polygon in pixels, or ``None`` if the face is not
        in front of the camera.  The central part spans ``_FACE_WIDTH_FRACTION``
        of the face's width.
        """
        rig = self.rig
        along = self._along_m
        half_m = 0.5 * rig.finger.thickness_m
        inner_m = _FACE_WIDTH_FRACTION * half_m
        across = np.array([-half_m, half_m, -inner_m, inner_m])
        cam = transform_points(
            rig.ir.gripper2cam,
            rig.top_points_gripper(j, aperture_m, along[:, None], across, bend_m[:, None]),
        )
        px = np.full((*cam.shape[:-1], 2), np.inf)
        front = cam[..., 2] > _NEAR_M
        if np.any(front):
            px[front] = rig.ir.intrinsics.project(cam[front])
        seen = np.all(np.abs(px) < _MAX_PX, axis=-1)
        outlines: list[FloatArray | None] = []
        for lo, hi in ((0, 1), (2, 3)):
            # Depth is affine along the finger, so the part in front of the lens is one run.
            keep = seen[:, lo] & seen[:, hi]
            if np.count_nonzero(keep) >= 2:
                outlines.append(np.concatenate([px[keep, lo], px[keep, hi][::-1]]))
            else:
                outlines.append(None)
        return outlines[0], outlines[1]


def _fill(outline: FloatArray | None, shape: tuple[int, int]) -> NDArray[np.uint8]:
    """0/1 mask of the pixels whose centres lie inside a polygon (pixels)."""
    mask = np.zeros(shape, dtype=np.uint8)
    if outline is not None:
        fixed = np.round(outline * (1 << _SHIFT)).astype(np.int32)
        cv2.fillPoly(mask, [fixed], 1, cv2.LINE_8, _SHIFT)
    return mask


def _median(samples: NDArray[np.float32]) -> float:
    """Median of ``samples`` (partitioned in place)."""
    n = samples.size
    half = n // 2
    if n % 2:
        samples.partition(half)
        return float(samples[half])
    samples.partition((half - 1, half))
    return 0.5 * (float(samples[half - 1]) + float(samples[half]))


def _finger_thermal(
    beams_c: FloatArray, positions_m: FloatArray, slots: tuple[int, ...], face_c: FloatArray
) -> FingerThermal:
    """Statistics of one finger from its beam temperatures and face pixels."""
    gradient = math.nan
    if len(slots) >= 2:
        x = positions_m[list(slots)]
        y = beams_c[list(slots)]
        dx = x - np.add.reduce(x) / x.size
        sxx = float(np.dot(dx, dx))
        if sxx > 0:
            gradient = float(np.dot(dx, y)) / sxx
    n = face_c.size
    if n:
        mean = float(np.add.reduce(face_c)) / n
        dev = face_c - mean
        std = math.sqrt(float(np.dot(dev, dev)) / n)
        stats = (mean, float(np.maximum.reduce(face_c)), float(np.minimum.reduce(face_c)), std)
    else:
        stats = (math.nan, math.nan, math.nan, math.nan)
    return FingerThermal(
        beam_temps_c=tuple(float(b) for b in beams_c),
        mean_c=stats[0],
        max_c=stats[1],
        min_c=stats[2],
        std_k=stats[3],
        gradient_k_per_m=gradient,
    )
