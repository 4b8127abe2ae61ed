"""When the twin's sensors sample, and what they saw.

The cameras capture on their own clocks (30 Hz RGB, 1 Hz infrared, from the
twin's reset).  At each capture time the twin hands over a :class:`SceneState`
(a snapshot of what the camera would see); the image itself is rendered only
when someone observes it, so frames nobody looks at cost nothing.  A frame's
noise is drawn from ``(seed, stream, frame number)``: the same seed gives the
same frames whatever the observation rate.

The force ball's sensor samples at 100 Hz; between physics steps its true
force is interpolated linearly (a step is at most a camera period, over which
the force moves smoothly).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import ForceSamples, Frame
from relaxgrip.clock import TIME_SLACK_S
from relaxgrip.rig import invert_transform, transform_points
from relaxgrip.twin.config import TwinConfig
from relaxgrip.twin.objects import ObjectSpec
from relaxgrip.twin.render_ir import IrObject, IrRenderer
from relaxgrip.twin.render_rgb import RgbDrawing, RgbObject, RgbRenderer

FloatArray = NDArray[np.float64]

__all__ = ["DrawnFrame", "SceneState", "SensorSuite"]


@dataclass(frozen=True)
class SceneState:
    """What the cameras would see at one instant.

    Attributes
    ----------
    marker_deflection_m, marker_slope_rad : float
        Bending of the marker finger at the marker tab.
    aperture_m : float
        Gap between the undeflected contact faces (m).
    finger_temps_c : ndarray, shape (2, n_nodes)
        Node temperatures of both fingers (°C).
    ambient_c : float
        Air temperature (°C).
    objects : tuple of (ObjectSpec, centre in the gripper frame)
        Everything standing in view.
    finger_bend_m : (grid, deflections), optional
        Both fingers' deflection outwards (m), ``(2, n)``, at ``grid`` along
        them (m from the root); given when the infrared camera draws the bend
        (``IrSensorConfig.draw_bend``).
    """

    marker_deflection_m: float
    marker_slope_rad: float
    aperture_m: float
    finger_temps_c: FloatArray
    ambient_c: float
    objects: tuple[tuple[ObjectSpec, tuple[float, float, float]], ...]
    finger_bend_m: tuple[FloatArray, FloatArray] | None = None


class DrawnFrame(Frame):
    """An RGB frame of the twin, drawn when it is read.

    :attr:`image` draws the whole frame (once); :meth:`region` draws only the
    region asked for while the whole has not been drawn, with the pixels the
    whole frame has there (:class:`~relaxgrip.twin.render_rgb.RgbDrawing`).
    Pickled or copied, it is a plain :class:`~relaxgrip.backend.Frame`.
    """

    def __init__(self, t_s: float, seq: int, drawing: RgbDrawing) -> None:
        object.__setattr__(self, "t_s", t_s)
        object.__setattr__(self, "seq", seq)
        object.__setattr__(self, "_drawing", drawing)

    @property
    def image(self) -> NDArray[np.uint8]:
        """The whole frame, ``(H, W, 3)`` uint8."""
        drawing: RgbDrawing = self.__dict__["_drawing"]
        return drawing.image()

    def layout(self) -> object:
        """A zero-strided array of the frame's shape and dtype (no pixels drawn)."""
        drawing: RgbDrawing = self.__dict__["_drawing"]
        return np.broadcast_to(np.uint8(0), drawing.shape)

    def region(self, y0: int, y1: int, x0: int, x1: int) -> NDArray[np.uint8]:
        """The pixels ``[y0:y1, x0:x1]``, drawn alone unless the whole frame is."""
        drawing: RgbDrawing = self.__dict__["_drawing"]
        return drawing.region(y0, y1, x0, x1)

    def __reduce__(self) -> tuple[type[Frame], tuple[float, int, NDArray[np.uint8]]]:
        return Frame, (self.t_s, self.seq, self.image)

    def __deepcopy__(self, memo: dict[int, object]) -> Frame:
        return Frame(self.t_s, self.seq, self.image.copy())


class _Stream:
    """One camera's schedule and its latest capture."""

    def __init__(self, rate_hz: float, t0_s: float) -> None:
        self.period_s = 1.0 / rate_hz
        self.t0_s = t0_s
        self.next_seq = 0
        self.latest: tuple[int, float, SceneState] | None = None
        self.frame: Frame | None = None

    @property
    def next_t_s(self) -> float:
        return self.t0_s + self.next_seq * self.period_s


class SensorSuite:
    """The twin's cameras and reference force sensor.

    Parameters
    ----------
    config : TwinConfig
        Rig geometry and sensor imperfections.
    seed : int
        The twin's seed.
    t0_s : float
        Reset time: frame ``k`` is captured at ``t0_s + k / rate``.
    node_positions_m : ndarray
        Positions of the finger's thermal nodes (m from the root).
    """

    def __init__(self, config: TwinConfig, seed: int, t0_s: float,
                 node_positions_m: FloatArray) -> None:
        self.config = config
        rig = config.rig
        self._nodes_m = node_positions_m
        self._rgb = None if config.rgb is None else RgbRenderer(rig, config.rgb, seed)
        self._ir = None if config.ir is None else IrRenderer(rig, config.ir, seed, config.unit)
        self._rgb_stream = None if config.rgb is None else _Stream(rig.rgb.rate_hz, t0_s)
        self._ir_stream = None if config.ir is None else _Stream(rig.ir.rate_hz, t0_s)
        self._force_rng = np.random.default_rng([seed, 20])
        self._noise_pool: list[float] = []  # standard normals, drawn 1024 at a time
        self.force_sensor = config.force_sensor
        rate_hz = 1.0 if config.force_sensor is None else config.force_sensor.rate_hz
        self._force_period_s = 1.0 / rate_hz
        self._force_t0_s = t0_s
        self._force_next = 0  # index of the next sample instant
        self._trace_t: list[float] = []  # true force at physics-step ends since the last take
        self._trace_n: list[float] = []
        self.streams = tuple(s for s in (self._rgb_stream, self._ir_stream) if s is not None)
        self._next_capture_s = self._earliest_capture()

    def _earliest_capture(self) -> float:
        return min((s.next_t_s for s in self.streams), default=math.inf)

    def next_capture_s(self) -> float:
        """Time of the next camera capture (s), ``inf`` without cameras."""
        return self._next_capture_s

    def capture(self, t_s: float, scene: Callable[[], SceneState],
                until_s: float = -math.inf) -> None:
        """Record the scene for every camera whose capture is due at ``t_s``.

        Parameters
        ----------
        t_s : float
            Capture time (s).
        scene : callable
            Returns the scene now; called at most once, and only if a camera
            keeps this capture.
        until_s : float
            The twin advances to this time before anyone can look: a capture
            whose camera captures again by then is replaced unseen, and only
            its frame number is kept.
        """
        seen: SceneState | None = None
        for stream in self.streams:
            while stream.next_t_s <= t_s + TIME_SLACK_S:
                if stream.next_t_s + stream.period_s > until_s + TIME_SLACK_S:  # kept
                    if seen is None:
                        seen = scene()
                    stream.latest = (stream.next_seq, stream.next_t_s, seen)
                stream.next_seq += 1
        self._next_capture_s = self._earliest_capture()

    def rgb_frame(self) -> Frame | None:
        """The latest RGB frame, rendered on first request."""
        stream, renderer = self._rgb_stream, self._rgb
        if stream is None or renderer is None or stream.latest is None:
            return None
        seq, t_s, scene = stream.latest
        if stream.frame is None or stream.frame.seq != seq:
            marker2cam = self.config.rig.marker2cam(scene.marker_deflection_m,
                                                    scene.marker_slope_rad)
            stream.frame = DrawnFrame(t_s, seq, renderer.prepare(seq, marker2cam,
                                                                 self._rgb_objects(scene)))
        return stream.frame

    def ir_frame(self) -> Frame | None:
        """The latest infrared frame, rendered on first request."""
        stream, renderer = self._ir_stream, self._ir
        if stream is None or renderer is None or stream.latest is None:
            return None
        seq, t_s, scene = stream.latest
        if stream.frame is None or stream.frame.seq != seq:
            objects = [
                IrObject(centre, 0.5 * spec.width_m, spec.temp_c, spec.emissivity)
                for spec, centre in scene.objects
            ]
            image = renderer.render(seq, scene.finger_temps_c, self._nodes_m, scene.aperture_m,
                                    objects, scene.ambient_c, scene.finger_bend_m)
            stream.frame = Frame(t_s, seq, image)
        return stream.frame

    def _rgb_objects(self, scene: SceneState) -> list[RgbObject]:
        rig = self.config.rig
        gripper2finger = invert_transform(rig.finger2gripper(rig.marker_finger, scene.aperture_m))
        gripper2cam = rig.rgb.finger2cam @ gripper2finger
        out = []
        for spec, centre in scene.objects:
            x, y, z = transform_points(gripper2cam, centre).tolist()
            out.append(RgbObject((x, y, z), 0.5 * spec.width_m, spec.color_rgb))
        return out

    # -- reference force --------------------------------------------------
    def record_force(self, t_s: float, force_n: float) -> None:
        """Note the true force at a physics-step end (the sensor samples between them)."""
        self._trace_t.append(t_s)
        self._trace_n.append(force_n)

    def skip_force(self, t_s: float) -> None:
        """No sensor in the grasp up to ``t_s``: drop the trace, no samples until then."""
        n = math.floor((t_s - self._force_t0_s + TIME_SLACK_S) / self._force_period_s) + 1
        self._force_next = max(self._force_next, n)
        self._trace_t, self._trace_n = [], []

    def take_force(self) -> ForceSamples | None:
        """Readings at the sensor's instants covered by the trace since the last call."""
        trace_t, trace_n = self._trace_t, self._trace_n
        if len(trace_t) < 2:
            return None
        period, origin = self._force_period_s, self._force_t0_s
        first = max(self._force_next,
                    math.ceil((trace_t[0] - origin - TIME_SLACK_S) / period))
        last = math.floor((trace_t[-1] - origin + TIME_SLACK_S) / period)
        self._trace_t, self._trace_n = trace_t[-1:], trace_n[-1:]
        if last < first:
            return None
        self._force_next = last + 1
        # A handful of samples per observation: plain floats beat NumPy calls here.
        assert self.force_sensor is not None, "no force sensor configured"
        noise = self.force_sensor.noise_n
        times, forces = [], []
        j, end = 0, len(trace_t) - 2
        for k in range(first, last + 1):
            t = origin + k * period
            while j < end and trace_t[j + 1] < t:
                j += 1
            t0, t1 = trace_t[j], trace_t[j + 1]
            w = min(max((t - t0) / (t1 - t0), 0.0), 1.0) if t1 > t0 else 1.0
            if not self._noise_pool:
                self._noise_pool = self._force_rng.standard_normal(1024).tolist()
            times.append(t)
            forces.append(trace_n[j] + w * (trace_n[j + 1] - trace_n[j])
                          + noise * self._noise_pool.pop())
        return ForceSamples(np.array(times), np.array(forces))
