"""Camera frame sources of a real rig: OpenCV RGB, UVC radiometric thermal, the emulator's channel.

Every source has the same small interface, :class:`FrameSource`: ``start``,
``read(now_s)`` (the newest frame, or :class:`CameraStalledError` if none has
arrived for longer than ``stall_s``) and ``close``.  The serial gripper takes
its two sources by that interface; the rig file names which ones to build
(:func:`open_frame_sources`).

Live cameras are read by a thread that timestamps every frame on arrival with
the injected clock.  The emulator's source reads the frame channel
(:mod:`relaxgrip.hardware.frame_channel`); in lockstep it waits until the
emulator has sent every frame up to the time asked for.
"""

from __future__ import annotations

import collections
import contextlib
import socket
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import cv2
import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import ForceSamples, Frame, Truth
from relaxgrip.clock import Clock
from relaxgrip.errors import InputError
from relaxgrip.hardware.frame_channel import (
    KIND_IR,
    KIND_RGB,
    KIND_TICK,
    MessageReader,
    truth_from_dict,
)
from relaxgrip.hardware.rig_file import IrCameraSpec, RgbCameraSpec, RigFile

__all__ = [
    "CameraError",
    "CameraStalledError",
    "CaptureFactory",
    "EmulatorChannel",
    "EmulatorFrameSource",
    "FrameSource",
    "OpenCvRgbSource",
    "UvcThermalSource",
    "open_frame_sources",
]


class CameraError(InputError):
    """A camera could not be opened or delivers frames that make no sense."""


class CameraStalledError(CameraError):
    """A camera has delivered no frame for longer than its stall limit."""


@runtime_checkable
class FrameSource(Protocol):
    """A stream of timestamped frames from one camera."""

    name: str
    stall_s: float

    def start(self) -> None:
        """Open the camera and start receiving frames."""
        ...

    def read(self, now_s: float) -> Frame | None:
        """The newest frame at ``now_s``; ``None`` before the first.

        Raises
        ------
        CameraStalledError
            If no frame arrived for more than ``stall_s`` before ``now_s``.
        """
        ...

    def close(self) -> None:
        """Stop receiving and release the device."""
        ...


def _stalled(name: str, now_s: float, last_s: float, stall_s: float, had_frame: bool) -> None:
    age = now_s - last_s
    if age > stall_s + 1e-9:  # round-off of clock sums is not a stall
        what = "no new frame" if had_frame else "no frame at all"
        raise CameraStalledError(f"{name} camera stalled: {what} for {age * 1e3:.0f} ms "
                                 f"(limit {stall_s * 1e3:.0f} ms)")


#: Force chunks (one per emulator tick that has readings) an :class:`EmulatorChannel`
#: keeps for :meth:`EmulatorChannel.take_truth`: at least 5 s of the twin's 100 Hz force
#: ball.  A host without a truth consumer (a rig-file host) never takes them.
_FORCE_CHUNKS = 512

#: Builds a ``cv2.VideoCapture``-like object for a device (tests pass a fake).
CaptureFactory = Callable[[int | str], Any]


def _default_capture(device: int | str) -> Any:
    return cv2.VideoCapture(device)


def _one_line(exc: BaseException) -> str:
    """``exc`` as one line (OpenCV's messages span several)."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class _CaptureSource:
    """A ``VideoCapture`` read by a thread; frames stamped on arrival with ``clock``."""

    def __init__(self, name: str, device: int | str, clock: Clock, stall_s: float,
                 capture_factory: CaptureFactory | None) -> None:
        self.name = name
        self.device = device
        self.clock = clock
        self.stall_s = stall_s
        self._factory = capture_factory if capture_factory is not None else _default_capture
        self._cap: Any = None
        self._lock = threading.Lock()
        self._latest: Frame | None = None
        self._last_s = 0.0
        self._seq = 0
        self._error: str | None = None
        self._stop = threading.Event()  # the current reader thread's; each thread has its own
        self._thread: threading.Thread | None = None

    def _configure(self, cap: Any) -> None:
        raise NotImplementedError

    def _convert(self, raw: NDArray[Any]) -> NDArray[np.generic]:
        raise NotImplementedError

    def start(self) -> None:
        """Open the device, configure it and start the reader thread.

        Does nothing while the reader thread runs: the device is open already
        (and may refuse a second opening).
        """
        if self._thread is not None and self._thread.is_alive():
            return
        cap = self._factory(self.device)
        if cap is None or not cap.isOpened():
            if cap is not None:
                cap.release()
            raise CameraError(f"cannot open {self.name} camera {self.device!r}")
        try:
            self._configure(cap)
        except BaseException:
            cap.release()
            raise
        self._cap = cap
        self._last_s = self.clock.now()
        # A new Event per thread: one that close() gave up waiting for (stuck in the
        # driver's read) must still stop when that read returns.
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(cap, self._stop),
                                        name=f"{self.name}-camera", daemon=True)
        self._thread.start()

    def _run(self, cap: Any, stop: threading.Event) -> None:
        try:
            while not stop.is_set():
                try:
                    ok, raw = cap.read()
                    if not ok or raw is None:
                        time.sleep(0.005)  # no frame now; the stall check notices a dead camera
                        continue
                    t = self.clock.now()
                    image = self._convert(np.asarray(raw))
                except CameraError as exc:
                    with self._lock:
                        self._error = str(exc)
                    continue
                except Exception as exc:  # the reader must not die unreported: the host
                    with self._lock:      # would see a stalled camera, not the cause
                        self._error = _one_line(exc)
                    return
                with self._lock:
                    self._latest = Frame(t, self._seq, image)
                    self._seq += 1
                    self._last_s = t
        finally:  # here, never beside a read() that still runs (a camera stuck in it)
            cap.release()

    def read(self, now_s: float) -> Frame | None:
        """The newest frame; raises :class:`CameraStalledError` if the camera stalled."""
        with self._lock:
            latest, last, error = self._latest, self._last_s, self._error
        if error is not None:
            raise CameraError(f"{self.name} camera: {error}")
        _stalled(self.name, now_s, last, self.stall_s, latest is not None)
        return latest

    def close(self) -> None:
        """Stop the thread, which releases the device.

        A thread stuck in the driver's ``read()`` (an unplugged camera) is
        left to release it when that returns: releasing beside a running
        read is undefined in the drivers.
        """
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._cap = None


class OpenCvRgbSource(_CaptureSource):
    """An RGB camera through ``cv2.VideoCapture`` (frames converted BGR → RGB).

    Parameters
    ----------
    spec : RgbCameraSpec
        Device, resolution (the mount's intrinsics), fps, exposure, stall limit.
    clock : Clock
        Stamps each frame on arrival.
    capture_factory : callable, optional
        Builds the capture from the device (default ``cv2.VideoCapture``).
    """

    def __init__(self, spec: RgbCameraSpec, clock: Clock,
                 capture_factory: CaptureFactory | None = None) -> None:
        if spec.device is None:
            raise InputError("the RGB camera needs a device")
        super().__init__("RGB", spec.device, clock, spec.stall_s, capture_factory)
        self.spec = spec

    def _configure(self, cap: Any) -> None:
        intr = self.spec.mount.intrinsics
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, intr.width_px)
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, intr.height_px)
        cap.set(cv2.CAP_PROP_FPS, self.spec.fps)
        if self.spec.exposure is not None:
            cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, 1)  # manual (V4L2 meaning: 1 = manual)
            cap.set(cv2.CAP_PROP_EXPOSURE, self.spec.exposure)

    def _convert(self, raw: NDArray[Any]) -> NDArray[np.generic]:
        intr = self.spec.mount.intrinsics
        if raw.ndim not in (2, 3) or (raw.ndim == 3 and raw.shape[2] not in (1, 3)):
            what = f"{raw.shape[2]} channels" if raw.ndim == 3 else f"shape {raw.shape}"
            raise CameraError(f"frame has {what}, expected 3 (BGR) or 1 (grey): "
                              "is the camera's RGB conversion off?")
        if raw.shape[:2] != intr.shape:
            raise CameraError(f"frame is {raw.shape[1]}x{raw.shape[0]}, the rig file says "
                              f"{intr.width_px}x{intr.height_px}")
        if raw.ndim == 2 or raw.shape[2] == 1:
            out: NDArray[np.generic] = cv2.cvtColor(raw, cv2.COLOR_GRAY2RGB)
        else:
            out = cv2.cvtColor(raw, cv2.COLOR_BGR2RGB)
        return out


class UvcThermalSource(_CaptureSource):
    """A UVC radiometric thermal camera streaming 16-bit Y16 frames (PureThermal / Lepton).

    RGB conversion is switched off and Y16 is asked for, so each frame holds
    the raw counts; they become °C as ``raw * scale + offset_c``.

    Parameters
    ----------
    spec : IrCameraSpec
        Device, resolution, fps, radiometric conversion, stall limit.
    clock : Clock
        Stamps each frame on arrival.
    capture_factory : callable, optional
        Builds the capture from the device (default ``cv2.VideoCapture``).
    """

    def __init__(self, spec: IrCameraSpec, clock: Clock,
                 capture_factory: CaptureFactory | None = None) -> None:
        if spec.device is None:
            raise InputError("the thermal camera needs a device")
        super().__init__("thermal", spec.device, clock, spec.stall_s, capture_factory)
        self.spec = spec

    def _configure(self, cap: Any) -> None:
        intr = self.spec.mount.intrinsics
        cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc("Y", "1", "6", " "))
        cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, intr.width_px)
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, intr.height_px)
        cap.set(cv2.CAP_PROP_FPS, self.spec.fps)

    def _convert(self, raw: NDArray[Any]) -> NDArray[np.generic]:
        h, w = self.spec.mount.intrinsics.shape
        if raw.dtype == np.uint16 and raw.shape == (h, w):
            counts = raw
        elif raw.dtype == np.uint8 and raw.size == 2 * h * w:
            # Some backends hand Y16 over as raw bytes, (1, 2HW) or (H, 2W).
            counts = np.frombuffer(np.ascontiguousarray(raw).tobytes(), dtype="<u2").reshape(h, w)
        else:
            raise CameraError(f"expected {w}x{h} 16-bit radiometric frames (Y16), got "
                              f"{raw.dtype} {raw.shape}: is the camera in Y16 mode?")
        out: NDArray[np.generic] = self.spec.temp_c(counts.astype(np.float32)).astype(np.float32)
        return out


class EmulatorChannel:
    """Host end of the emulator's frame channel: one socket, both cameras and the ticks.

    A reader thread takes every message: the newest RGB and infrared frames,
    the time covered by the latest tick, the truth at that tick and the force
    readings accumulated since the host last took them (those of the last
    512 ticks at most: a host that never takes them must not hold them all).

    Parameters
    ----------
    address : str or socket.socket
        Path of the emulator's Unix socket, or a connected socket (in process).
    clock : Clock
        The host clock.
    lockstep : bool
        The emulator shares the host's virtual clock: frames keep the twin's
        capture time and :meth:`wait_until` waits for each tick.  Otherwise
        frames are stamped with ``clock`` on arrival.
    wait_timeout_s : float
        Longest wall-clock wait for a tick in lockstep (s); a live emulator
        answers in milliseconds, so running out of it means it stopped.
    """

    def __init__(self, address: str | socket.socket, clock: Clock, *, lockstep: bool = False,
                 wait_timeout_s: float = 2.0) -> None:
        self.address = address
        self.clock = clock
        self.lockstep = lockstep
        self.wait_timeout_s = wait_timeout_s
        self._sock: socket.socket | None = None
        self._cond = threading.Condition()
        self._frames: dict[int, Frame] = {}
        self._arrival: dict[int, float] = {}
        self._tick_s = -float("inf")
        self._truth: Truth | None = None
        self._force: collections.deque[tuple[list[float], list[float]]] = collections.deque(
            maxlen=_FORCE_CHUNKS)
        self._error: str | None = None
        self._closed = False
        self._thread: threading.Thread | None = None
        self.started_s = 0.0

    def start(self) -> None:
        """Connect (if given a path) and start the reader thread; idempotent."""
        if self._thread is not None:
            return
        if isinstance(self.address, socket.socket):
            sock = self.address
        else:
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                sock.connect(self.address)
            except OSError as exc:
                sock.close()
                raise CameraError(f"cannot reach the emulator's frame channel "
                                  f"{self.address}: {exc.strerror or exc}") from None
        self._sock = sock
        self.started_s = self.clock.now()
        with self._cond:  # started again after close(): report this connection's faults
            self._closed = False
            self._error = None
        self._thread = threading.Thread(target=self._run, name="frame-channel", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        assert self._sock is not None
        reader = MessageReader(self._sock)
        try:
            while True:
                msg = reader.read()
                if msg is None:
                    break
                with self._cond:
                    if msg.kind == KIND_TICK and msg.tick is not None:
                        self._tick_s = msg.t_s
                        truth = msg.tick.get("truth")
                        self._truth = None if truth is None else truth_from_dict(truth)
                        force = msg.tick.get("force")
                        if force is not None:
                            self._force.append((force["t_s"], force["force_n"]))
                    elif msg.frame is not None:
                        frame = msg.frame
                        arrival = frame.t_s if self.lockstep else self.clock.now()
                        if not self.lockstep:
                            frame = Frame(arrival, frame.seq, frame.image)
                        self._frames[msg.kind] = frame
                        self._arrival[msg.kind] = arrival
                    self._cond.notify_all()
        except (OSError, InputError, ValueError) as exc:
            with self._cond:
                if not self._closed:
                    self._error = f"frame channel broke: {exc}"
        except Exception as exc:  # the reader must not die unreported: the host would
            with self._cond:      # see a stalled camera, not the cause
                if not self._closed:
                    self._error = f"frame channel broke: {type(exc).__name__}: {exc}"
        with self._cond:
            if not self._closed and self._error is None:
                self._error = "the emulator closed the frame channel"
            self._cond.notify_all()

    def wait_until(self, t_s: float) -> None:
        """In lockstep, wait (wall clock, bounded) for every frame up to ``t_s``."""
        if not self.lockstep:
            return
        deadline = time.monotonic() + self.wait_timeout_s
        with self._cond:
            while self._tick_s < t_s - 1e-9 and self._error is None:
                left = deadline - time.monotonic()
                if left <= 0:
                    return  # the stall check reports what is missing
                self._cond.wait(left)

    def latest(self, kind: int) -> tuple[Frame | None, float, str | None]:
        """Newest frame of a stream, its arrival time (or the start), the channel's error."""
        with self._cond:
            return (self._frames.get(kind), self._arrival.get(kind, self.started_s),
                    self._error)

    def take_truth(self) -> tuple[Truth | None, ForceSamples | None]:
        """The truth at the latest tick and the force readings since the last call."""
        with self._cond:
            truth, chunks = self._truth, list(self._force)
            self._force.clear()
        if not chunks:
            return truth, None
        t = np.concatenate([np.asarray(c[0], dtype=np.float64) for c in chunks])
        f = np.concatenate([np.asarray(c[1], dtype=np.float64) for c in chunks])
        return truth, ForceSamples(t, f)

    def close(self) -> None:
        """Disconnect."""
        with self._cond:
            self._closed = True
        if self._sock is not None:
            with contextlib.suppress(OSError):
                self._sock.shutdown(socket.SHUT_RDWR)
            self._sock.close()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None


class EmulatorFrameSource:
    """One camera stream (RGB or infrared) of an :class:`EmulatorChannel`.

    Parameters
    ----------
    channel : EmulatorChannel
        The shared channel (started by the first source that starts).
    kind : {"rgb", "ir"}
        Which stream.
    stall_s : float
        Stall limit (s).
    shape : (int, int), optional
        The frame size (rows, columns) the host's rig file expects; a frame of
        another size is a :class:`CameraError`, as from a real camera.
    """

    def __init__(self, channel: EmulatorChannel, kind: str, stall_s: float,
                 shape: tuple[int, int] | None = None) -> None:
        if kind not in ("rgb", "ir"):
            raise InputError(f"emulator stream must be rgb or ir, got {kind!r}")
        self.channel = channel
        self.kind = KIND_RGB if kind == "rgb" else KIND_IR
        self.name = "RGB" if kind == "rgb" else "thermal"
        self.stall_s = stall_s
        self.shape = shape

    def start(self) -> None:
        """Start the channel (once for both streams)."""
        self.channel.start()

    def read(self, now_s: float) -> Frame | None:
        """The newest frame at ``now_s`` (waiting for the emulator's tick in lockstep)."""
        self.channel.wait_until(now_s)
        frame, last, error = self.channel.latest(self.kind)
        if error is not None:
            raise CameraError(f"{self.name} camera (emulator): {error}")
        _stalled(self.name, now_s, last, self.stall_s, frame is not None)
        if frame is not None and self.shape is not None and frame.image.shape[:2] != self.shape:
            h, w = frame.image.shape[:2]
            raise CameraError(f"{self.name} camera (emulator): frame is {w}x{h}, the rig file "
                              f"says {self.shape[1]}x{self.shape[0]}")
        return frame

    def close(self) -> None:
        """Close the channel (closing twice is harmless)."""
        self.channel.close()


def open_frame_sources(rig: RigFile, clock: Clock, *,
                       capture_factory: CaptureFactory | None = None,
                       channel: EmulatorChannel | None = None,
                       ) -> tuple[FrameSource, FrameSource]:
    """The RGB and thermal sources a rig file names (not started).

    Parameters
    ----------
    rig : RigFile
        The rig.
    clock : Clock
        Host clock that stamps frames.
    capture_factory : callable, optional
        Replaces ``cv2.VideoCapture`` (tests).
    channel : EmulatorChannel, optional
        An emulator channel to use instead of connecting to the rig's socket.

    Returns
    -------
    (FrameSource, FrameSource)
        RGB and thermal.
    """
    if channel is None and "emulator" in (rig.rgb.source, rig.ir.source):
        assert rig.emulator is not None  # the rig file checks it
        channel = EmulatorChannel(rig.emulator.socket, clock)
    rgb: FrameSource
    ir: FrameSource
    if rig.rgb.source == "emulator":
        assert channel is not None
        rgb = EmulatorFrameSource(channel, "rgb", rig.rgb.stall_s,
                                  rig.rgb.mount.intrinsics.shape)
    else:
        rgb = OpenCvRgbSource(rig.rgb, clock, capture_factory)
    if rig.ir.source == "emulator":
        assert channel is not None
        ir = EmulatorFrameSource(channel, "ir", rig.ir.stall_s, rig.ir.mount.intrinsics.shape)
    else:
        ir = UvcThermalSource(rig.ir, clock, capture_factory)
    return rgb, ir
