"""An external force gauge on its own serial port: a pty pair and a fake gauge writing lines."""

from __future__ import annotations

import os
import threading
import time
import tty
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest
import serial

from relaxgrip.clock import VirtualClock, WallClock
from relaxgrip.errors import InputError
from relaxgrip.hardware.force_ref import (
    EmulatorForceBall,
    ForceReference,
    ForceRefError,
    LinearCalibration,
    McuLoadCell,
    SerialForceGauge,
    rig_force_reference,
)
from relaxgrip.hardware.protocol import McuClient, MemoryLink
from relaxgrip.hardware.rig_file import ForceRefSpec


@contextmanager
def _pty() -> Iterator[tuple[int, str]]:
    master, slave = os.openpty()
    tty.setraw(master)
    try:
        yield master, os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)


class _FakeGauge:
    """Writes ``lines`` to the pty's master at ``rate_hz`` in a thread (then repeats the last)."""

    def __init__(self, master: int, lines: list[bytes], rate_hz: float) -> None:
        self.master, self.lines, self.period = master, lines, 1.0 / rate_hz
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        # The host opens its port first: opening it flushes what the pty held.
        time.sleep(0.3)
        k = 0
        while not self.stop.is_set():
            os.write(self.master, self.lines[min(k, len(self.lines) - 1)])
            k += 1
            time.sleep(self.period)

    def __enter__(self) -> _FakeGauge:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join()


def _open(port: str, baud: int) -> serial.Serial:
    return serial.Serial(port, baud, timeout=0.05)


def _wait_readings(gauge: SerialForceGauge, clock: WallClock, n: int) -> tuple[np.ndarray, ...]:
    t: list[float] = []
    f: list[float] = []
    deadline = time.monotonic() + 10.0
    while len(f) < n and time.monotonic() < deadline:
        got = gauge.read(clock.now())
        if got is not None:
            t.extend(got.t_s.tolist())
            f.extend(got.force_n.tolist())
        time.sleep(0.01)
    return np.asarray(t), np.asarray(f)


def test_a_gauge_s_lines_become_forces_with_scale_offset_and_their_own_times() -> None:
    clock = WallClock()
    with _pty() as (master, port), _FakeGauge(master, [b"1.5 N\r\n", b"+2.00N\n", b"oops\n",
                                                         b"2.5\n"], 50.0):
        gauge = SerialForceGauge(port, 115200, 2.0, 0.25, 50.0, clock, open_port=_open)
        assert isinstance(gauge, ForceReference)
        start = clock.now()
        gauge.start()
        try:
            t, f = _wait_readings(gauge, clock, 6)
        finally:
            gauge.close()
    assert f[:3].tolist() == [3.25, 4.25, 5.25]  # 1.5, 2.0, 2.5 scaled; "oops" skipped
    assert gauge.bad_lines >= 1
    assert np.all(np.diff(t) > 0)  # stamped on arrival, in order
    assert t[0] >= start
    assert np.median(np.diff(t)) > 0.5 / 50.0  # the gauge's own pace, not the reader's


def test_the_tare_zeroes_the_gauge() -> None:
    clock = WallClock()
    with _pty() as (master, port), _FakeGauge(master, [b"0.8\n"], 50.0):
        gauge = SerialForceGauge(port, 9600, 1.0, 0.0, 50.0, clock, open_port=_open)
        gauge.start()
        try:
            _wait_readings(gauge, clock, 2)
            gauge.shift_zero(0.8)
            _, f = _wait_readings(gauge, clock, 2)
        finally:
            gauge.close()
    np.testing.assert_allclose(f, 0.0, atol=1e-12)


def test_a_gauge_that_does_not_answer_is_one_clear_error() -> None:
    clock = WallClock()
    with _pty() as (_, port):
        gauge = SerialForceGauge(port, 9600, 1.0, 0.0, 50.0, clock, open_port=_open)
        with pytest.raises(ForceRefError, match=f"force gauge on {port} did not answer: "
                                                "no reading in 2 s"):
            gauge.start()
    assert gauge._thread is None  # the reader stopped, the port closed


def test_a_gauge_sending_garbage_does_not_answer_either() -> None:
    clock = WallClock()
    with _pty() as (master, port), _FakeGauge(master, [b"ERR\n"], 50.0):
        gauge = SerialForceGauge(port, 9600, 1.0, 0.0, 50.0, clock, open_port=_open)
        with pytest.raises(ForceRefError, match=r"did not answer.*line\(s\) that were not a "
                                                "number"):
            gauge.start()


def test_a_missing_port_is_one_clear_error(tmp_path) -> None:
    gauge = SerialForceGauge(str(tmp_path / "ttyNONE"), 9600, 1.0, 0.0, 10.0, WallClock())
    with pytest.raises(ForceRefError, match="cannot open \\[force_ref\\] port"):
        gauge.start()


def test_a_gauge_that_falls_silent_is_a_stall_and_read_never_waits() -> None:
    clock = WallClock()
    with _pty() as (master, port):
        with _FakeGauge(master, [b"1.0\n"], 100.0):
            gauge = SerialForceGauge(port, 9600, 1.0, 0.0, 100.0, clock, open_port=_open)
            gauge.start()
            _wait_readings(gauge, clock, 2)
        try:
            begin = time.monotonic()
            gauge.read(clock.now())  # nothing new: returns at once
            assert time.monotonic() - begin < 0.05
            time.sleep(gauge.stall_s + 0.2)
            with pytest.raises(ForceRefError, match="stalled: no reading for"):
                gauge.read(clock.now())
        finally:
            gauge.close()


def test_the_rig_s_force_ref_table_picks_the_source_and_its_calibration() -> None:
    clock = VirtualClock()
    client = McuClient(MemoryLink(clock).host, clock)
    cell = rig_force_reference(ForceRefSpec("mcu", 80.0, 0.02, 2.0e-5, 0.5), client, clock)
    assert isinstance(cell, McuLoadCell)
    assert cell.calibration == LinearCalibration(2.0e-5, -0.5 / 2.0e-5)
    assert cell.calibration.force_n(0.0) == pytest.approx(0.5)  # reading * scale + offset_n
    gauge = rig_force_reference(ForceRefSpec("serial", 10.0, 0.01, 0.5, 0.0, "/dev/ttyX", 9600),
                                client, clock)
    assert isinstance(gauge, SerialForceGauge)
    assert gauge.port == "/dev/ttyX"
    with pytest.raises(InputError, match="source 'twin' reads the twin's force ball through an "
                                         "emulator"):
        rig_force_reference(ForceRefSpec("twin", 100.0, 0.02), client, clock)
    assert EmulatorForceBall.name == "emulator-force-ball"
