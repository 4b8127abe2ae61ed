"""Reference force sensors the host reads beside the gripper: the ``force_ref`` of a rig.

A rig's force reference (the load cell in the calibration object) labels
recordings (``/relaxgrip/force_ref``) and calibrations; estimators and
controllers never read it.  :class:`ForceReference` is what
:class:`~relaxgrip.hardware.gripper.SerialGripper` needs of one, so that any
source plugs in: :class:`McuLoadCell` is the MCU's HX711 channel, reported
in Status (protocol minor 1); :class:`SerialForceGauge` an external force
gauge on its own serial port (one reading a line); :class:`EmulatorForceBall`
the twin's force ball through an emulator's frame channel (an emulator rig's
``source = "twin"``).  :func:`rig_force_reference` makes the one a rig file's
``[force_ref]`` names.

Timestamps are on the host's clock.  A load-cell conversion is stamped
with the MCU's time of reading; the host maps it onto its clock through the
Status that carried it: ``t = t_rx - (mcu_time_us - load_cell_time_us) / 1e6``.

The tare (zeroing) is the host's: :meth:`ForceReference.shift_zero` moves a
linear source's zero so that a reading taken with nothing on the cell
becomes 0 N (:meth:`SerialGripper.tare_force_ref` averages such readings).
The MCU reports raw counts and keeps no calibration, so that every source,
the MCU's or an external gauge, is zeroed and scaled in one place.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from relaxgrip.backend import ForceSamples
from relaxgrip.clock import Clock
from relaxgrip.errors import InputError
from relaxgrip.hardware.protocol.client import McuClient
from relaxgrip.hardware.protocol.codec import Feature, Status

if TYPE_CHECKING:
    from relaxgrip.hardware.cameras import EmulatorChannel
    from relaxgrip.hardware.rig_file import ForceRefSpec

__all__ = [
    "EmulatorForceBall",
    "ForceRefError",
    "ForceReference",
    "LinearCalibration",
    "McuLoadCell",
    "SerialForceGauge",
    "rig_force_reference",
]

_U32 = 1 << 32
_U16 = 1 << 16


@runtime_checkable
class ForceReference(Protocol):
    """A reference force sensor read by the host."""

    name: str

    def start(self) -> None:
        """Begin reading (after the MCU's handshake).

        Raises
        ------
        InputError
            If the sensor is not there or does not answer.
        """
        ...

    def read(self, now_s: float) -> ForceSamples | None:
        """Readings since the last call, on the host clock; None if there are none."""
        ...

    def shift_zero(self, force_n: float) -> None:
        """Subtract ``force_n`` from every later reading (the tare)."""
        ...

    def close(self) -> None:
        """Stop reading and release the sensor."""
        ...


@dataclass(frozen=True)
class LinearCalibration:
    """Force from raw counts: ``F = (counts - offset_counts) · scale_n_per_count``.

    Attributes
    ----------
    scale_n_per_count : float
        Newtons per count (from a calibration with known weights).
    offset_counts : float
        Reading with nothing on the cell (counts; the tare moves it).
    """

    scale_n_per_count: float
    offset_counts: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale_n_per_count) and self.scale_n_per_count != 0.0):
            raise InputError("load-cell scale_n_per_count must be a finite non-zero number, "
                             f"got {self.scale_n_per_count}")
        if not math.isfinite(self.offset_counts):
            raise InputError(f"load-cell offset_counts must be finite, got {self.offset_counts}")

    def force_n(self, counts: float) -> float:
        """Force of a reading (N)."""
        return (counts - self.offset_counts) * self.scale_n_per_count


@dataclass
class _Pending:
    t_s: list[float] = field(default_factory=list)
    force_n: list[float] = field(default_factory=list)


class McuLoadCell:
    """The MCU's load-cell channel as a :class:`ForceReference`.

    It listens to every Status the client receives (answers, unsolicited and
    late ones) and keeps each new conversion (a new ``load_cell_samples``).

    Parameters
    ----------
    client : McuClient
        The MCU's client; the load cell registers itself as a Status listener.
    calibration : LinearCalibration
        Scale and zero of the cell.

    Attributes
    ----------
    conversions : int
        Conversions received.
    conversions_missed : int
        Conversions the MCU made that no received Status carried.
    """

    name = "mcu-load-cell"

    def __init__(self, client: McuClient, calibration: LinearCalibration) -> None:
        self.client = client
        self.calibration = calibration
        self.conversions = 0
        self.conversions_missed = 0
        self._last_samples: int | None = None
        self._pending = _Pending()
        self._listening = False

    def start(self) -> None:
        """Check that the MCU reports a load cell, then listen to its Status frames.

        Raises
        ------
        InputError
            If the session's protocol minor is 0 (no load-cell fields) or the
            firmware was built without a load cell.
        """
        ack = self.client.hello_ack
        if ack is None:
            raise InputError("the MCU load cell starts after the MCU's handshake")
        if self.client.session_minor < 1 or ack.features is None:
            raise InputError(
                f"the force reference is the MCU's load cell, but the MCU ({ack.firmware_id!r}) "
                "speaks protocol minor 0, whose Status has no load cell: flash firmware "
                "of protocol 1.1 or later (docs/firmware.md)")
        if not ack.features & Feature.LOAD_CELL:
            raise InputError(
                f"the force reference is the MCU's load cell, but the MCU firmware "
                f"({ack.firmware_id!r}) was built without one: build it with LOAD_CELL=1 "
                "(docs/firmware.md)")
        self._last_samples = None
        if not self._listening:
            self.client.status_listeners.append(self.on_status)
            self._listening = True

    def on_status(self, status: Status, rx_time_s: float) -> None:
        """Take the conversion a Status carries, if it is a new one."""
        samples = status.load_cell_samples
        if samples is None or status.load_cell_counts is None or \
                status.load_cell_time_us is None or samples == 0:
            return
        if samples == self._last_samples:
            return
        if self._last_samples is not None:
            self.conversions_missed += (samples - self._last_samples - 1) % _U16
        self._last_samples = samples
        age_s = ((status.mcu_time_us - status.load_cell_time_us) % _U32) / 1e6
        self._pending.t_s.append(rx_time_s - age_s)
        self._pending.force_n.append(self.calibration.force_n(status.load_cell_counts))
        self.conversions += 1

    def read(self, now_s: float) -> ForceSamples | None:
        """Conversions received since the last call (host clock), None if none."""
        pending = self._pending
        if not pending.t_s:
            return None
        self._pending = _Pending()
        return ForceSamples(np.asarray(pending.t_s, dtype=np.float64),
                            np.asarray(pending.force_n, dtype=np.float64))

    def shift_zero(self, force_n: float) -> None:
        """Move the zero so that a reading of ``force_n`` becomes 0 N."""
        cal = self.calibration
        self.calibration = LinearCalibration(
            cal.scale_n_per_count, cal.offset_counts + force_n / cal.scale_n_per_count)

    def close(self) -> None:
        """Stop listening."""
        if self._listening:
            self.client.status_listeners.remove(self.on_status)
            self._listening = False


class ForceRefError(InputError):
    """A force reference that stopped answering or sends what is not a force."""


#: Longest line a force gauge may send (bytes): a number, a unit, a few spaces.
MAX_GAUGE_LINE = 64
#: Readings kept between two :meth:`SerialForceGauge.read` calls (the oldest go first): a
#: minute of a 1 kHz gauge.
MAX_PENDING = 60_000


class SerialForceGauge:
    """An external force gauge on its own serial port, as a :class:`ForceReference`.

    The gauge sends one reading a line at its own rate: a decimal number,
    optionally followed by a unit (``1.234``, ``1.234 N``, ``+1.2340N``);
    ``force_n = reading * scale + offset_n``.  A reader thread takes the lines
    as they come and stamps each with the host clock when its end arrived, so
    that :meth:`read` never waits for the port: the control loop is never
    held up by the gauge.

    Parameters
    ----------
    port : str
        The gauge's serial device.
    baud : int
        Its line speed (bit/s).
    scale, offset_n : float
        The conversion of a reading to newtons (N per reading unit, N).
    rate_hz : float
        The gauge's reading rate (Hz): it sets how long :meth:`start` waits for
        the first reading and how long a silence counts as a stalled gauge.
    clock : Clock
        Host clock that stamps the readings (a wall clock).
    open_port : callable, optional
        ``open_port(port, baud)`` returns a pyserial-like object with
        ``read(n)``, ``in_waiting`` and ``close()`` (default: :class:`serial.Serial` with a
        50 ms read timeout).

    Attributes
    ----------
    readings : int
        Lines read as forces.
    bad_lines : int
        Lines that were not a number (skipped).
    """

    name = "serial-force-gauge"

    def __init__(self, port: str, baud: int, scale: float, offset_n: float, rate_hz: float,
                 clock: Clock, open_port: Callable[[str, int], Any] | None = None) -> None:
        if not (math.isfinite(scale) and scale != 0.0):
            raise InputError(f"force gauge scale must be finite and non-zero, got {scale}")
        if not (math.isfinite(rate_hz) and rate_hz > 0.0):
            raise InputError(f"force gauge rate_hz must be > 0, got {rate_hz}")
        self.port = port
        self.baud = baud
        self.scale = scale
        self.offset_n = offset_n
        self.rate_hz = rate_hz
        self.clock = clock
        self._open_port = open_port if open_port is not None else _open_serial
        self.readings = 0
        self.bad_lines = 0
        self._lock = threading.Lock()
        self._t: list[float] = []
        self._f: list[float] = []
        self._last_wall_s: float | None = None
        self._error: str | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._serial: Any = None

    @property
    def answer_timeout_s(self) -> float:
        """How long :meth:`start` waits for the first reading (s): five periods, at least 2 s."""
        return max(2.0, 5.0 / self.rate_hz)

    @property
    def stall_s(self) -> float:
        """A silence this long is a stalled gauge (s): ten periods, at least 1 s."""
        return max(1.0, 10.0 / self.rate_hz)

    def start(self) -> None:
        """Open the port, start the reader and wait for the first reading.

        Raises
        ------
        ForceRefError
            If the port cannot be opened, or no reading comes within
            :attr:`answer_timeout_s`.
        """
        if self._thread is not None:
            return
        try:
            self._serial = self._open_port(self.port, self.baud)
        except Exception as exc:  # pyserial's SerialException, OSError
            raise ForceRefError(f"force gauge: cannot open [force_ref] port {self.port}: "
                                f"{exc}") from None
        self._stop.clear()
        self._error = None
        self._thread = threading.Thread(target=self._run, name="force-gauge", daemon=True)
        self._thread.start()
        deadline = time.monotonic() + self.answer_timeout_s
        while time.monotonic() < deadline:
            with self._lock:
                if self._last_wall_s is not None or self._error is not None:
                    break
            time.sleep(0.01)
        with self._lock:
            answered, error = self._last_wall_s is not None, self._error
        if not answered:
            bad = f" ({self.bad_lines} line(s) that were not a number)" if self.bad_lines else ""
            self.close()
            raise ForceRefError(
                f"force gauge on {self.port} did not answer: no reading in "
                f"{self.answer_timeout_s:g} s{bad}" + (f": {error}" if error else
                f"; is it on, at {self.baud} bit/s, sending one number a line?"))

    def _run(self) -> None:
        buf = b""
        try:
            while not self._stop.is_set():
                # What is there, or the next byte (pyserial's read(n) would wait for n bytes
                # or its timeout, and stamp several readings at once).
                waiting = int(getattr(self._serial, "in_waiting", 0) or 0)
                data = self._serial.read(min(max(1, waiting), 4096))
                if not data:
                    continue
                buf += data
                *lines, buf = buf.split(b"\n")
                if len(buf) > MAX_GAUGE_LINE:
                    buf = b""
                    self.bad_lines += 1
                for line in lines:
                    self._take(line)
        except Exception as exc:  # the port went away
            if not self._stop.is_set():
                with self._lock:
                    self._error = f"{type(exc).__name__}: {exc}"

    def _take(self, line: bytes) -> None:
        text = line.strip().decode("ascii", "replace").rstrip("Nn").strip()
        try:
            value = float(text) if len(line) <= MAX_GAUGE_LINE else math.nan
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            self.bad_lines += 1
            return
        now = self.clock.now()
        with self._lock:
            self._t.append(now)
            self._f.append(value)  # converted by read(): a tare applies to what is pending
            if len(self._t) > MAX_PENDING:
                del self._t[0], self._f[0]
            self._last_wall_s = time.monotonic()
            self.readings += 1

    def read(self, now_s: float) -> ForceSamples | None:
        """Readings since the last call (host clock), None if none.

        Raises
        ------
        ForceRefError
            If the port failed or the gauge has sent nothing for :attr:`stall_s`.
        """
        with self._lock:
            t, f, self._t, self._f = self._t, self._f, [], []
            error, last, offset_n = self._error, self._last_wall_s, self.offset_n
        if error is not None:
            raise ForceRefError(f"force gauge on {self.port} lost: {error}")
        if last is not None and time.monotonic() - last > self.stall_s:
            raise ForceRefError(f"force gauge on {self.port} stalled: no reading for "
                                f"{time.monotonic() - last:.1f} s")
        if not t:
            return None
        return ForceSamples(np.asarray(t, dtype=np.float64),
                            np.asarray(f, dtype=np.float64) * self.scale + offset_n)

    def shift_zero(self, force_n: float) -> None:
        """Move the zero so that a reading of ``force_n`` becomes 0 N."""
        with self._lock:
            self.offset_n -= force_n

    def close(self) -> None:
        """Stop the reader and close the port."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self._serial is not None:
            with contextlib.suppress(Exception):
                self._serial.close()
            self._serial = None


def _open_serial(port: str, baud: int) -> Any:
    try:
        import serial
    except ImportError:  # pragma: no cover - pyserial is a core dependency
        raise InputError("a force gauge on a serial port needs pyserial: "
                         "pip install pyserial") from None
    return serial.Serial(port, baud, timeout=0.05)


class EmulatorForceBall:
    """The twin's force ball, read through an emulator's frame channel (``source = "twin"``).

    The emulator sends the ball's readings beside its frames; this takes only
    those (never the twin's truth), so that a hold on an emulator rig is
    scored as one on a real rig is: against its force reference.  The
    readings carry the twin's times; they are moved onto the host clock by
    the smallest offset seen between a read and the newest reading it got
    (the channel's latency floor).

    Parameters
    ----------
    channel : EmulatorChannel
        The rig's frame channel (shared with its cameras).
    """

    name = "emulator-force-ball"

    def __init__(self, channel: EmulatorChannel) -> None:
        self.channel = channel
        self._zero_n = 0.0
        self._offset_s = math.inf

    def start(self) -> None:
        """Start the channel if no camera did."""
        self.channel.start()

    def read(self, now_s: float) -> ForceSamples | None:
        """The ball's readings since the last call (host clock), None if none."""
        _, force = self.channel.take_truth()
        if force is None or not force.t_s.size:
            return None
        self._offset_s = min(self._offset_s, now_s - float(force.t_s[-1]))
        return ForceSamples(force.t_s + self._offset_s, force.force_n - self._zero_n)

    def shift_zero(self, force_n: float) -> None:
        """Move the zero so that a reading of ``force_n`` becomes 0 N."""
        self._zero_n += force_n

    def close(self) -> None:
        """Nothing to release: the cameras close the channel."""


def rig_force_reference(spec: ForceRefSpec, client: McuClient, clock: Clock,
                        channel: EmulatorChannel | None = None) -> ForceReference:
    """The force reference a rig's ``[force_ref]`` names, with its calibration.

    Parameters
    ----------
    spec : ForceRefSpec
        The rig file's table.
    client : McuClient
        The MCU's client (``mcu``: the load cell listens to its Status frames).
    clock : Clock
        Host clock (``serial``: stamps the gauge's readings).
    channel : EmulatorChannel, optional
        The rig's emulator channel (``twin`` only).

    Raises
    ------
    InputError
        ``twin`` without an emulator channel (the rig file refuses it on a real rig).
    """
    if spec.source == "mcu":
        return McuLoadCell(client, LinearCalibration(spec.scale, -spec.offset_n / spec.scale))
    if spec.source == "serial":
        assert spec.port is not None  # the rig file checks them
        assert spec.baud is not None
        return SerialForceGauge(spec.port, spec.baud, spec.scale, spec.offset_n, spec.rate_hz,
                                clock)
    if channel is None:
        raise InputError("[force_ref] source 'twin' reads the twin's force ball through an "
                         "emulator: the rig's cameras' source must be 'emulator'")
    return EmulatorForceBall(channel)
