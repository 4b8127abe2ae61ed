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
decides which surface a pixel sees, so near things cover far ones.  A
microbolometer pixel integrates over its area: where an outline may cross a
pixel (it or a neighbour sees another surface), ``samples_per_px`` squared
rays spread over its area are cast, and the pixel is their mean, so an
outline moves the image however little it moves.  Then the optics blur the
radiance, and the sensor adds its fixed offset and its per-pixel noise.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from relaxgrip.errors import InputError
from relaxgrip.rig import CameraIntrinsics, RigGeometry, transform_points
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


class _FaceFrame(NamedTuple):
    """A finger's top face in the camera frame: its root, and unit steps along and across."""

    origin: FloatArray
    e_along: FloatArray
    e_across: FloatArray


class _Samples(NamedTuple):
    """The pixels an outline may cross, ``mixed``, and what each of their samples meets:
    per face its mask and where along it (m), per object its mask (``(n, k * k)``)."""

    mixed: NDArray[np.bool_]
    faces: list[tuple[NDArray[np.bool_], FloatArray]]
    spheres: list[NDArray[np.bool_]]


@lru_cache(maxsize=8)
def _camera_rays(intrinsics: CameraIntrinsics, k: int) -> tuple[
        FloatArray, FloatArray, FloatArray | None, FloatArray | None]:
    """Directions (x/z, y/z) of the ray through each pixel centre, distortion included,
    ``(H, W)`` each; with ``k > 1`` samples a pixel also those of the ``k * k`` rays spread
    over each pixel's area, ``(H, W, k * k)``, cast only near outlines.  Made once per
    camera and shared by every renderer (read-only): a dataset makes a twin per unit."""
    h, w = intrinsics.shape
    grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), axis=-1).astype(np.float64)
    normalized = intrinsics.normalized(grid)
    rays: list[FloatArray | None] = [np.ascontiguousarray(normalized[..., 0]),
                                     np.ascontiguousarray(normalized[..., 1]), None, None]
    if k > 1:
        offsets = (np.arange(k) + 0.5) / k - 0.5
        sub = np.stack(np.meshgrid(offsets, offsets), axis=-1).reshape(-1, 2)  # (k*k, 2)
        samples = intrinsics.normalized(grid[:, :, None, :] + sub)
        rays[2] = np.ascontiguousarray(samples[..., 0])
        rays[3] = np.ascontiguousarray(samples[..., 1])
    for ray in rays:
        if ray is not None:
            ray.flags.writeable = False
    x, y, sx, sy = rays
    assert x is not None
    assert y is not None
    return x, y, sx, sy


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
        self._ray_x, self._ray_y, self._sample_ray_x, self._sample_ray_y = _camera_rays(
            self.intrinsics, config.samples_per_px)
        self._hit_cache: tuple[
            tuple[object, ...], list[_FaceHits], list[_SphereHits | None], _Samples | None
        ] | None = None

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
        img = self._scene_radiance(temps, nodes, aperture, objects, ambient, bend)

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
        """The signal ``T_app^4`` (K^4) of each pixel, before the optics.

        A pixel is what its centre ray meets; with several samples a pixel,
        one that an outline may cross (it or a neighbour sees another
        surface) is the mean of its samples.
        """
        cfg = self.config
        h, w = self.intrinsics.shape
        background = float(_radiance(ambient_c, cfg.background_emissivity, ambient_c))
        img = np.full((h, w), background, dtype=np.float32)
        faces, spheres, sampled = self._hits(aperture_m, objects, bend)
        for j, (rows, cols, seen, along) in enumerate(faces):
            field = np.interp(along, nodes, temps[j])
            img[rows, cols][seen] = _radiance(field, cfg.finger_emissivity, ambient_c)
        for obj, hit in zip(objects, spheres, strict=True):
            if hit is not None:
                rows, cols, seen = hit
                img[rows, cols][seen] = np.float32(_radiance(obj.temp_c, obj.emissivity,
                                                             ambient_c))
        if sampled is not None:
            mixed, face_samples, sphere_samples = sampled
            signal = np.full(face_samples[0][0].shape, background)
            for j, (seen, along) in enumerate(face_samples):
                signal[seen] = _radiance(np.interp(along, nodes, temps[j]),
                                         cfg.finger_emissivity, ambient_c)
            for obj, seen in zip(objects, sphere_samples, strict=True):
                signal[seen] = _radiance(obj.temp_c, obj.emissivity, ambient_c)
            img[mixed] = signal.mean(axis=1)
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
    ) -> tuple[list[_FaceHits], list[_SphereHits | None], _Samples | None]:
        """What each pixel's centre ray meets, nearest surface first, and the samples.

        The geometry moves only with the aperture, the bend and the objects,
        which a hold keeps nearly still for minutes: the ray cast of the last
        geometry is kept, and only the temperatures are painted anew.
        """
        bend_key = None if bend is None else (bend[0].tobytes(), np.asarray(bend[1]).tobytes())
        key = (aperture_m, tuple((o.center_gripper_m, o.radius_m) for o in objects), bend_key)
        if self._hit_cache is not None and self._hit_cache[0] == key:
            return self._hit_cache[1:]
        bends = [None if bend is None else (bend[0], np.asarray(bend[1])[j]) for j in (0, 1)]
        frames = [self._face_frame(j, aperture_m) for j in (0, 1)]
        centres = [self._sphere_centre(o) for o in objects]
        h, w = self.intrinsics.shape
        depth = np.full((h, w), np.inf)
        faces = [self._cast_face(depth, frames[j], bends[j]) for j in (0, 1)]
        spheres = [None if c is None else self._cast_sphere(depth, c, o.radius_m)
                   for c, o in zip(centres, objects, strict=True)]
        sampled = None
        if self._sample_ray_x is not None and self._sample_ray_y is not None:
            # Which surface each pixel centre sees: 0 the room, 1 and 2 the faces, then
            # the objects.  A pixel whose neighbourhood sees one surface lies inside it.
            labels = np.zeros((h, w), np.uint16)
            for j, hit in enumerate(faces):
                labels[hit.rows, hit.cols][hit.seen] = 1 + j
            for i, s_hit in enumerate(spheres):
                if s_hit is not None:
                    labels[s_hit.rows, s_hit.cols][s_hit.seen] = min(3 + i, 65535)
            kernel = np.ones((3, 3), np.uint8)
            mixed = cv2.dilate(labels, kernel) != cv2.erode(labels, kernel)
            rx, ry = self._sample_ray_x[mixed], self._sample_ray_y[mixed]
            sample_depth = np.full(rx.shape, np.inf)
            face_samples = [self._face_rays(frames[j], rx, ry, sample_depth, bends[j])
                            for j in (0, 1)]
            sphere_samples = [np.zeros(rx.shape, bool) if c is None
                              else self._sphere_rays(c, o.radius_m, rx, ry, sample_depth)
                              for c, o in zip(centres, objects, strict=True)]
            sampled = _Samples(mixed, face_samples, sphere_samples)
        self._hit_cache = (key, faces, spheres, sampled)
        return faces, spheres, sampled

    def _face_frame(self, j: int, aperture_m: float) -> _FaceFrame:
        """Finger ``j``'s top face in the camera: its root, and one metre along and across."""
        ref = transform_points(
            self._gripper2cam,
            self.rig.top_points_gripper(j, aperture_m, [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
        )
        return _FaceFrame(ref[0], ref[1] - ref[0], ref[2] - ref[0])

    def _face_rays(self, face: _FaceFrame, rx: FloatArray, ry: FloatArray, depth: FloatArray,
                   bend: tuple[FloatArray, FloatArray] | None) -> tuple[NDArray[np.bool_],
                                                                         FloatArray]:
        """The rays ``(rx, ry, 1)`` that meet the face nearer than ``depth`` (marked there),
        and where along it (m).

        The face stays in its plane as the finger bends (the bend is across it): bent,
        it is the band ``|across - bend(along)| <= half`` of the plane.
        """
        finger = self.rig.finger
        origin, e_along, e_across = face
        normal = np.cross(e_along, e_across)
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
        seen = (
            (t > _NEAR_M)
            & (along >= 0.0)
            & (along <= finger.length_m)
            & (np.abs(across) <= 0.5 * finger.thickness_m)
            & (t < depth)
        )
        depth[seen] = t[seen]
        return seen, along[seen]

    def _cast_face(self, depth: FloatArray, face: _FaceFrame,
                   bend: tuple[FloatArray, FloatArray] | None = None) -> _FaceHits:
        """Ray cast a finger's top face through the pixel centres where it is nearest;
        mark its depth in ``depth``."""
        finger = self.rig.finger
        half = 0.5 * finger.thickness_m
        low, high = (0.0, 0.0) if bend is None else (min(0.0, float(bend[1].min())),
                                                      max(0.0, float(bend[1].max())))
        origin, e_along, e_across = face
        corners = origin + np.array(
            [a * finger.length_m * e_along + c * e_across
             for a in (0, 1) for c in (low - half, high + half)]
        )
        rows, cols = self._window(corners)
        rx, ry = self._ray_x[rows, cols], self._ray_y[rows, cols]
        if rx.size == 0:
            return _FaceHits(rows, cols, np.zeros(rx.shape, bool), np.empty(0))
        seen, along = self._face_rays(face, rx, ry, depth[rows, cols], bend)
        return _FaceHits(rows, cols, seen, along)

    def _sphere_centre(self, obj: IrObject) -> FloatArray | None:
        """An object's centre in the camera; None if it is around the lens or behind it."""
        centre = transform_points(self._gripper2cam, np.asarray(obj.center_gripper_m))
        r = obj.radius_m
        if float(centre @ centre) <= r * r or centre[2] + r <= _NEAR_M:
            return None  # nothing sensible to draw
        return centre

    def _sphere_rays(self, centre: FloatArray, r: float, rx: FloatArray, ry: FloatArray,
                     depth: FloatArray) -> NDArray[np.bool_]:
        """The rays ``(rx, ry, 1)`` that meet the sphere nearer than ``depth`` (marked there)."""
        # |t d - c|^2 = r^2 with d = (x, y, 1): a t^2 - 2 b t + (|c|^2 - r^2) = 0; near root.
        a = rx * rx + ry * ry + 1.0
        b = centre[0] * rx + centre[1] * ry + centre[2]
        disc = b * b - a * (float(centre @ centre) - r * r)
        hit = disc >= 0.0
        t = np.full(rx.shape, np.inf)
        t[hit] = (b[hit] - np.sqrt(disc[hit])) / a[hit]
        seen: NDArray[np.bool_] = hit & (t > _NEAR_M) & (t < depth)
        depth[seen] = t[seen]
        return seen

    def _cast_sphere(self, depth: FloatArray, centre: FloatArray, r: float
                     ) -> _SphereHits | None:
        """Ray cast an object (a sphere) through the pixel centres where it is nearest;
        mark its depth in ``depth``."""
        # The sphere's image lies within that of its bounding cube.
        cube = centre + r * np.array(
            [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64
        )
        rows, cols = self._window(cube)
        rx, ry = self._ray_x[rows, cols], self._ray_y[rows, cols]
        if rx.size == 0:
            return None
        seen = self._sphere_rays(centre, r, rx, ry, depth[rows, cols])
        if not np.any(seen):
            return None
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
