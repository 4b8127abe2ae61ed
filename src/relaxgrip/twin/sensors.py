"""How the twin's sensors misbehave: noise, offsets, blur, lighting, occlusion.

Geometry (where the cameras are and what they look at) lives in
:mod:`relaxgrip.rig`, shared with perception; what lives here is the twin's
side only: the imperfections a real sensor has and perception must cope with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from relaxgrip.errors import InputError
from relaxgrip.twin.objects import get_object

__all__ = ["ForceSensorConfig", "IrSensorConfig", "RgbSensorConfig", "SceneObject"]


@dataclass(frozen=True)
class RgbSensorConfig:
    """Rendering of the RGB camera.

    Attributes
    ----------
    drawing : {"supersampled", "exact"}
        How the marker tab is drawn.  ``"supersampled"``: warped from a
        texture at ``supersample`` times the resolution, then area-averaged
        down.  ``"exact"``: each pixel gets the exact area of the tab's white
        and of each black run it covers (:mod:`relaxgrip.twin.raster`), as a
        camera pixel integrates the light on its area; faster, and the
        marker's bend reads closer than at 8 (the rotation's error along a
        bend 4.6 mdeg SD against 5.8 at 8 and 8.5 at 4;
        ``tests/twin/test_render_rgb.py``).
    supersample : int
        Supersampling factor of the ``"supersampled"`` drawing: the marker is
        warped at this multiple of the resolution, then area-averaged down
        (antialiased, sub-pixel edges), from a texture of 12 pixels a module
        per unit.  Fewer are faster but read the marker's bend less exactly:
        the rotation's error along a bend is 15 mdeg SD at 2, 8.8 at 4
        (docs/hold-experiments.md, session 49).
    noise_dn : float
        Standard deviation of the pixel noise (8-bit levels).
    blur_sigma_px : float
        Gaussian blur of the optics (pixels); 0 for none.
    lighting_gain : float
        Overall brightness factor (1 is nominal).
    lighting_flicker : float
        Relative frame-to-frame brightness jitter (standard deviation).
    occlusion : float
        Fraction of the marker width covered from its left side (0 for none).
    """

    drawing: str = "exact"
    supersample: int = 4
    noise_dn: float = 2.0
    blur_sigma_px: float = 0.0
    lighting_gain: float = 1.0
    lighting_flicker: float = 0.0
    occlusion: float = 0.0

    def __post_init__(self) -> None:
        if self.drawing not in ("supersampled", "exact"):
            raise InputError(f"drawing must be 'supersampled' or 'exact', got {self.drawing!r}")
        if (isinstance(self.supersample, bool) or not isinstance(self.supersample, int)
                or not 1 <= self.supersample <= 8):
            raise InputError(f"supersample must be an integer 1-8, got {self.supersample!r}")
        if not all(0 <= v < math.inf
                   for v in (self.noise_dn, self.blur_sigma_px, self.lighting_flicker)):
            raise InputError("noise, blur and flicker must be finite and >= 0")
        if not 0.05 <= self.lighting_gain <= 4.0:
            raise InputError(f"lighting_gain must be in [0.05, 4], got {self.lighting_gain}")
        if not 0.0 <= self.occlusion <= 1.0:
            raise InputError(f"occlusion must be in [0, 1], got {self.occlusion}")


@dataclass(frozen=True)
class IrSensorConfig:
    """Rendering of the infrared (microbolometer) camera.

    Attributes
    ----------
    netd_k : float
        Noise-equivalent temperature difference: per-pixel noise std (K).
    max_offset_k : float
        Each camera (each gripper unit) has a fixed offset drawn uniformly in
        ``±max_offset_k`` (K): the absolute accuracy of an uncalibrated core.
    finger_emissivity : float
        Emissivity of the finger skin.
    background_emissivity : float
        Emissivity of the scene behind the fingers (at ambient temperature).
    psf_sigma_px : float
        Gaussian blur of the optics (pixels).
    draw_bend : bool
        Draw the fingers bent by their load (their top faces move outwards,
        12 mm at the distal beam under 8 N at 55 °C), as a camera sees them:
        on by default, and the shipped models are trained on these frames,
        read where the load bends the fingers (``RigGeometry.ir_follow_bend``).
        Drawn unbent, the distal beams lie inside a held ball's silhouette and
        read the ball, a cue no real camera gives (twin v4 and before).
    samples_per_px : int
        Each pixel is the mean radiance over ``samples_per_px`` squared rays
        spread across its area, as a microbolometer integrates its pixel
        (twin v7: 4); 1 (twin v6) casts one ray through its centre, so that
        an outline moves in the image only when it crosses a pixel centre.
        Read in the frame, a finger's bend is then placed to 0.038 mm SD at
        1 sample and 0.0053 mm at 4 (noise-free frames, the amplitude stepped
        by 10 µm).  Only the pixels an outline may cross are sampled (inside
        a surface the mean is its centre's to 0.0015 K): a frame takes about
        3 ms at 4 against 1.3 ms at 1.
    """

    netd_k: float = 0.05
    max_offset_k: float = 1.0
    finger_emissivity: float = 0.95
    background_emissivity: float = 0.95
    psf_sigma_px: float = 0.7
    draw_bend: bool = True
    samples_per_px: int = 4

    def __post_init__(self) -> None:
        if not all(0 <= v < math.inf for v in (self.netd_k, self.max_offset_k, self.psf_sigma_px)):
            raise InputError("NETD, offset and blur must be finite and >= 0")
        if (isinstance(self.samples_per_px, bool) or not isinstance(self.samples_per_px, int)
                or not 1 <= self.samples_per_px <= 8):
            raise InputError(f"samples_per_px must be an integer in 1-8, got "
                             f"{self.samples_per_px!r}")
        for name in ("finger_emissivity", "background_emissivity"):
            if not 0.0 < getattr(self, name) <= 1.0:
                raise InputError(f"{name} must be in (0, 1], got {getattr(self, name)}")


@dataclass(frozen=True)
class ForceSensorConfig:
    """The force-measurement ball's internal sensor.

    Attributes
    ----------
    rate_hz : float
        Sampling rate (Hz).
    noise_n : float
        Measurement noise std (N).
    """

    rate_hz: float = 100.0
    noise_n: float = 0.01

    def __post_init__(self) -> None:
        if not 0 < self.rate_hz < math.inf:
            raise InputError(f"force sensor rate_hz must be finite and > 0, got {self.rate_hz}")
        if not 0 <= self.noise_n < math.inf:
            raise InputError(f"force sensor noise_n must be finite and >= 0, got {self.noise_n}")


@dataclass(frozen=True)
class SceneObject:
    """A catalogue object standing in the scene, seen by the cameras but not grasped.

    Attributes
    ----------
    name : str
        Catalogue key (see :data:`relaxgrip.twin.objects.CATALOGUE`).
    position_m : tuple of float
        Centre in the world frame, which is the gripper frame at reset (m).
    """

    name: str
    position_m: tuple[float, float, float]

    def __post_init__(self) -> None:
        get_object(self.name)
