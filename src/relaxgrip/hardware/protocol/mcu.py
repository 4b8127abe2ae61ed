"""The MCU side of the protocol as a pure state machine, and a thin wiring to a transport.

:class:`McuCore` is what the firmware does, in Python: it takes decoded
host frames (or typed decode errors) and the time, and returns the replies;
it runs the watchdog, clamps velocity and duty, and keeps the fault flags.
It knows nothing of bytes, clocks or the plant: the applied command is its
:attr:`McuCore.outputs`, the encoder position is handed in.
:class:`McuEndpoint` puts it on a transport with a :class:`Plant` (a later
issue plugs the digital twin in there, behind a pseudo-terminal).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Protocol

from relaxgrip.clock import Clock
from relaxgrip.errors import InputError
from relaxgrip.hardware.protocol.codec import (
    DUTY_FULL_SCALE,
    PROTOCOL_MINOR,
    PROTOCOL_VERSION,
    SEQ_MODULUS,
    TRIP_FAULTS,
    WATCHDOG_DEFAULT_MS,
    WATCHDOG_MAX_MS,
    WATCHDOG_MIN_MS,
    Command,
    ErrorCode,
    ErrorReply,
    FaultFlag,
    Feature,
    FrameDecoder,
    FrameError,
    GetStatus,
    Hello,
    HelloAck,
    Message,
    Packet,
    SetEnable,
    SetHeaterDuty,
    SetMotorVelocity,
    SetWatchdog,
    StateFlag,
    Status,
    encode_frame,
)
from relaxgrip.hardware.protocol.transport import Transport

__all__ = ["LOAD_CELL_FRESH_US", "AppliedOutputs", "IdealMotorPlant", "McuConfig", "McuCore",
           "McuEndpoint", "Plant"]

_U16_MAX = 0xFFFF
#: Status's LOAD_CELL state bit stays set this long after a conversion (µs): at 10 SPS
#: five conversions in a row may be missed before the host is told.
LOAD_CELL_FRESH_US = 500_000
_COUNTS_24 = (-(1 << 23), (1 << 23) - 1)


@dataclass(frozen=True)
class McuConfig:
    """Firmware constants of an (emulated) MCU.

    Attributes
    ----------
    firmware_id : str
        Reported in HelloAck (printable ASCII, <= 16 characters).
    protocol_version : int
        Version the MCU speaks (tests set another one to provoke a mismatch).
    max_velocity_um_s : int
        Velocity limit (µm/s); commands beyond it are clamped.
    watchdog_default_ms : int
        Watchdog period after reset and after each Hello (ms).
    protocol_minor : int
        Newest minor version the MCU speaks (0 emulates an MCU from before
        the load cell).
    heater_duty_limit_permyriad : int
        Every heater duty is clamped to this (permyriad, at most 10000).
    load_cell : bool
        A load-cell ADC is fitted (reported in HelloAck's features).
    """

    firmware_id: str = "relaxgrip-emu 1"
    protocol_version: int = PROTOCOL_VERSION
    max_velocity_um_s: int = 20_000
    watchdog_default_ms: int = WATCHDOG_DEFAULT_MS
    protocol_minor: int = PROTOCOL_MINOR
    heater_duty_limit_permyriad: int = DUTY_FULL_SCALE
    load_cell: bool = False

    def __post_init__(self) -> None:
        if self.max_velocity_um_s <= 0:
            raise InputError(f"max_velocity_um_s must be > 0, got {self.max_velocity_um_s}")
        if not 0 <= self.protocol_minor <= PROTOCOL_MINOR:
            raise InputError(f"protocol_minor {self.protocol_minor} is outside 0..{PROTOCOL_MINOR}")
        if not 0 <= self.heater_duty_limit_permyriad <= DUTY_FULL_SCALE:
            raise InputError(f"heater_duty_limit_permyriad {self.heater_duty_limit_permyriad} "
                             f"is outside 0..{DUTY_FULL_SCALE}")
        if not WATCHDOG_MIN_MS <= self.watchdog_default_ms <= WATCHDOG_MAX_MS:
            raise InputError(
                f"watchdog_default_ms {self.watchdog_default_ms} is outside "
                f"{WATCHDOG_MIN_MS}..{WATCHDOG_MAX_MS}"
            )


@dataclass(frozen=True)
class AppliedOutputs:
    """What the MCU drives right now.

    Attributes
    ----------
    velocity_um_s : int
        Motor velocity (µm/s), within the limit; 0 when disabled.
    heater_duty_permyriad : tuple of int
        Heater duties (0..10000); 0 when disabled.
    """

    velocity_um_s: int = 0
    heater_duty_permyriad: tuple[int, int] = (0, 0)

    @property
    def velocity_mm_s(self) -> float:
        """Motor velocity (mm/s)."""
        return self.velocity_um_s / 1000.0

    @property
    def heater_duty(self) -> tuple[float, float]:
        """Heater duties (0..1)."""
        d0, d1 = self.heater_duty_permyriad
        return d0 / DUTY_FULL_SCALE, d1 / DUTY_FULL_SCALE


_OFF = AppliedOutputs()


class McuCore:
    """Pure MCU state machine (see ``docs/protocol.md``, "MCU behaviour").

    Parameters
    ----------
    config : McuConfig
        Firmware constants.
    start_s : float
        Time of power-up on the caller's clock (s); ``mcu_time_us`` counts from it.
    """

    def __init__(self, config: McuConfig | None = None, start_s: float = 0.0) -> None:
        self.config = config if config is not None else McuConfig()
        self._start_us = round(start_s * 1e6)
        self._now_us = self._start_us
        self.encoder_position_um = 0
        self.handshaken = False
        self.enabled = False
        self.fault_flags = int(FaultFlag.RESET)
        self.watchdog_ms = self.config.watchdog_default_ms
        self._last_feed_us = self._start_us
        self._last_seq = 0
        self._setpoint = _OFF
        self.rx_error_count = 0
        self.rx_gap_count = 0
        self.session_minor = 0
        self.load_cell_counts = 0
        self.load_cell_time_us = 0
        self.load_cell_samples = 0
        self._load_cell_read_us: int | None = None

    # ------------------------------------------------------------------ state

    @property
    def outputs(self) -> AppliedOutputs:
        """The command applied to motor and heaters now (zero unless enabled)."""
        return self._setpoint if self.enabled else _OFF

    def _to_us(self, now_s: float) -> int:
        t_us = round(now_s * 1e6)
        self._now_us = max(self._now_us, t_us)
        return self._now_us

    def _mcu_time_us(self, t_us: int) -> int:
        return (t_us - self._start_us) % (1 << 32)

    def status(self, ack_seq: int, unsolicited: bool = False) -> Status:
        """The Status the MCU would send now (in the session's minor layout)."""
        out = self.outputs
        state = (StateFlag.ENABLED if self.enabled else 0) | (
            StateFlag.UNSOLICITED if unsolicited else 0
        )
        cell: tuple[int | None, int | None, int | None] = (None, None, None)
        if self.session_minor >= 1:
            read = self._load_cell_read_us
            if read is not None and self._now_us - read < LOAD_CELL_FRESH_US:
                state |= StateFlag.LOAD_CELL
            cell = (self.load_cell_counts, self.load_cell_time_us, self.load_cell_samples)
        return Status(
            ack_seq=ack_seq,
            mcu_time_us=self._mcu_time_us(self._now_us),
            encoder_position_um=max(-(1 << 31), min((1 << 31) - 1, self.encoder_position_um)),
            velocity_um_s=out.velocity_um_s,
            heater_duty_permyriad=out.heater_duty_permyriad,
            fault_flags=self.fault_flags,
            state_flags=int(state),
            rx_error_count=self.rx_error_count,
            rx_gap_count=self.rx_gap_count,
            load_cell_counts=cell[0],
            load_cell_time_us=cell[1],
            load_cell_samples=cell[2],
        )

    def load_cell_conversion(self, counts: int, now_s: float) -> None:
        """Record a load-cell conversion read at ``now_s`` (raw 24-bit counts, saturated).

        Ignored unless the config has a load cell.
        """
        if not self.config.load_cell:
            return
        t_us = round(now_s * 1e6)
        lo, hi = _COUNTS_24
        self.load_cell_counts = max(lo, min(hi, int(counts)))
        self.load_cell_time_us = self._mcu_time_us(t_us)
        self.load_cell_samples = (self.load_cell_samples + 1) & _U16_MAX
        self._load_cell_read_us = t_us

    def _trip(self, flag: FaultFlag) -> list[Message]:
        self.fault_flags |= int(flag)
        self.enabled = False
        self._setpoint = _OFF
        return [self.status(self._last_seq, unsolicited=True)]

    def _reject(self, code: ErrorCode, seq: int = 0, msg_type: int = 0, detail: int = 0) -> Message:
        self.rx_error_count = (self.rx_error_count + 1) & _U16_MAX
        return ErrorReply(seq, int(code), msg_type, detail & _U16_MAX)

    # ------------------------------------------------------------------ time

    def tick(self, now_s: float) -> list[Message]:
        """Advance to ``now_s``: trip the watchdog if it expired.

        Parameters
        ----------
        now_s : float
            Current time (s) on the caller's clock.

        Returns
        -------
        list of Message
            An unsolicited Status if the watchdog tripped now, else nothing.
        """
        now_us = self._to_us(now_s)
        if self.enabled and now_us - self._last_feed_us >= self.watchdog_ms * 1000:
            return self._trip(FaultFlag.WATCHDOG)
        return []

    def raise_fault(self, flag: FaultFlag, now_s: float) -> list[Message]:
        """Report a hardware fault (over-temperature, encoder, motor driver) detected at ``now_s``.

        Trip faults switch the outputs off and disable the MCU; the replies
        hold one unsolicited Status.
        """
        self._to_us(now_s)
        if flag & TRIP_FAULTS:
            return self._trip(flag)
        self.fault_flags |= int(flag)
        return [self.status(self._last_seq, unsolicited=True)]

    # ------------------------------------------------------------------ frames

    def receive(self, item: Packet | FrameError, now_s: float) -> list[Message]:
        """Handle one decoded host frame (or decode error) at ``now_s``.

        Parameters
        ----------
        item : Packet or FrameError
            What the MCU's frame decoder produced.
        now_s : float
            Arrival time (s) on the caller's clock.

        Returns
        -------
        list of Message
            Replies in order: an unsolicited Status if the watchdog had
            expired, then exactly one answer (HelloAck, Status or ErrorReply).
        """
        replies = self.tick(now_s)
        if isinstance(item, FrameError):
            replies.append(self._reject(item.code, item.seq or 0, item.msg_type or 0, item.detail))
            return replies
        replies.append(self._handle(item))
        return replies

    def _handle(self, packet: Packet) -> Message:
        msg, seq = packet.message, packet.seq
        typ = int(msg.TYPE)
        if isinstance(msg, Hello):
            cfg = self.config
            self.handshaken = True
            self.enabled = False
            self._setpoint = _OFF
            self.watchdog_ms = cfg.watchdog_default_ms
            self._last_seq = seq
            # The session speaks the older of the two minor versions (docs/protocol.md §12).
            self.session_minor = min(msg.host_minor or 0, cfg.protocol_minor)
            if self.session_minor == 0:
                return HelloAck(seq, self.watchdog_ms, cfg.max_velocity_um_s, cfg.firmware_id)
            return HelloAck(seq, self.watchdog_ms, cfg.max_velocity_um_s, cfg.firmware_id,
                            mcu_minor=cfg.protocol_minor,
                            features=int(Feature.LOAD_CELL) if cfg.load_cell else 0,
                            heater_duty_limit_permyriad=cfg.heater_duty_limit_permyriad)
        if isinstance(msg, HelloAck | Status | ErrorReply):
            return self._reject(ErrorCode.UNKNOWN_TYPE, seq, typ, typ)
        if not self.handshaken:
            return self._reject(ErrorCode.NO_HANDSHAKE, seq, typ)
        diff = (seq - self._last_seq) % SEQ_MODULUS
        if diff == 0:  # a retransmission: answer, do not apply twice
            return self.status(seq)
        if diff >= SEQ_MODULUS // 2:
            return self._reject(ErrorCode.STALE_SEQUENCE, seq, typ, self._last_seq)
        self.rx_gap_count = (self.rx_gap_count + diff - 1) & _U16_MAX
        self._last_seq = seq
        if isinstance(msg, GetStatus):
            return self.status(seq)
        if isinstance(msg, SetEnable):
            self._setpoint = _OFF
            if msg.enabled:
                self.fault_flags = 0  # latched faults cleared; nothing commanded yet
                self._last_feed_us = self._now_us
            self.enabled = msg.enabled
            return self.status(seq)
        if isinstance(msg, SetWatchdog):
            if not WATCHDOG_MIN_MS <= msg.period_ms <= WATCHDOG_MAX_MS:
                return self._reject(ErrorCode.VALUE_OUT_OF_RANGE, seq, typ, msg.period_ms)
            self.watchdog_ms = msg.period_ms
            self._last_feed_us = self._now_us
            return self.status(seq)
        # motion and heater commands
        if not self.enabled:
            return self._reject(ErrorCode.NOT_ENABLED, seq, typ, self.fault_flags)
        velocity, duty = self._setpoint.velocity_um_s, self._setpoint.heater_duty_permyriad
        if isinstance(msg, SetMotorVelocity | Command):
            velocity = self._clamp_velocity(msg.velocity_um_s)
        if isinstance(msg, SetHeaterDuty | Command):
            duty = self._clamp_duty(msg.heater_duty_permyriad)
        self._setpoint = AppliedOutputs(velocity, duty)
        self._last_feed_us = self._now_us
        return self.status(seq)

    def _clamp_velocity(self, v: int) -> int:
        vmax = self.config.max_velocity_um_s
        clamped = max(-vmax, min(vmax, v))
        self._set_flag(FaultFlag.VELOCITY_CLAMPED, clamped != v)
        return clamped

    def _clamp_duty(self, duty: tuple[int, int]) -> tuple[int, int]:
        limit = self.config.heater_duty_limit_permyriad
        d0, d1 = (min(d, limit) for d in duty)
        self._set_flag(FaultFlag.DUTY_CLAMPED, (d0, d1) != duty)
        return d0, d1

    def _set_flag(self, flag: FaultFlag, on: bool) -> None:
        if on:
            self.fault_flags |= int(flag)
        else:
            self.fault_flags &= ~int(flag)


class Plant(Protocol):
    """What the MCU drives and reads: a motor with an encoder, two heaters, a load cell."""

    def apply(self, outputs: AppliedOutputs, now_s: float) -> None:
        """Drive ``outputs`` from ``now_s`` on."""
        ...

    def encoder_position_um(self, now_s: float) -> int:
        """Encoder reading at ``now_s`` (µm from fully open)."""
        ...

    def load_cell_conversions(self, now_s: float) -> list[tuple[float, int]]:
        """Load-cell conversions completed since the last call, up to ``now_s``.

        Returns
        -------
        list of (float, int)
            Completion time (s) and raw 24-bit counts of each, oldest first;
            empty without a load cell.
        """
        ...


class IdealMotorPlant:
    """A motor that follows its velocity exactly (position = integral of velocity).

    Enough to exercise the protocol without the digital twin.
    """

    def __init__(self, start_s: float = 0.0) -> None:
        self._t_s = start_s
        self._position_um = 0.0
        self._outputs = _OFF

    def _advance(self, now_s: float) -> None:
        if now_s > self._t_s:
            self._position_um += self._outputs.velocity_um_s * (now_s - self._t_s)
            self._t_s = now_s

    def apply(self, outputs: AppliedOutputs, now_s: float) -> None:
        """Drive ``outputs`` from ``now_s`` on."""
        self._advance(now_s)
        self._outputs = outputs

    def encoder_position_um(self, now_s: float) -> int:
        """Position at ``now_s`` (µm)."""
        self._advance(now_s)
        return round(self._position_um)

    def load_cell_conversions(self, now_s: float) -> list[tuple[float, int]]:
        """No load cell: nothing."""
        return []

    @property
    def outputs(self) -> AppliedOutputs:
        """What the plant is driven with."""
        return self._outputs


class McuEndpoint:
    """An :class:`McuCore` on a transport: bytes in, frames out, plant updated.

    Parameters
    ----------
    transport : Transport
        The MCU's end of the link.
    clock : Clock
        Time source (a virtual clock in tests).
    core : McuCore or None
        The state machine; default a fresh one started at ``clock.now()``.
    plant : Plant or None
        Motor and heaters; default an :class:`IdealMotorPlant`.
    """

    def __init__(
        self,
        transport: Transport,
        clock: Clock,
        core: McuCore | None = None,
        plant: Plant | None = None,
    ) -> None:
        self.transport = transport
        self.clock = clock
        self.core = core if core is not None else McuCore(start_s=clock.now())
        self.plant: Plant = plant if plant is not None else IdealMotorPlant(clock.now())
        self.decoder = FrameDecoder(self.core.config.protocol_version,
                                    self.core.config.protocol_minor)
        self._tx_seq = 0
        self.frames_sent = 0

    def _send(self, replies: list[Message]) -> None:
        for msg in replies:
            frame = encode_frame(msg, self._tx_seq, version=self.core.config.protocol_version)
            self._tx_seq = (self._tx_seq + 1) % SEQ_MODULUS
            self.transport.write(frame)
            self.frames_sent += 1

    def poll(self, timeout_s: float = 0.0) -> None:
        """Read what arrived (waiting up to ``timeout_s``), answer it, run the watchdog."""
        data = self.transport.read(timeout_s)
        now = self.clock.now()
        core = self.core
        core.encoder_position_um = self.plant.encoder_position_um(now)
        for t_s, counts in self.plant.load_cell_conversions(now):
            core.load_cell_conversion(counts, t_s)
        replies = core.tick(now)
        for item in self.decoder.feed(data):
            replies += core.receive(item, now)
        self.plant.apply(core.outputs, now)
        self._send(replies)

    def serve(self, stop: threading.Event, poll_s: float = 0.002) -> None:
        """Poll until ``stop`` is set (for a thread in wall-clock time)."""
        while not stop.is_set():
            self.poll(poll_s)
