"""Each finger's bend as the infrared camera sees it: the top face's midline, row by row.

Beyond the paper.  The infrared camera looks down on both fingers' top faces,
and a loaded finger bends across its face (5 mm at the distal beams at 5 N
and 40 °C).  The marker shows only finger 0; this shows both, and so the creep
of the finger without the marker, which sets most of a hold's error after its
first seconds (docs/hold-experiments.md, session 56).

Per image row, the face is a band warmer (or colder) than the background: its
two edges are where the row crosses half-way between the two levels
(linearly interpolated between pixels).  Every pixel centre is back-projected
on the plane of the top faces (the gripper's ``z = height / 2``), so the
edges' midpoint is a point of the face's centre line in the gripper frame,
and its distance outwards from where the unbent centre line lies at the
current aperture is the bend there.  A frame gives one such point per row,
from the root to the tip.

:func:`fit_contact_deflection_m` fits the beam model's deflection profile to them:
the deflection at the contact, for a contact position and temperature.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.physics.beam import FingerParams, deflection_share
from relaxgrip.rig import RigGeometry, bend_profile_m

FloatArray = NDArray[np.float64]

__all__ = [
    "ALONG_RANGE_M", "FaceBendReader", "FaceMidline", "clear_span_m", "fit_contact_deflection_m",
]

#: The span of the finger read (m from the root): near the root a row sees little bend,
#: and beyond 108 mm the face's end runs along the row.  The distal rows carry most
#: of the creep: read only to 100 mm, finger 1's creep over 22 holds scattered 0.037
#: against 0.029 N SD (as the chain's force).
ALONG_RANGE_M = (0.015, 0.108)
#: Aperture and bend resolution of the cached search windows (m).
_STEP_M = 1.0e-4
#: Background pixels on either side of where a face can be, in each row's window.
_PAD_PX = 4
#: Windows kept.
_CACHE_SIZE = 64


@dataclass(frozen=True)
class FaceMidline:
    """One finger's top-face centre line in one infrared frame.

    Attributes
    ----------
    along_m : ndarray, shape (n,)
        Positions along the finger (m from the root), one per image row that
        showed both edges of the face.
    bend_m : ndarray, shape (n,)
        The finger's deflection outwards there (m).
    width_m : ndarray, shape (n,)
        The face's width there (m): the finger's thickness where the whole
        face is seen, less where something in front hides part of it.
    """

    along_m: FloatArray
    bend_m: FloatArray
    width_m: FloatArray


class _Window(NamedTuple):
    """The rows searched for one finger's face, each row's columns (padded) and which are real."""

    rows: NDArray[np.intp]
    cols: NDArray[np.intp]
    valid: NDArray[np.bool_]


class FaceBendReader:
    """Reads both fingers' face midlines from infrared frames.

    Parameters
    ----------
    rig : RigGeometry
        The infrared camera's mount and intrinsics, and the fingers.
    min_contrast_k : float
        A row whose face differs from the background by less (K) is not read:
        a finger at the room's temperature has no outline.
    margin_m : float
        How far beyond the face's expected outline a row is searched (m),
        and then four pixels more, the background's.
    along_range_m : (float, float)
        Rows are read where the face lies within this span along the finger
        (m from the root; :data:`ALONG_RANGE_M`).
    """

    def __init__(self, rig: RigGeometry, min_contrast_k: float = 2.0, margin_m: float = 0.003,
                 along_range_m: tuple[float, float] = ALONG_RANGE_M) -> None:
        if not (math.isfinite(min_contrast_k) and min_contrast_k > 0):
            raise InputError(f"least contrast must be > 0 K, got {min_contrast_k}")
        if not (math.isfinite(margin_m) and margin_m > 0):
            raise InputError(f"search margin must be > 0 m, got {margin_m}")
        lo, hi = along_range_m
        if not 0.0 <= lo < hi <= rig.finger.length_m:
            raise InputError(f"rows must lie along the finger, got {along_range_m} m")
        self.rig = rig
        self.min_contrast_k = float(min_contrast_k)
        self.margin_m = float(margin_m)
        self.along_range_m = (float(lo), float(hi))
        intr = rig.ir.intrinsics
        h, w = intr.shape
        grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), axis=-1).astype(np.float64)
        normal = intr.normalized(grid)
        c2g = rig.ir.cam2gripper
        rays = np.concatenate([normal, np.ones((h, w, 1))], axis=-1) @ c2g[:3, :3].T
        origin = c2g[:3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (0.5 * rig.finger.height_m - origin[2]) / rays[..., 2]
        t = np.where(t > 0, t, np.nan)
        #: Where each pixel centre's ray meets the plane of the top faces (gripper x, y; m).
        self._x = origin[0] + t * rays[..., 0]
        self._y = origin[1] + t * rays[..., 1]
        self._cache: dict[tuple[int, int, int, int], _Window] = {}

    def read(self, image: NDArray[np.floating], aperture_m: float,
             bend: tuple[float, float] | None = None,
             loaded: tuple[int, ...] = (0, 1)) -> tuple[FaceMidline, FaceMidline]:
        """Both fingers' face midlines in one frame.

        Parameters
        ----------
        image : ndarray, shape (H, W)
            Apparent temperatures (°C), dead pixels already filled.
        aperture_m : float
            The aperture from the encoder (m).
        bend : (deflection_m, slope_rad), optional
            The marker finger's bend at the tab: where the ``loaded`` fingers'
            faces are looked for (in a grasp the fingers carry equal and
            opposite forces).  None looks for them unbent.
        loaded : tuple of int
            The fingers the load bends; the others are looked for unbent.

        Returns
        -------
        (FaceMidline, FaceMidline)
            Finger 0's and finger 1's.
        """
        img = np.asarray(image, dtype=np.float64)
        out = []
        for j in (0, 1):
            window = self._window(j, aperture_m, bend if j in loaded else None)
            out.append(self._midline(j, img, aperture_m, *window))
        return out[0], out[1]

    def _window(self, j: int, aperture_m: float, bend: tuple[float, float] | None) -> _Window:
        """Finger ``j``'s rows searched, each row's columns (padded) and which are real.

        Kept per finger, aperture and bend (to 0.1 mm and 1 mrad): the margin
        covers the rounding.
        """
        deflection, slope = (0.0, 0.0) if bend is None else bend
        key = (j, round(aperture_m / _STEP_M), round(deflection / _STEP_M), round(slope * 1e3))
        cached = self._cache.get(key)
        if cached is not None:
            return cached
        rig = self.rig
        half = 0.5 * rig.finger.thickness_m
        lo, hi = self.along_range_m
        x = np.nan_to_num(self._x, nan=-1.0)
        guess = bend_profile_m(np.clip(x, 0.0, rig.finger.length_m), rig.marker.position_m,
                               deflection, slope)
        side = -1.0 if j == 0 else 1.0
        across = side * self._y - (0.5 * aperture_m + half + guess)
        near = (np.abs(across) <= half + self.margin_m) & (x >= lo) & (x <= hi)
        rows = np.flatnonzero(near.any(axis=1))
        # Beyond where the face can be, the background the row's level is taken from.
        first = np.maximum(near[rows].argmax(axis=1) - _PAD_PX, 0)
        last = np.minimum(near.shape[1] - 1 - near[rows, ::-1].argmax(axis=1) + _PAD_PX,
                          near.shape[1] - 1)
        width = int((last - first).max()) + 1 if rows.size else 0
        cols = first[:, None] + np.arange(width)
        window = _Window(rows, np.minimum(cols, near.shape[1] - 1), cols <= last[:, None])
        if len(self._cache) >= _CACHE_SIZE:
            self._cache.pop(next(iter(self._cache)))
        self._cache[key] = window
        return window

    def _midline(self, j: int, img: FloatArray, aperture_m: float, rows: NDArray[np.intp],
                 cols: NDArray[np.intp], valid: NDArray[np.bool_]) -> FaceMidline:
        empty = FaceMidline(np.zeros(0), np.zeros(0), np.zeros(0))
        if rows.size == 0 or cols.shape[1] < 8:
            return empty
        n = valid.sum(axis=1)
        p = img[rows[:, None], cols]
        # The background: the window's three pixels at each end (its margin).
        last3 = n[:, None] - 1 - np.arange(3)
        base = np.median(np.concatenate([p[:, :3], np.take_along_axis(p, last3, axis=1)],
                                        axis=1), axis=1)
        polarity = np.sign(np.where(valid, p, 0.0).sum(axis=1) / n - base)
        q = (p - base[:, None]) * polarity[:, None]  # the face counts up from 0
        q[~valid] = -np.inf
        k = np.argmax(q, axis=1)
        r = np.arange(rows.size)
        lo_k, hi_k = np.maximum(k - 1, 0), np.minimum(k + 1, n - 1)
        a, b, c = q[r, lo_k], q[r, k], q[r, hi_k]
        peak = np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), c))  # their median
        half = 0.5 * peak
        idx = np.arange(cols.shape[1])
        below = q < half[:, None]
        left = np.where(below & (idx < k[:, None]), idx, -1).max(axis=1)
        right = np.where(below & (idx > k[:, None]), idx, cols.shape[1]).min(axis=1)
        # The face must lie wholly inside the window: its ends are background.
        ends = np.maximum(q[:, :3].max(axis=1), np.take_along_axis(q, last3, axis=1).max(axis=1))
        ok = (peak >= self.min_contrast_k) & (left >= 0) & (right < n) & (ends < 0.25 * peak)
        if not ok.any():
            return empty
        r, left, right, half = r[ok], left[ok], right[ok], half[ok]
        qa = q[r]
        # Sub-pixel crossings: between left and left + 1, and between right - 1 and right.
        fl = (half - qa[np.arange(r.size), left]) / (
            qa[np.arange(r.size), left + 1] - qa[np.arange(r.size), left])
        fr = (qa[np.arange(r.size), right - 1] - half) / (
            qa[np.arange(r.size), right - 1] - qa[np.arange(r.size), right])
        row_px = rows[r]
        c = cols[r]
        xs, ys = self._x[row_px[:, None], c], self._y[row_px[:, None], c]
        at = np.arange(r.size)

        def lerp(plane: FloatArray, i: NDArray[np.intp], f: FloatArray) -> FloatArray:
            out: FloatArray = plane[at, i] + f * (plane[at, i + 1] - plane[at, i])
            return out

        x_mid = 0.5 * (lerp(xs, left, fl) + lerp(xs, right - 1, fr))
        y_left, y_right = lerp(ys, left, fl), lerp(ys, right - 1, fr)
        side = -1.0 if j == 0 else 1.0
        thickness = self.rig.finger.thickness_m
        bend = side * 0.5 * (y_left + y_right) - 0.5 * aperture_m - 0.5 * thickness
        good = np.isfinite(x_mid) & np.isfinite(bend)
        return FaceMidline(x_mid[good], bend[good], np.abs(y_right - y_left)[good])


def clear_span_m(midline: FaceMidline, tolerance_m: float = 0.3e-3,
                 along_range_m: tuple[float, float] = ALONG_RANGE_M,
                 reference_below_m: float = 0.040) -> tuple[float, float]:
    """The span of the finger, from the root, where the whole face is seen (m).

    A held object stands above the faces between the fingers and hides part
    of them near it (the force ball, 30 mm in radius: the rows beyond about
    57 mm at 5 N): there the face reads narrower than it is, and its outline
    is partly the object's, which does not move as the finger creeps.  The
    face's own width is its median over the rows nearer the root than
    ``reference_below_m``; the span ends before the first two rows running
    (root to tip) that read more than ``tolerance_m`` narrower.

    Returns
    -------
    (float, float)
        ``along_range_m`` cut short where the face is first hidden; the whole
        of it if no row near the root is seen to measure the width on.
    """
    lo, hi = along_range_m
    order = np.argsort(midline.along_m)
    along, width = midline.along_m[order], midline.width_m[order]
    near_root = along < reference_below_m
    if not near_root.any():
        return lo, hi
    narrow = width < float(np.median(width[near_root])) - tolerance_m
    keep = (along >= lo) & (along <= hi)
    along, narrow = along[keep], narrow[keep]
    hidden = np.flatnonzero(narrow[:-1] & narrow[1:])
    if hidden.size:
        first = int(hidden[0])
        hi = lo if first == 0 else 0.5 * (along[first] + along[first - 1])
    return lo, hi


def fit_contact_deflection_m(midline: FaceMidline, contact_m: float, temp_c: float,
                         finger: FingerParams, along_range_m: tuple[float, float] = ALONG_RANGE_M,
                         min_rows: int = 8) -> float:
    """The deflection at the contact that best explains a face midline (m).

    The beam model's deflection profile for a load at ``contact_m`` on a
    finger at ``temp_c``, scaled by least squares to the midline's points
    within ``along_range_m``.

    Parameters
    ----------
    midline : FaceMidline
        A finger's midline from :meth:`FaceBendReader.read`.
    contact_m : float
        Where the object touches the finger (m from the root).
    temp_c : float
        The finger's temperature (°C), taken uniform.
    finger : FingerParams
        Finger constants for the beam model.
    along_range_m : (float, float)
        The span of the finger whose points are fitted (m).
    min_rows : int
        Fewer points than this give nan.

    Returns
    -------
    float
        Deflection at the contact (m, outwards); nan if too few points or
        an unusable contact or temperature.
    """
    if not (math.isfinite(contact_m) and 0.0 < contact_m <= finger.length_m
            and math.isfinite(temp_c)):
        return math.nan
    lo, hi = along_range_m
    keep = (midline.along_m >= lo) & (midline.along_m <= hi)
    if int(keep.sum()) < min_rows:
        return math.nan
    shape = deflection_share(midline.along_m[keep], contact_m, temp_c, finger)
    return float(shape @ midline.bend_m[keep] / (shape @ shape))
