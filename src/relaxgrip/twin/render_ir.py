"""The twin's infrared camera: a radiometric microbolometer looking at both fingers.

The scene is painted in radiance, not in temperature: every surface gets the
broadband graybody signal a radiometric camera set to emissivity 1 receives,
``T_app^4 = ε T^4 + (1 - ε) T_refl^4`` (kelvin), with the room at ambient as
the reflected surroundings.  A low-emissivity object (bare aluminium) so
shows the room, not itself.

Surfaces are ray cast through the centre of each pixel: a finger's contact
face is a rectangle whose plane maps to the image by a homography, so each
pixel gets the exact position along the finger it sees and the temperature
the thermal nodes give there (no stair steps, however foreshortened the face);
an object is a sphere, which also gives its exact silhouette.  A depth buffer
decides which surface a pixel sees, so near things cover far ones.  Then the
optics blur the radiance, and the sensor adds its fixed offset and its
per-pixel noise.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import NamedTuple

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from relaxgrip.errors import InputError
from relaxgrip.rig import RigGeometry, transform_points
from relaxgrip.twin.sensors import IrSensorConfig
from relaxgrip.validate import ABSOLUTE_ZERO_C, check_finite, check_temp_c

FloatArray = NDArray[np.float64]

__all__ = ["IrObject", "IrRenderer", "apparent_temp_c"]

#: Pre-drawn noise: banks of a frame plus this margin, sliced at a random offset per frame.
_NOISE_BANKS = 4
_NOISE_PAD = 32

#: Surfaces nearer to the lens than this are not drawn (m).
_NEAR_M = 0.005
#: Margin around a surface's projected bounding box that is ray cast (pixels).
_MARGIN_PX = 3


@dataclass(frozen=True)
class IrObject:
    """An object seen by the IR camera: a sphere-like blob.

    Attributes
    ----------
    center_gripper_m : tuple of float
        Centre in the gripper frame ``G`` (m).
    radius_m : float
        Radius (m).
    temp_c : float
        Surface temperature (°C).
    emissivity : float
        Broadband emissivity in (0, 1].
    """

    center_gripper_m: tuple[float, float, float]
    radius_m: float
    temp_c: float
    emissivity: float

    def __post_init__(self) -> None:
        if len(self.center_gripper_m) != 3 or not all(
            math.isfinite(c) for c in self.center_gripper_m
        ):
            raise InputError(f"object centre must be 3 finite numbers, got {self.center_gripper_m}")
        if not (math.isfinite(self.radius_m) and self.radius_m > 0):
            raise InputError(f"object radius must be > 0 m, got {self.radius_m}")
        check_temp_c(self.temp_c, "object temperature")
        if not 0.0 < self.emissivity <= 1.0:
            raise InputError(f"object emissivity must be in (0, 1], got {self.emissivity}")


def apparent_temp_c(temp_c: ArrayLike, emissivity: float, reflected_c: float) -> FloatArray:
    """Temperature a radiometric camera set to emissivity 1 reports for a graybody.

    Broadband approximation: ``T_app^4 = ε T^4 + (1 - ε) T_refl^4`` in kelvin.

    Parameters
    ----------
    temp_c : array_like
        True surface temperatures (°C).
    emissivity : float
        Emissivity of the surface, in (0, 1].
    reflected_c : float
        Temperature of the surroundings the surface reflects (°C).

    Returns
    -------
    ndarray
        Apparent temperatures (°C), shaped like ``temp_c``.
    """
    out: FloatArray = np.sqrt(np.sqrt(_radiance(temp_c, emissivity, reflected_c)))
    out += ABSOLUTE_ZERO_C
    return out


def _radiance(temp_c: ArrayLike, emissivity: float, reflected_c: float) -> FloatArray:
    """Apparent signal ``T_app^4`` (K^4) of a graybody: what the image holds before the sensor."""
    t_k = np.asarray(temp_c, dtype=np.float64) - ABSOLUTE_ZERO_C
    r_k = reflected_c - ABSOLUTE_ZERO_C
    out: FloatArray = emissivity * t_k**4 + (1.0 - emissivity) * r_k**4
    return out


class _FaceHits(NamedTuple):
    """The pixels of a window that see a finger's face, and where along the face (m)."""

    rows: slice
    cols: slice
    seen: NDArray[np.bool_]
    along_m: FloatArray


class _SphereHits(NamedTuple):
    """The pixels of a window that see an object."""

    rows: slice
    cols: slice
    seen: NDArray[np.bool_]


class IrRenderer:
    """Renders the frames of the infrared camera on the gripper base.

    Parameters
    ----------
    rig : RigGeometry
        Camera mount, intrinsics and finger shape.
    config : IrSensorConfig
        Noise, offset, emissivities and blur.
    seed : int
        Seed of the run: frame ``seq`` of a seed is always the same image,
        whatever other frames were rendered.
    unit : int
        The gripper unit this camera belongs to: fixes its offset.
    """

    def __init__(self, rig: RigGeometry, config: IrSensorConfig, seed: int,
                 unit: int = 0) -> None:
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise InputError(f"seed must be a non-negative integer, got {seed!r}")
        self.rig = rig
        self.config = config
        self.seed = int(seed)
        self.intrinsics = rig.ir.intrinsics
        self._gripper2cam = rig.ir.gripper2cam
        self._offset_k = float(
            np.random.default_rng([int(unit), 3]).uniform(-config.max_offset_k, config.max_offset_k)
        )
        # Direction (x/z, y/z, 1) of the ray through each pixel centre, distortion included.
        h, w = self.intrinsics.shape
        grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), axis=-1).astype(np.float64)
        normalized = self.intrinsics.normalized(grid)
        self._ray_x = np.ascontiguousarray(normalized[..., 0])
        self._ray_y = np.ascontiguousarray(normalized[..., 1])
        self._hit_cache: tuple[
            tuple[object, ...], list[_FaceHits], list[_SphereHits | None]
        ] | None = None
        #: With several samples a pixel: the same camera with that many pixels a side
        #: more, whose pixel centres are the samples (its scene only is drawn).
        self._fine: IrRenderer | None = None
        k = config.samples_per_px
        if k > 1:
            intr = self.intrinsics
            fine = replace(intr, width_px=intr.width_px * k, height_px=intr.height_px * k,
                           fx_px=intr.fx_px * k, fy_px=intr.fy_px * k,
                           cx_px=k * intr.cx_px + 0.5 * (k - 1),
                           cy_px=k * intr.cy_px + 0.5 * (k - 1))
            self._fine = IrRenderer(replace(rig, ir=replace(rig.ir, intrinsics=fine)),
                                    replace(config, samples_per_px=1), seed, unit)

    @property
    def offset_k(self) -> float:
        """This camera's fixed offset (K), drawn once from its unit in ``±max_offset_k``."""
        return self._offset_k

    def render(
        self,
        seq: int,
        finger_temps_c: ArrayLike,
        node_positions_m: ArrayLike,
        aperture_m: float,
        objects: Sequence[IrObject],
        ambient_c: float,
        bend: tuple[FloatArray, FloatArray] | None = None,
    ) -> NDArray[np.float32]:
        """Render frame ``seq``.

        Parameters
        ----------
        seq : int
            Frame number: selects the frame's noise.
        finger_temps_c : array_like, shape (2, n_nodes)
            Node temperatures of finger 0 and finger 1 (°C).
        node_positions_m : array_like, shape (n_nodes,)
            Node positions along the finger (m from the root), increasing.  The
            temperature between nodes is interpolated linearly, and held
            constant beyond the first and last node.
        aperture_m : float
            Gap between the contact faces (m).
        objects : sequence of IrObject
            Objects in the scene, in any order.
        ambient_c : float
            Temperature of the room: the background and what surfaces reflect (°C).
        bend : (grid, deflections), optional
            The fingers' deflection outwards (m), ``(2, n)``, at positions
            ``grid`` along them (m from the root, increasing; interpolated
            linearly): their top faces are drawn bent.  None: unbent.

        Returns
        -------
        ndarray, shape (H, W), float32
            Apparent temperatures (°C) as a radiometric camera set to
            emissivity 1 reports them, offset and noise included.
        """
        if isinstance(seq, bool) or not isinstance(seq, int | np.integer) or seq < 0:
            raise InputError(f"seq must be a non-negative integer, got {seq!r}")
        temps, nodes = self._check_fingers(finger_temps_c, node_positions_m)
        aperture = check_finite(aperture_m, "aperture_m")
        ambient = check_temp_c(ambient_c, "ambient_c")
        cfg = self.config

        h, w = self.intrinsics.shape
        if self._fine is None:
            img = self._scene_radiance(temps, nodes, aperture, objects, ambient, bend)
        else:
            # The mean radiance over each pixel's area: its samples averaged.
            fine = self._fine._scene_radiance(temps, nodes, aperture, objects, ambient, bend)
            img = np.asarray(cv2.resize(fine, (w, h), interpolation=cv2.INTER_AREA),
                             dtype=np.float32)

        if cfg.psf_sigma_px > 0:
            cv2.GaussianBlur(
                img, (0, 0), cfg.psf_sigma_px, dst=img, borderType=cv2.BORDER_REPLICATE
            )
        out = np.sqrt(np.sqrt(img, out=img), out=img)
        out += np.float32(self._offset_k + ABSOLUTE_ZERO_C)
        if cfg.netd_k > 0:
            # Pre-drawn standard normals, sliced at an offset drawn for this frame.
            rng = np.random.default_rng([self.seed, 2, int(seq)])
            bank = _noise_bank((h, w))
            b = int(rng.integers(bank.shape[0]))
            oy, ox = (int(v) for v in rng.integers(0, _NOISE_PAD, size=2))
            out += np.float32(cfg.netd_k) * bank[b, oy : oy + h, ox : ox + w]
        return out

    def _scene_radiance(self, temps: FloatArray, nodes: FloatArray, aperture_m: float,
                        objects: Sequence[IrObject], ambient_c: float,
                        bend: tuple[FloatArray, FloatArray] | None) -> NDArray[np.float32]:
        """The signal ``T_app^4`` (K^4) each pixel's centre ray meets: before the optics."""
        cfg = self.config
        h, w = self.intrinsics.shape
        background = float(_radiance(ambient_c, cfg.background_emissivity, ambient_c))
        img = np.full((h, w), background, dtype=np.float32)
        faces, spheres = self._hits(aperture_m, objects, bend)
        for j, (rows, cols, seen, along) in enumerate(faces):
            field = np.interp(along, nodes, temps[j])
            img[rows, cols][seen] = _radiance(field, cfg.finger_emissivity, ambient_c)
        for obj, hit in zip(objects, spheres, strict=True):
            if hit is not None:
                rows, cols, seen = hit
                img[rows, cols][seen] = np.float32(_radiance(obj.temp_c, obj.emissivity,
                                                             ambient_c))
        return img

    def _check_fingers(
        self, finger_temps_c: ArrayLike, node_positions_m: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        temps = np.asarray(finger_temps_c, dtype=np.float64)
        nodes = np.asarray(node_positions_m, dtype=np.float64)
        if nodes.ndim != 1 or nodes.size < 1:
            raise InputError(f"node_positions_m must be a 1-D array, got shape {nodes.shape}")
        if temps.shape != (2, nodes.size):
            raise InputError(
                f"finger_temps_c must have shape (2, {nodes.size}), got {temps.shape}"
            )
        if not (np.all(np.isfinite(nodes)) and np.all(np.diff(nodes) > 0)):
            raise InputError("node_positions_m must be finite and increasing")
        if not np.all(np.isfinite(temps)) or float(temps.min()) <= ABSOLUTE_ZERO_C:
            raise InputError("finger temperatures must be finite and above absolute zero")
        return temps, nodes

    def _window(self, corners_cam_m: FloatArray) -> tuple[slice, slice]:
        """Image rows and columns that can see the convex hull of ``corners_cam_m``.

        The whole image if any corner is behind the lens (its projection is unbounded).
        """
        h, w = self.intrinsics.shape
        if np.any(corners_cam_m[:, 2] <= _NEAR_M):
            return slice(0, h), slice(0, w)
        px = self.intrinsics.project(corners_cam_m)
        pad = _MARGIN_PX
        x0 = max(0, math.floor(float(px[:, 0].min()) - pad))
        x1 = min(w, math.ceil(float(px[:, 0].max()) + pad) + 1)
        y0 = max(0, math.floor(float(px[:, 1].min()) - pad))
        y1 = min(h, math.ceil(float(px[:, 1].max()) + pad) + 1)
        return slice(y0, max(y0, y1)), slice(x0, max(x0, x1))

    def _hits(
        self, aperture_m: float, objects: Sequence[IrObject],
        bend: tuple[FloatArray, FloatArray] | None = None,
    ) -> tuple[list[_FaceHits], list[_SphereHits | None]]:
        """The pixels that see each finger's face and each object, nearest surface first.

        The geometry moves only with the aperture, the bend and the objects,
        which a hold keeps nearly still for minutes: the ray cast of the last
        geometry is kept, and only the temperatures are painted anew.
        """
        bend_key = None if bend is None else (bend[0].tobytes(), np.asarray(bend[1]).tobytes())
        key = (aperture_m, tuple((o.center_gripper_m, o.radius_m) for o in objects), bend_key)
        if self._hit_cache is not None and self._hit_cache[0] == key:
            return self._hit_cache[1], self._hit_cache[2]
        h, w = self.intrinsics.shape
        depth = np.full((h, w), np.inf)
        faces = [self._cast_face(depth, j, aperture_m,
                                 None if bend is None else (bend[0], np.asarray(bend[1])[j]))
                 for j in (0, 1)]
        spheres = [self._cast_sphere(depth, o) for o in objects]
        self._hit_cache = (key, faces, spheres)
        return faces, spheres

    def _cast_face(self, depth: FloatArray, j: int, aperture_m: float,
                   bend: tuple[FloatArray, FloatArray] | None = None) -> _FaceHits:
        """Ray cast finger ``j``'s top face where it is nearest; mark its depth in ``depth``.

        The face stays in its plane as the finger bends (the bend is across it): bent,
        it is the band ``|across - bend(along)| <= half`` of the plane.
        """
        finger = self.rig.finger
        half = 0.5 * finger.thickness_m
        low, high = (0.0, 0.0) if bend is None else (min(0.0, float(bend[1].min())),
                                                      max(0.0, float(bend[1].max())))
        # The face's frame in the camera: origin at the root, unit vectors along and across.
        ref = transform_points(
            self._gripper2cam,
            self.rig.top_points_gripper(j, aperture_m, [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
        )
        origin, e_along, e_across = ref[0], ref[1] - ref[0], ref[2] - ref[0]
        normal = np.cross(e_along, e_across)
        corners = origin + np.array(
            [a * finger.length_m * e_along + c * e_across
             for a in (0, 1) for c in (low - half, high + half)]
        )
        rows, cols = self._window(corners)
        rx, ry = self._ray_x[rows, cols], self._ray_y[rows, cols]
        nothing = _FaceHits(rows, cols, np.zeros(rx.shape, bool), np.empty(0))
        if rx.size == 0:
            return nothing
        # The ray t (x, y, 1) meets the plane n . (p - o) = 0 at t = n . o / n . (x, y, 1);
        # t is the depth.
        with np.errstate(divide="ignore", invalid="ignore"):
            t = float(normal @ origin) / (normal[0] * rx + normal[1] * ry + normal[2])
        along = t * (e_along[0] * rx + e_along[1] * ry + e_along[2]) - float(e_along @ origin)
        across = t * (e_across[0] * rx + e_across[1] * ry + e_across[2]) - float(
            e_across @ origin
        )
        if bend is not None:
            across = across - np.interp(along, bend[0], bend[1])
        sub_depth = depth[rows, cols]
        seen = (
            (t > _NEAR_M)
            & (along >= 0.0)
            & (along <= finger.length_m)
            & (np.abs(across) <= half)
            & (t < sub_depth)
        )
        if not np.any(seen):
            return nothing
        sub_depth[seen] = t[seen]
        return _FaceHits(rows, cols, seen, along[seen])

    def _cast_sphere(self, depth: FloatArray, obj: IrObject) -> _SphereHits | None:
        """Ray cast an object (a sphere) where it is nearest; mark its depth in ``depth``."""
        centre = transform_points(self._gripper2cam, np.asarray(obj.center_gripper_m))
        r = obj.radius_m
        dist2 = float(centre @ centre)
        if dist2 <= r * r or centre[2] + r <= _NEAR_M:
            return None  # around the lens or behind it: nothing sensible to draw
        # The sphere's image lies within that of its bounding cube.
        cube = centre + r * np.array(
            [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64
        )
        rows, cols = self._window(cube)
        rx, ry = self._ray_x[rows, cols], self._ray_y[rows, cols]
        if rx.size == 0:
            return None
        # |t d - c|^2 = r^2 with d = (x, y, 1): a t^2 - 2 b t + (|c|^2 - r^2) = 0; near root.
        a = rx * rx + ry * ry + 1.0
        b = centre[0] * rx + centre[1] * ry + centre[2]
        disc = b * b - a * (dist2 - r * r)
        hit = disc >= 0.0
        t = np.full(rx.shape, np.inf)
        t[hit] = (b[hit] - np.sqrt(disc[hit])) / a[hit]
        sub_depth = depth[rows, cols]
        seen = hit & (t > _NEAR_M) & (t < sub_depth)
        if not np.any(seen):
            return None
        sub_depth[seen] = t[seen]
        return _SphereHits(rows, cols, seen)


@lru_cache(maxsize=4)
def _noise_bank(shape: tuple[int, int]) -> NDArray[np.float32]:
    """Standard normal noise shared by every renderer of a frame size (read-only)."""
    h, w = shape
    bank = np.random.default_rng(12).standard_normal(
        (_NOISE_BANKS, h + _NOISE_PAD, w + _NOISE_PAD), dtype=np.float32
    )
    bank.flags.writeable = False
    return bank
