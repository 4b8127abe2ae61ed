"""Perception: frames and encoder in, marker pose, thermal state and ICFN features out.

:class:`Perception` reads only what a real gripper provides (RGB and
infrared frames, the motor encoder); it never sees an
:class:`~relaxgrip.backend.Observation`'s ground truth, because it is never
handed one.  The 30 Hz and 1 Hz streams are synchronised by holding the
latest infrared features between infrared frames; every percept says how old
they are, and a consumer (the temperature loop) decides when they are too
old to act on.  A bad frame gives an ``invalid`` state for that stream, never
an exception.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import Frame
from relaxgrip.perception.features import build_icfn_features
from relaxgrip.perception.frames import FrameError
from relaxgrip.perception.marker import MarkerState, MarkerTracker, TrackStatus
from relaxgrip.perception.proximity import Proximity, ProximityEstimator, ProximityTarget
from relaxgrip.perception.thermal import ThermalFeatures, ThermalPerception
from relaxgrip.rig import RigGeometry

FloatArray = NDArray[np.float64]

__all__ = ["Percept", "Perception", "StreamSync", "finger_bend"]

#: The marker tab's outline relative to the black square (its white quiet
#: zone and a margin), masked out when looking for a target object.
_TAB_SCALE = 1.45


class StreamSync:
    """Hold the latest item of a slow stream and tell its age.

    Parameters
    ----------
    max_age_s : float
        Age beyond which the held item counts as stale.
    """

    def __init__(self, max_age_s: float) -> None:
        self.max_age_s = max_age_s
        self.latest: ThermalFeatures | None = None
        self.error: str = ""

    def hold(self, item: ThermalFeatures) -> None:
        """Replace the held item."""
        self.latest = item
        self.error = ""

    def age_s(self, t_s: float) -> float:
        """Age of the held item at ``t_s`` (s); ``inf`` if none yet."""
        return math.inf if self.latest is None else max(0.0, t_s - self.latest.t_s)

    def stale(self, t_s: float) -> bool:
        """Whether the held item is missing or older than ``max_age_s``."""
        return self.age_s(t_s) > self.max_age_s


@dataclass(frozen=True)
class Percept:
    """What perception makes of the sensors at one instant.

    Attributes
    ----------
    t_s : float
        Time of the RGB frame it is based on (s).
    marker : MarkerState
        Marker tracking for that frame.
    thermal : ThermalFeatures or None
        Latest infrared features (held between infrared frames).
    ir_age_s : float
        Age of ``thermal`` (s); ``inf`` if none yet.
    ir_error : str
        Why the last infrared frame was rejected, if it was.
    features : ndarray or None
        ICFN features (:data:`relaxgrip.perception.features.ICFN_SCHEMA`),
        when the marker is tracked and thermal features exist.
    proximity : Proximity or None
        Approach cue, when a target is set.
    """

    t_s: float
    marker: MarkerState
    thermal: ThermalFeatures | None
    ir_age_s: float
    ir_error: str
    features: FloatArray | None
    proximity: Proximity | None


class Perception:
    """The perception stage of the loop.

    Parameters
    ----------
    rig : RigGeometry
        Cameras, marker and fingers.
    tracker : MarkerTracker, optional
        Marker tracker (default: one for ``rig`` with default settings).
    thermal : ThermalPerception, optional
        Thermal feature extractor (default: one for ``rig``).
    max_ir_age_s : float
        Age beyond which infrared features count as stale (s).
    """

    def __init__(
        self,
        rig: RigGeometry,
        tracker: MarkerTracker | None = None,
        thermal: ThermalPerception | None = None,
        max_ir_age_s: float = 3.0,
    ) -> None:
        self.rig = rig
        if tracker is None:
            # Where the unbent finger's marker is: of two markers of its id, the finger's.
            tracker = MarkerTracker(rig.rgb.intrinsics, rig.marker, home_m=rig.marker_home_m)
        self.tracker = tracker
        self.thermal = thermal if thermal is not None else ThermalPerception(rig)
        self.ir = StreamSync(max_ir_age_s)
        self._proximity: ProximityEstimator | None = None
        self._last_rgb_seq: int | None = None
        self._last_ir_seq: int | None = None
        self._last_rgb_t: float | None = None
        self._last_ir_t: float | None = None
        self._last: Percept | None = None
        #: The marker finger's bend at the tab, (deflection m, slope rad), as last tracked.
        self._bend: tuple[float, float] | None = None

    def set_target(self, target: ProximityTarget | None) -> None:
        """Look for ``target`` in the RGB frames (``None`` to stop)."""
        self._proximity = None if target is None else ProximityEstimator(self.rig, target)

    def reset(self) -> None:
        """Forget the zero pose, the held infrared features and the last frames."""
        self.tracker.reset()
        self.ir = StreamSync(self.ir.max_age_s)
        self._last_rgb_seq = self._last_ir_seq = None
        self._last_rgb_t = self._last_ir_t = None
        self._last = None
        self._bend = None

    def update(self, rgb: Frame | None, ir: Frame | None, motor_position_mm: float) -> Percept:
        """Process whatever frames are new.

        Parameters
        ----------
        rgb, ir : Frame or None
            The latest frames of each stream (the same frame may come again:
            it is processed once).
        motor_position_mm : float
            Encoder position, for where the fingers are.

        Returns
        -------
        Percept
        """
        # A frame is processed once, and only if it is newer than the last of its stream
        # (a frame delivered again after a later one would set the clock back).
        new_ir = ir is not None and ir.seq != self._last_ir_seq and _newer(ir, self._last_ir_t)
        if ir is not None and new_ir:
            self._last_ir_seq, self._last_ir_t = ir.seq, ir.t_s
            try:
                self.ir.hold(self.thermal.extract(ir, motor_position_mm, self._bend))
            except FrameError as exc:
                self.ir.error = str(exc)
        if rgb is None:
            t_s = self._last.t_s if self._last is not None else 0.0
            marker = MarkerState(t_s, TrackStatus.INVALID, message="no RGB frame")
            return self._percept(marker, None, None)
        if self._last is not None and (rgb.seq == self._last_rgb_seq
                                       or not _newer(rgb, self._last_rgb_t)):
            if new_ir:  # the marker as it was, with the infrared frame just read
                last = self._last
                self._last = self._percept(last.marker, last.proximity, last.t_s)
            return self._last
        self._last_rgb_seq, self._last_rgb_t = rgb.seq, rgb.t_s
        marker = self.tracker.update(rgb)
        if (self.rig.ir_follow_bend and marker.delta_t_m is not None
                and marker.delta_r_rad is not None):
            self._bend = finger_bend(self.rig, marker.delta_t_m, marker.delta_r_rad)
        proximity = None
        if self._proximity is not None and marker.status is not TrackStatus.INVALID:
            tab = None
            if marker.pose is not None:
                corners = marker.pose.corners_px
                centre = corners.mean(axis=0)
                tab = centre + _TAB_SCALE * (corners - centre)
            proximity = self._proximity.estimate(rgb, motor_position_mm, tab)
        self._last = self._percept(marker, proximity, rgb.t_s)
        return self._last

    def _percept(self, marker: MarkerState, proximity: Proximity | None,
                 t_s: float | None) -> Percept:
        t = marker.t_s if t_s is None else t_s
        thermal = self.ir.latest
        features = None if thermal is None else build_icfn_features(marker, thermal)
        return Percept(t, marker, thermal, self.ir.age_s(t), self.ir.error, features, proximity)


def finger_bend(rig: RigGeometry, delta_t_m: FloatArray, delta_r_rad: FloatArray
                ) -> tuple[float, float]:
    """The marker finger's deflection (m, outwards) and slope (rad) at the tab, from the
    marker's pose relative to its zero (camera frame): the camera is fixed to the finger's
    root, so the tab's move is the bend (:meth:`~relaxgrip.rig.MarkerMount.marker2finger`)."""
    cam2finger = rig.rgb.cam2finger[:3, :3]
    return float(cam2finger[2] @ delta_t_m), -float(cam2finger[1] @ delta_r_rad)


def _newer(frame: Frame, last_t_s: float | None) -> bool:
    """Whether ``frame`` comes after the last frame of its stream (time ``last_t_s``)."""
    return math.isfinite(frame.t_s) and (last_t_s is None or frame.t_s > last_t_s)
