"""Camera sources with a fake VideoCapture: settings, conversion, timestamps, stall detection."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from relaxgrip.backend import Frame, Truth
from relaxgrip.clock import VirtualClock
from relaxgrip.errors import InputError
from relaxgrip.hardware.cameras import (
    CameraError,
    CameraStalledError,
    OpenCvRgbSource,
    UvcThermalSource,
    open_frame_sources,
)
from relaxgrip.hardware.frame_channel import (
    KIND_RGB,
    encode_frame_message,
    encode_tick,
    truth_from_dict,
)
from relaxgrip.hardware.rig_file import load_rig

DOCS = Path(__file__).resolve().parents[2] / "docs"


class FakeCapture:
    """A VideoCapture that serves ``frames`` once each, then nothing (a stalled camera)."""

    def __init__(self, frames: list[np.ndarray[Any, Any]], opened: bool = True) -> None:
        self.frames = list(frames)
        self.opened = opened
        self.props: dict[int, float] = {}
        self.released = False

    def isOpened(self) -> bool:
        return self.opened

    def set(self, prop: int, value: float) -> bool:
        self.props[prop] = value
        return True

    def read(self) -> tuple[bool, np.ndarray[Any, Any] | None]:
        time.sleep(0.001)
        if not self.frames:
            return False, None
        return True, self.frames.pop(0)

    def release(self) -> None:
        self.released = True


def _wait_error(source: Any) -> None:
    """Until the source's reader has met its error (2 s at most)."""
    for _ in range(2000):
        if source._error is not None:
            return
        time.sleep(0.001)


def _wait_frame(source: Any, clock: VirtualClock) -> Frame:
    for _ in range(2000):
        frame = source.read(clock.now())
        if frame is not None:
            return frame  # type: ignore[no-any-return]
        time.sleep(0.001)
    raise AssertionError("no frame")


def test_rgb_source_sets_the_camera_converts_to_rgb_and_detects_a_stall() -> None:
    rig = load_rig(DOCS / "rigs" / "relaxgrip.toml")
    clock = VirtualClock(5.0)
    bgr = np.zeros((480, 640, 3), np.uint8)
    bgr[..., 0] = 200  # blue in OpenCV's order
    cap = FakeCapture([bgr])
    source = OpenCvRgbSource(rig.rgb, clock, capture_factory=lambda dev: cap)
    source.start()
    try:
        frame = _wait_frame(source, clock)
        assert frame.t_s == 5.0  # stamped on arrival with the injected clock
        assert frame.image.shape == (480, 640, 3)
        assert int(frame.image[0, 0, 2]) == 200
        assert int(frame.image[0, 0, 0]) == 0
        assert cap.props[cv2.CAP_PROP_FRAME_WIDTH] == 640
        assert cap.props[cv2.CAP_PROP_FPS] == 30.0
        assert cap.props[cv2.CAP_PROP_EXPOSURE] == -6
        assert source.read(5.2) is frame  # 200 ms: at the limit, not yet stalled
        with pytest.raises(CameraStalledError, match=r"RGB camera stalled: no new frame for "
                                                     r"201 ms \(limit 200 ms\)"):
            source.read(5.201)
    finally:
        source.close()
    assert cap.released


def test_thermal_source_asks_for_y16_and_converts_centikelvin() -> None:
    rig = load_rig(DOCS / "rigs" / "relaxgrip.toml")
    clock = VirtualClock()
    raw = np.full((192, 256), 31315, np.uint16)  # 40.00 °C in centi-kelvin
    as_bytes = np.frombuffer(raw.tobytes(), np.uint8).reshape(1, -1)  # how some backends hand Y16
    cap = FakeCapture([raw, as_bytes])
    source = UvcThermalSource(rig.ir, clock, capture_factory=lambda dev: cap)
    source.start()
    try:
        first = _wait_frame(source, clock)
        assert first.image.dtype == np.float32
        assert float(first.image[10, 10]) == pytest.approx(40.0, abs=1e-3)
        for _ in range(2000):
            frame = source.read(0.0)
            if frame is not None and frame.seq == 1:
                break
            time.sleep(0.001)
        assert frame is not None
        assert frame.seq == 1
        assert np.array_equal(frame.image, first.image)
        assert cap.props[cv2.CAP_PROP_CONVERT_RGB] == 0
        assert cap.props[cv2.CAP_PROP_FOURCC] == cv2.VideoWriter.fourcc("Y", "1", "6", " ")
    finally:
        source.close()


def test_thermal_source_rejects_8_bit_frames() -> None:
    rig = load_rig(DOCS / "rigs" / "relaxgrip.toml")
    cap = FakeCapture([np.zeros((192, 256, 3), np.uint8)])
    source = UvcThermalSource(rig.ir, VirtualClock(), capture_factory=lambda dev: cap)
    source.start()
    try:
        _wait_error(source)
        with pytest.raises(CameraError, match="is the camera in Y16 mode"):
            source.read(0.0)
    finally:
        source.close()


def test_camera_that_does_not_open_and_a_stall_before_any_frame() -> None:
    rig = load_rig(DOCS / "rigs" / "relaxgrip.toml")
    closed = OpenCvRgbSource(rig.rgb, VirtualClock(),
                             capture_factory=lambda dev: FakeCapture([], opened=False))
    with pytest.raises(CameraError, match="cannot open RGB camera 0"):
        closed.start()
    silent = UvcThermalSource(rig.ir, VirtualClock(), capture_factory=lambda dev: FakeCapture([]))
    silent.start()
    try:
        assert silent.read(2.5) is None
        with pytest.raises(CameraStalledError, match="thermal camera stalled: no frame at all"):
            silent.read(2.6)
    finally:
        silent.close()


def test_rig_file_names_the_sources() -> None:
    rig = load_rig(DOCS / "rigs" / "relaxgrip.toml")
    rgb, ir = open_frame_sources(rig, VirtualClock())
    assert isinstance(rgb, OpenCvRgbSource)
    assert isinstance(ir, UvcThermalSource)
    emu = load_rig(DOCS / "rig-emulator.toml")
    rgb2, ir2 = open_frame_sources(emu, VirtualClock())
    assert (rgb2.name, ir2.name) == ("RGB", "thermal")
    assert emu.emulator is not None
    moved = replace(emu, emulator=replace(emu.emulator, socket="/nonexistent/s"))
    source = open_frame_sources(moved, VirtualClock())[0]
    with pytest.raises(CameraError, match="cannot reach the emulator's frame channel"):
        source.start()


def test_frame_channel_messages_round_trip() -> None:
    import socket

    from relaxgrip.hardware.frame_channel import MessageReader

    image = np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3)
    temps = np.linspace(20.0, 60.0, 12, dtype=np.float32).reshape(3, 4)
    truth = Truth(1.5, (0.1, 0.2), (0.0, 0.0), (0.01, 0.02), 0.08, ((30.0, 31.0), (32.0,)),
                  (30.5, 32.0), 0.1, "force_ball", 0.0, False, False, False, 0.0)
    a, b = socket.socketpair()
    a.sendall(encode_frame_message(KIND_RGB, Frame(0.5, 7, image))
              + encode_frame_message(2, Frame(1.0, 1, temps))
              + encode_tick(3, 1.0, truth, None))
    a.close()
    reader = MessageReader(b)
    m1, m2, m3 = reader.read(), reader.read(), reader.read()
    assert reader.read() is None
    b.close()
    assert m1 is not None
    assert m1.frame is not None
    assert m1.frame.seq == 7
    assert np.array_equal(m1.frame.image, image)
    assert m1.t_s == 0.5
    assert m2 is not None
    assert m2.frame is not None
    assert np.array_equal(m2.frame.image, temps)
    assert m2.frame.image.dtype == np.float32
    assert m3 is not None
    assert m3.tick is not None
    assert truth_from_dict(m3.tick["truth"]) == truth
    with pytest.raises(InputError, match="cannot send"):
        encode_frame_message(KIND_RGB, Frame(0.0, 0, np.zeros((2, 2), np.int64)))


@pytest.mark.parametrize(("body", "problem"), [
    (b"[1, 2]", "a tick is not a JSON object"),
    (b'{"truth": {"bogus": 1}}', "truth does not have the Truth fields"),
    (b'{"truth": null, "force": {"t_s": 1}}', "force readings are not two number lists"),
    (b'{"truth": null, "force": {"t_s": [1, 2], "force_n": ["a", 2]}}', "not two number lists"),
])
def test_a_malformed_tick_is_reported_as_the_channel_s_fault(body: bytes, problem: str) -> None:
    """The reader thread reports it; the host does not see a stalled camera instead."""
    import socket

    from relaxgrip.clock import WallClock
    from relaxgrip.hardware.cameras import EmulatorChannel, EmulatorFrameSource
    from relaxgrip.hardware.frame_channel import _HEADER, CHANNEL_VERSION, KIND_TICK, MAGIC

    mine, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    clock = WallClock()
    channel = EmulatorChannel(theirs, clock)
    rgb = EmulatorFrameSource(channel, "rgb", 0.2)
    rgb.start()
    try:
        mine.sendall(_HEADER.pack(MAGIC, CHANNEL_VERSION, KIND_TICK, 0, 0, 0, 0.0, 0, 0,
                                  len(body)) + body)
        deadline = time.monotonic() + 5.0
        while channel._thread is not None and channel._thread.is_alive() \
                and time.monotonic() < deadline:
            time.sleep(0.01)
        with pytest.raises(CameraError, match=f"frame channel broke: .*{problem}"):
            rgb.read(clock.now())
    finally:
        channel.close()
        mine.close()


def test_an_emulator_frame_of_another_size_than_the_rig_file_s_is_refused() -> None:
    import socket

    from relaxgrip.clock import WallClock
    from relaxgrip.hardware.cameras import EmulatorChannel, EmulatorFrameSource

    mine, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    clock = WallClock()
    channel = EmulatorChannel(theirs, clock)
    rgb = EmulatorFrameSource(channel, "rgb", 5.0, shape=(240, 320))
    rgb.start()
    try:
        mine.sendall(encode_frame_message(KIND_RGB, Frame(0.0, 1, np.zeros((480, 640, 3),
                                                                            np.uint8))))
        deadline = time.monotonic() + 5.0
        while channel.latest(KIND_RGB)[0] is None and time.monotonic() < deadline:
            time.sleep(0.01)
        with pytest.raises(CameraError, match="frame is 640x480, the rig file says 320x240"):
            rgb.read(clock.now())
    finally:
        channel.close()
        mine.close()


def test_a_camera_stuck_in_read_is_released_after_the_read_not_beside_it() -> None:
    import threading

    class StuckCapture(FakeCapture):
        def __init__(self) -> None:
            super().__init__([])
            self.in_read = threading.Event()
            self.unblock = threading.Event()
            self.released_in_read = False

        def read(self) -> tuple[bool, np.ndarray[Any, Any] | None]:
            self.in_read.set()
            self.unblock.wait(10.0)
            self.in_read.clear()
            return False, None

        def release(self) -> None:
            self.released_in_read = self.in_read.is_set()
            super().release()

    cap = StuckCapture()
    source = OpenCvRgbSource(load_rig(DOCS / "rigs" / "relaxgrip.toml").rgb, VirtualClock(),
                             capture_factory=lambda dev: cap)
    source.start()
    assert cap.in_read.wait(5.0)
    source.close()  # gives up waiting for the stuck thread
    released_early = cap.released
    assert not released_early
    cap.unblock.set()
    deadline = time.monotonic() + 5.0
    while not cap.released and time.monotonic() < deadline:
        time.sleep(0.01)
    assert cap.released
    assert not cap.released_in_read


def test_starting_a_running_camera_opens_nothing_and_a_given_up_reader_still_stops() -> None:
    """start() while the reader runs leaves it alone; a reader that close() gave up waiting
    for (stuck in the driver) stops when its read returns, even after a new start()."""
    import threading

    class StuckCapture(FakeCapture):
        def __init__(self) -> None:
            super().__init__([])
            self.in_read = threading.Event()
            self.unblock = threading.Event()

        def read(self) -> tuple[bool, np.ndarray[Any, Any] | None]:
            self.in_read.set()
            self.unblock.wait(10.0)
            return False, None

    caps: list[FakeCapture] = []

    def factory(dev: int | str) -> FakeCapture:
        caps.append(StuckCapture() if not caps else FakeCapture([]))
        return caps[-1]

    source = OpenCvRgbSource(load_rig(DOCS / "rigs" / "relaxgrip.toml").rgb, VirtualClock(),
                             capture_factory=factory)
    source.start()
    source.start()
    assert len(caps) == 1  # one device, one reader
    stuck = caps[0]
    assert isinstance(stuck, StuckCapture)
    assert stuck.in_read.wait(5.0)
    first = source._thread
    assert first is not None
    source.close()  # gives up waiting for the stuck reader
    source.start()  # the camera again, with a reader of its own
    try:
        assert len(caps) == 2
        stuck.unblock.set()
        first.join(timeout=5.0)
        assert not first.is_alive()
        assert stuck.released
    finally:
        source.close()
    assert caps[1].released


@pytest.mark.parametrize("channels", [2, 4])
def test_an_rgb_frame_with_another_channel_count_is_named(channels: int) -> None:
    rig = load_rig(DOCS / "rigs" / "relaxgrip.toml")
    clock = VirtualClock()
    grey = FakeCapture([np.full((480, 640, 1), 90, np.uint8)])
    source = OpenCvRgbSource(rig.rgb, clock, capture_factory=lambda dev: grey)
    source.start()
    try:
        frame = _wait_frame(source, clock)
        assert frame.image.shape == (480, 640, 3)  # grey (one channel) becomes grey RGB
        assert int(frame.image[5, 5, 0]) == int(frame.image[5, 5, 2]) == 90
    finally:
        source.close()
    cap = FakeCapture([np.zeros((480, 640, channels), np.uint8)])
    source = OpenCvRgbSource(rig.rgb, clock, capture_factory=lambda dev: cap)
    source.start()
    try:
        _wait_error(source)
        with pytest.raises(CameraError, match=f"RGB camera: frame has {channels} channels, "
                                              r"expected 3 \(BGR\) or 1 \(grey\)"):
            source.read(0.0)
    finally:
        source.close()


def test_a_camera_whose_read_raises_is_reported_not_stalled() -> None:
    class BrokenCapture(FakeCapture):
        def read(self) -> tuple[bool, np.ndarray[Any, Any] | None]:
            raise cv2.error("(-2:Unspecified error) in function 'read'\n> driver gone")

    cap = BrokenCapture([])
    source = OpenCvRgbSource(load_rig(DOCS / "rigs" / "relaxgrip.toml").rgb, VirtualClock(),
                             capture_factory=lambda dev: cap)
    source.start()
    try:
        thread = source._thread
        assert thread is not None
        thread.join(timeout=5.0)
        assert not thread.is_alive()
        assert cap.released
        with pytest.raises(CameraError) as info:
            source.read(0.0)
    finally:
        source.close()
    message = str(info.value)
    assert message == ("RGB camera: error: (-2:Unspecified error) in function 'read' "
                       "> driver gone")


def test_force_readings_nobody_takes_are_bounded() -> None:
    """A rig-file host has no truth consumer: the channel keeps only the newest readings."""
    import socket

    from relaxgrip.backend import ForceSamples
    from relaxgrip.clock import WallClock
    from relaxgrip.hardware.cameras import _FORCE_CHUNKS, EmulatorChannel

    n = _FORCE_CHUNKS + 100
    mine, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    channel = EmulatorChannel(theirs, WallClock())
    channel.start()
    try:
        for k in range(n):
            mine.sendall(encode_tick(k, k * 0.01, None,
                                     ForceSamples(np.array([k * 0.01]), np.array([float(k)]))))
        deadline = time.monotonic() + 10.0
        while channel._tick_s < (n - 1) * 0.01 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert channel._tick_s == (n - 1) * 0.01
        assert len(channel._force) == _FORCE_CHUNKS
        _, force = channel.take_truth()
        assert force is not None
        assert force.force_n.tolist() == [float(k) for k in range(n - _FORCE_CHUNKS, n)]
        assert channel.take_truth()[1] is None
    finally:
        channel.close()
        mine.close()
