"""Host side of the MCU protocol: :class:`McuClient` on any :class:`Transport`.

Every host frame gets exactly one answer (HelloAck, Status or ErrorReply)
carrying its sequence number; the client waits for it on the injected
clock for at most ``reply_timeout_s`` (default 100 ms) and otherwise raises
a typed, one-line :class:`~relaxgrip.hardware.protocol.errors.LinkError`
saying what it saw: silence, corrupted frames or a truncated frame.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from relaxgrip.clock import Clock
from relaxgrip.errors import InputError
from relaxgrip.hardware.protocol.codec import (
    PROTOCOL_MINOR,
    PROTOCOL_VERSION,
    SEQ_MODULUS,
    TRIP_FAULTS,
    WATCHDOG_MAX_MS,
    WATCHDOG_MIN_MS,
    Command,
    ErrorCode,
    ErrorReply,
    FaultFlag,
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
    Status,
    encode_frame,
    permyriad_from_duty,
)
from relaxgrip.hardware.protocol.errors import (
    LinkCorruptedError,
    LinkTimeoutError,
    McuFaultError,
    McuRejectedError,
    VersionMismatchError,
)
from relaxgrip.hardware.protocol.transport import Transport
from relaxgrip.validate import check_finite

__all__ = ["LinkStats", "McuClient"]


@dataclass
class LinkStats:
    """Counters of one client's link.

    Attributes
    ----------
    frames_sent, frames_received : int
        Frames written and valid frames read.
    decode_errors : int
        Frames from the MCU that failed to decode (CRC, COBS, length, ...).
    mcu_frames_lost : int
        MCU frames missing according to their sequence numbers.
    unsolicited : int
        Status frames the MCU sent on its own (a fault tripped).
    stale_frames : int
        Valid frames dropped because their sequence number repeated or went
        back (a line that replays old frames: an old Status's encoder reading
        must not pass for a new one).
    """

    frames_sent: int = 0
    frames_received: int = 0
    decode_errors: int = 0
    mcu_frames_lost: int = 0
    unsolicited: int = 0
    stale_frames: int = 0


def _is_answer(reply: Message, request: Message, seq: int) -> bool:
    """Whether ``reply`` answers ``request`` sent with ``seq``."""
    if isinstance(reply, Status):
        return reply.ack_seq == seq and not reply.unsolicited
    if isinstance(reply, HelloAck):
        return reply.ack_seq == seq and isinstance(request, Hello)
    if isinstance(reply, ErrorReply):
        return (reply.offending_type != 0 and reply.ack_seq == seq
                and reply.offending_type == int(request.TYPE))
    return False


def _fault_names(flags: int) -> str:
    names = [str(f.name) for f in FaultFlag if flags & f]
    return ", ".join(names) if names else "none"


class McuClient:
    """Talk to the gripper MCU: handshake, commands, telemetry.

    Parameters
    ----------
    transport : Transport
        Link to the MCU (in-memory in tests, serial on hardware).
    clock : Clock
        Time source for reply deadlines; the transport waits on the same time.
    reply_timeout_s : float
        Longest wait for the answer to a frame (s), at most 1 s.
    protocol_version : int
        Version this host speaks (tests change it to provoke a mismatch).
    first_seq : int
        Sequence number of the first frame (0..65535).
    protocol_minor : int
        Newest minor version this host speaks; the session runs at the
        smaller of this and the MCU's (0 emulates a host from before the
        load cell).
    """

    def __init__(
        self,
        transport: Transport,
        clock: Clock,
        *,
        reply_timeout_s: float = 0.1,
        protocol_version: int = PROTOCOL_VERSION,
        first_seq: int = 0,
        protocol_minor: int = PROTOCOL_MINOR,
    ) -> None:
        timeout = check_finite(reply_timeout_s, "reply_timeout_s")
        if not 0.0 < timeout <= 1.0:
            raise InputError(f"reply_timeout_s must be in (0, 1] s, got {reply_timeout_s}")
        if not 0 <= first_seq < SEQ_MODULUS:
            raise InputError(f"first_seq {first_seq} is outside 0..65535")
        if not 0 <= protocol_minor <= PROTOCOL_MINOR:
            raise InputError(f"protocol_minor {protocol_minor} is outside 0..{PROTOCOL_MINOR}")
        self.transport = transport
        self.clock = clock
        self.reply_timeout_s = timeout
        self.protocol_version = protocol_version
        self.protocol_minor = protocol_minor
        self.session_minor = 0
        """Minor version agreed in the last handshake."""
        self.decoder = FrameDecoder(protocol_version, protocol_minor)
        self.stats = LinkStats()
        self.hello_ack: HelloAck | None = None
        self.last_status: Status | None = None
        self.recent_errors: deque[FrameError] = deque(maxlen=32)
        self._telemetry: deque[Status] = deque(maxlen=256)
        self.status_listeners: list[Callable[[Status, float], None]] = []
        """Called with every valid Status received and the host time it arrived."""
        self._seq = first_seq
        self._rx_seq: int | None = None
        self._last_rx_s: float | None = None

    # ------------------------------------------------------------------ public API

    def handshake(self) -> HelloAck:
        """Open a session: send Hello, check the MCU's protocol version, agree the minor.

        A host of minor 1 or later says the Hello that names its minor; an MCU
        of minor 0 answers that with WRONG_LENGTH, and the host says the
        minor-0 Hello instead (docs/protocol.md §12).

        Returns
        -------
        HelloAck
            Firmware id, velocity limit and watchdog period of the MCU (and,
            in a session of minor 1, its minor, features and duty limit).

        Raises
        ------
        VersionMismatchError
            If the MCU speaks another protocol version (both are named).
        LinkTimeoutError, LinkCorruptedError
            If no valid answer arrives within ``reply_timeout_s``.
        """
        self.decoder.reset()
        self._rx_seq = None  # a rebooted MCU counts from 0 again: no frames were lost
        self.session_minor = 0
        if self.protocol_minor == 0:
            reply = self._exchange(Hello())
        else:
            try:
                reply = self._exchange(Hello(self.protocol_minor))
            except McuRejectedError as exc:
                if exc.code != ErrorCode.WRONG_LENGTH:
                    raise
                reply = self._exchange(Hello())  # an MCU of minor 0
        assert isinstance(reply, HelloAck)
        self.hello_ack = reply
        if reply.mcu_minor is not None:
            self.session_minor = min(self.protocol_minor, reply.mcu_minor)
        return reply

    def command(self, velocity_mm_s: float, heater_duty: tuple[float, float]) -> Status:
        """Send one control tick (motor velocity and both heater duties); return the Status.

        Parameters
        ----------
        velocity_mm_s : float
            Closing velocity (mm/s); negative opens.  The MCU clamps it to
            its limit and flags VELOCITY_CLAMPED.
        heater_duty : tuple of float
            Duty of both heaters, each in [0, 1].

        Returns
        -------
        Status
            The MCU's answer (applied values, encoder position, faults).

        Raises
        ------
        InputError
            If a value is not finite, a duty is outside [0, 1].
        McuFaultError
            If a fault (e.g. the watchdog) has stopped the outputs.
        LinkTimeoutError, LinkCorruptedError
            If no valid answer arrives within ``reply_timeout_s``.
        """
        return self._status(Command.from_si(velocity_mm_s, heater_duty))

    def set_motor_velocity(self, velocity_mm_s: float) -> Status:
        """Set the motor velocity only (mm/s); return the Status."""
        v = check_finite(velocity_mm_s, "velocity_mm_s")
        return self._status(SetMotorVelocity(round(v * 1000.0)))

    def set_heater_duty(self, heater_duty: tuple[float, float]) -> Status:
        """Set both heater duties only (each in [0, 1]); return the Status."""
        if len(heater_duty) != 2:
            raise InputError(f"heater_duty needs 2 values, got {len(heater_duty)}")
        return self._status(
            SetHeaterDuty(
                (
                    permyriad_from_duty(heater_duty[0], "heater_duty[0]"),
                    permyriad_from_duty(heater_duty[1], "heater_duty[1]"),
                )
            )
        )

    def set_enabled(self, enabled: bool) -> Status:
        """Enable (clearing latched faults) or disable the outputs; return the Status."""
        return self._status(SetEnable(bool(enabled)))

    def set_watchdog(self, period_s: float) -> Status:
        """Set the MCU's watchdog period (s, 0.02..2); return the Status."""
        p = check_finite(period_s, "watchdog period_s")
        period_ms = round(p * 1000.0)
        if not WATCHDOG_MIN_MS <= period_ms <= WATCHDOG_MAX_MS:
            raise InputError(
                f"watchdog period {period_s} s is outside "
                f"{WATCHDOG_MIN_MS / 1000}..{WATCHDOG_MAX_MS / 1000} s"
            )
        return self._status(SetWatchdog(period_ms))

    def request_status(self) -> Status:
        """Ask for a Status (does not feed the MCU's watchdog)."""
        return self._status(GetStatus())

    def poll(self, timeout_s: float = 0.0) -> list[Status]:
        """Status frames that were not the answer to a request (unsolicited or late).

        Parameters
        ----------
        timeout_s : float
            Longest wait for the first byte (s).

        Returns
        -------
        list of Status
            In arrival order; :attr:`last_status` is the newest.
        """
        for packet in self._ingest(self.transport.read(timeout_s)):
            if isinstance(packet.message, Status):
                self._telemetry.append(packet.message)
        out = list(self._telemetry)
        self._telemetry.clear()
        return out

    @property
    def link_age_s(self) -> float:
        """Time since the last valid frame from the MCU (s); inf before the first."""
        if self._last_rx_s is None:
            return math.inf
        return self.clock.now() - self._last_rx_s

    def close(self) -> None:
        """Close the transport (the MCU's watchdog then stops the outputs)."""
        self.transport.close()

    # ------------------------------------------------------------------ internals

    def _status(self, message: Message) -> Status:
        reply = self._exchange(message)
        assert isinstance(reply, Status)
        return reply

    def _next_seq(self) -> int:
        seq = self._seq
        self._seq = (self._seq + 1) % SEQ_MODULUS
        return seq

    def _ingest(self, data: bytes) -> list[Packet]:
        """Decode ``data``; record errors and telemetry; return the valid packets."""
        packets: list[Packet] = []
        for item in self.decoder.feed(data):
            if isinstance(item, FrameError):
                if item.code == ErrorCode.WRONG_VERSION and item.version is not None:
                    raise VersionMismatchError(self.protocol_version, item.version)
                self.stats.decode_errors += 1
                self.recent_errors.append(item)
                continue
            if self._rx_seq is not None:
                ahead = (item.seq - self._rx_seq) % SEQ_MODULUS
                if ahead == 0 or ahead >= SEQ_MODULUS // 2:  # repeated or gone back: a replay
                    self.stats.stale_frames += 1
                    continue
                self.stats.mcu_frames_lost += ahead - 1
            self.stats.frames_received += 1
            rx_s = self._last_rx_s = self.clock.now()
            self._rx_seq = item.seq
            if isinstance(item.message, Status):
                self.last_status = item.message
                if item.message.unsolicited:
                    self.stats.unsolicited += 1
                for listener in self.status_listeners:
                    listener(item.message, rx_s)
            packets.append(item)
        return packets

    def _exchange(self, message: Message) -> Message:
        seq = self._next_seq()
        what = f"{type(message).__name__} seq {seq}"
        frame = encode_frame(message, seq, version=self.protocol_version, leading_delimiter=True)
        errors_before = self.stats.decode_errors
        unreadable: list[str] = []
        self.transport.write(frame)
        self.stats.frames_sent += 1
        stale_before = self.stats.stale_frames
        deadline = self.clock.now() + self.reply_timeout_s
        while True:
            data = self.transport.read(max(0.0, deadline - self.clock.now()))
            packets = [p.message for p in self._ingest(data)]
            answer = next((i for i, m in enumerate(packets) if _is_answer(m, message, seq)), None)
            for i, other in enumerate(packets):
                # Status frames beside the answer, even those after it in the same read (a
                # fault that tripped just after answering), are poll()'s.
                if i == answer:
                    continue
                if isinstance(other, ErrorReply) and other.offending_type == 0:
                    unreadable.append(other.code_name)
                elif isinstance(other, Status):
                    self._telemetry.append(other)
            if answer is not None:
                reply = packets[answer]
                if isinstance(reply, ErrorReply):
                    self._raise_rejected(what, reply)
                return reply
            if self.clock.now() >= deadline:
                self._raise_timeout(what, self.stats.decode_errors - errors_before, unreadable,
                                    self.stats.stale_frames - stale_before)

    def _raise_rejected(self, what: str, reply: ErrorReply) -> None:
        if reply.code == ErrorCode.NOT_ENABLED and reply.detail & int(TRIP_FAULTS):
            raise McuFaultError(
                f"MCU refused {what}: outputs stopped by fault "
                f"{_fault_names(reply.detail & int(TRIP_FAULTS))}; call set_enabled(True) "
                "to clear it", reply.code
            )
        detail = f" (detail {reply.detail})" if reply.detail else ""
        raise McuRejectedError(f"MCU rejected {what}: {reply.code_name}{detail}", reply.code)

    def _raise_timeout(self, what: str, n_corrupt: int, unreadable: list[str],
                       n_stale: int = 0) -> None:
        ms = round(self.reply_timeout_s * 1000)
        notes = []
        if n_stale:
            notes.append(f"{n_stale} frame(s) with a repeated or old sequence number dropped")
        if n_corrupt:
            notes.append(f"{n_corrupt} corrupted frame(s) received ({self.recent_errors[-1]})")
        if unreadable:
            notes.append(
                f"the MCU could not read {len(unreadable)} frame(s) ({', '.join(unreadable)})"
            )
        if self.decoder.pending_bytes:
            notes.append(f"{self.decoder.pending_bytes} bytes of a truncated frame pending")
        if notes:
            raise LinkCorruptedError(
                f"no valid reply to {what} within {ms} ms: " + "; ".join(notes)
            )
        raise LinkTimeoutError(
            f"no reply from the MCU to {what} within {ms} ms: link dead or MCU stopped"
        )
