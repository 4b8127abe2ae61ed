"""MCU protocol codec: bytes <-> message dataclasses, pure (no I/O, no clock).

A frame on the wire is ``COBS(version | type | seq | payload | crc16) 0x00``
(see ``docs/protocol.md``).  The version byte is the protocol's major
version; a minor version only appends fields to payloads, so each message
type has one payload layout per minor version (``PAYLOAD_LAYOUTS``), and a
receiver accepts the layouts of every minor version up to its own.  All
integers are little-endian; the CRC is CRC-16/CCITT-FALSE (poly 0x1021,
init 0xFFFF, no reflection, no final xor, check value 0x29B1 for
``b"123456789"``) over the unencoded bytes before it.

Layers, bottom up: :func:`crc16_ccitt_false`, :func:`cobs_encode` /
:func:`cobs_decode`, the message dataclasses (``payload()`` /
``from_payload()``), :func:`encode_frame` / :func:`decode_frame` for one
frame, and :class:`FrameDecoder` for a byte stream.
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from typing import ClassVar

from relaxgrip.errors import InputError
from relaxgrip.hardware.protocol.errors import FrameDecodeError

__all__ = [
    "CRC_BYTES",
    "DELIMITER",
    "DUTY_FULL_SCALE",
    "HEADER_BYTES",
    "MAX_ENCODED_FRAME_BYTES",
    "MAX_RAW_FRAME_BYTES",
    "PROTOCOL_MINOR",
    "PROTOCOL_VERSION",
    "SEQ_MODULUS",
    "WATCHDOG_DEFAULT_MS",
    "WATCHDOG_MAX_MS",
    "WATCHDOG_MIN_MS",
    "Command",
    "DecodeResult",
    "ErrorCode",
    "ErrorReply",
    "FaultFlag",
    "Feature",
    "FieldValueError",
    "FrameDecoder",
    "FrameError",
    "GetStatus",
    "Hello",
    "HelloAck",
    "Message",
    "MsgType",
    "Packet",
    "SetEnable",
    "SetHeaterDuty",
    "SetMotorVelocity",
    "SetWatchdog",
    "StateFlag",
    "Status",
    "cobs_decode",
    "cobs_encode",
    "crc16_ccitt_false",
    "decode_frame",
    "duty_from_permyriad",
    "encode_frame",
    "permyriad_from_duty",
]

PROTOCOL_VERSION = 1
"""Major version of this protocol; byte 0 of every frame."""
PROTOCOL_MINOR = 1
"""Minor version of this protocol, agreed in the handshake (docs/protocol.md §12)."""
HEADER_BYTES = 4
"""version (u8), type (u8), seq (u16)."""
CRC_BYTES = 2
MAX_RAW_FRAME_BYTES = 254
"""Longest unencoded frame (header + payload + CRC): one COBS block."""
MAX_ENCODED_FRAME_BYTES = MAX_RAW_FRAME_BYTES + 1
"""Longest COBS-encoded frame, without its delimiter."""
DELIMITER = b"\x00"
SEQ_MODULUS = 1 << 16
DUTY_FULL_SCALE = 10_000
"""Heater duty 1.0 in permyriad (1 ‱ = 1e-4)."""
WATCHDOG_DEFAULT_MS = 200
WATCHDOG_MIN_MS = 20
WATCHDOG_MAX_MS = 2000

_U8 = (0, 0xFF)
_U16 = (0, 0xFFFF)
_U32 = (0, 0xFFFF_FFFF)
_I32 = (-(1 << 31), (1 << 31) - 1)


class MsgType(IntEnum):
    """Message type, byte 1 of a frame: host -> MCU below 0x80, MCU -> host from 0x80."""

    HELLO = 0x01
    SET_MOTOR_VELOCITY = 0x02
    SET_HEATER_DUTY = 0x03
    SET_ENABLE = 0x04
    SET_WATCHDOG = 0x05
    COMMAND = 0x06
    GET_STATUS = 0x07
    HELLO_ACK = 0x81
    STATUS = 0x82
    ERROR = 0x83


class ErrorCode(IntEnum):
    """Why a frame was rejected (the ``code`` of an Error reply, the kind of a FrameError)."""

    BAD_COBS = 1
    BAD_CRC = 2
    TOO_SHORT = 3
    OVERSIZE = 4
    WRONG_VERSION = 5
    UNKNOWN_TYPE = 6
    WRONG_LENGTH = 7
    VALUE_OUT_OF_RANGE = 8
    NO_HANDSHAKE = 9
    STALE_SEQUENCE = 10
    NOT_ENABLED = 11


class FaultFlag(IntFlag):
    """Bits of ``Status.fault_flags``.

    WATCHDOG, RESET, OVERTEMP, ENCODER and MOTOR_DRIVER latch until an
    Enable; all but RESET also switch the outputs off and disable the MCU.
    The two CLAMPED bits describe the latest motion or heater command.
    """

    WATCHDOG = 1 << 0
    RESET = 1 << 1
    VELOCITY_CLAMPED = 1 << 2
    DUTY_CLAMPED = 1 << 3
    OVERTEMP = 1 << 4
    ENCODER = 1 << 5
    MOTOR_DRIVER = 1 << 6


LATCHED_FAULTS = (
    FaultFlag.WATCHDOG
    | FaultFlag.RESET
    | FaultFlag.OVERTEMP
    | FaultFlag.ENCODER
    | FaultFlag.MOTOR_DRIVER
)
TRIP_FAULTS = FaultFlag.WATCHDOG | FaultFlag.OVERTEMP | FaultFlag.ENCODER | FaultFlag.MOTOR_DRIVER


class StateFlag(IntFlag):
    """Bits of ``Status.state_flags``."""

    ENABLED = 1 << 0
    UNSOLICITED = 1 << 1
    LOAD_CELL = 1 << 2
    """Minor 1: the load-cell ADC delivered a conversion within the last 500 ms."""


class Feature(IntFlag):
    """Bits of ``HelloAck.features`` (minor 1): what the firmware was built with."""

    LOAD_CELL = 1 << 0
    """An HX711-class load-cell ADC is read and reported in Status."""


# --------------------------------------------------------------------------- CRC and COBS


def crc16_ccitt_false(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (a.k.a. CRC-16/IBM-3740) of ``data``.

    Poly 0x1021, init 0xFFFF, input and output not reflected, xorout 0x0000;
    the check value of ``b"123456789"`` is 0x29B1.

    Parameters
    ----------
    data : bytes
        Bytes to checksum.

    Returns
    -------
    int
        The CRC, 0..0xFFFF.
    """
    # binascii.crc_hqx is the non-reflected 0x1021 CRC with a caller-chosen init.
    return binascii.crc_hqx(data, 0xFFFF)


def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing (Cheshire & Baker 1999) of ``data``.

    Parameters
    ----------
    data : bytes
        Any bytes.

    Returns
    -------
    bytes
        The encoding: no zero byte, ``len(data) + 1`` bytes for up to 254
        input bytes; without the 0x00 delimiter.
    """
    out = bytearray()
    block = bytearray()
    after_full_block = False
    for byte in data:
        after_full_block = False
        if byte == 0:
            out.append(len(block) + 1)
            out += block
            block.clear()
        else:
            block.append(byte)
            if len(block) == 254:
                out.append(255)
                out += block
                block.clear()
                after_full_block = True
    # A 0xFF block implies no zero after it, so input ending right after one
    # needs no final code byte (the canonical encoding).
    if not after_full_block:
        out.append(len(block) + 1)
        out += block
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Invert :func:`cobs_encode`.

    Parameters
    ----------
    data : bytes
        One COBS-encoded frame without its delimiter.

    Returns
    -------
    bytes
        The decoded bytes.

    Raises
    ------
    InputError
        If ``data`` is empty, holds a zero byte, or a code byte points past its end.
    """
    if not data:
        raise InputError("COBS frame is empty")
    out = bytearray()
    i = 0
    n = len(data)
    while i < n:
        code = data[i]
        if code == 0:
            raise InputError(f"COBS frame holds a zero byte at offset {i}")
        end = i + code
        if end > n:
            raise InputError(f"COBS code {code} at offset {i} runs past the frame end ({n} bytes)")
        block = data[i + 1 : end]
        if 0 in block:
            raise InputError(f"COBS frame holds a zero byte at offset {i + 1 + block.index(0)}")
        out += block
        i = end
        if code != 255 and i < n:
            out.append(0)
    return bytes(out)


# --------------------------------------------------------------------------- messages


class FieldValueError(InputError):
    """A payload field that does not decode: the MCU answers ``VALUE_OUT_OF_RANGE``
    with ``value`` as the Error's detail (docs/protocol.md §4)."""

    def __init__(self, message: str, value: int = 0) -> None:
        super().__init__(message)
        self.value = value


def _check_int(value: int, name: str, bounds: tuple[int, int]) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{name} must be an integer, got {value!r}")
    lo, hi = bounds
    if not lo <= value <= hi:
        raise InputError(f"{name} {value} is outside {lo}..{hi}")
    return value


def _check_duty_pair(value: tuple[int, int], name: str) -> None:
    if not isinstance(value, tuple) or len(value) != 2:
        raise InputError(f"{name} needs 2 values, got {value!r}")
    for k, duty in enumerate(value):
        _check_int(duty, f"{name}[{k}]", _U16)


def permyriad_from_duty(duty: float, name: str = "heater duty") -> int:
    """Wire value (permyriad, 0..10000) of a PWM duty in [0, 1].

    Parameters
    ----------
    duty : float
        PWM duty, 0..1.
    name : str
        Name used in the error message.

    Returns
    -------
    int
        ``round(duty * 10000)``.

    Raises
    ------
    InputError
        If ``duty`` is not a finite number in [0, 1].
    """
    from relaxgrip.validate import check_duty

    return round(check_duty(duty, name) * DUTY_FULL_SCALE)


def duty_from_permyriad(value: int) -> float:
    """PWM duty (0..1 when in range) of a wire value in permyriad."""
    return value / DUTY_FULL_SCALE


class _Empty:
    """Mix-in for messages without a payload."""

    PAYLOAD_LAYOUTS: ClassVar[tuple[int, ...]] = (0,)

    def payload(self) -> bytes:
        """The payload bytes (none)."""
        return b""


def _all_or_none(msg: object, names: tuple[str, ...], minor: int) -> bool:
    """Whether the fields ``names`` (those of minor ``minor``'s layout) are all set.

    Raises
    ------
    InputError
        If some are set and others are None: a layout is whole or absent.
    """
    given = [getattr(msg, name) is not None for name in names]
    if any(given) and not all(given):
        missing = [n for n, g in zip(names, given, strict=True) if not g]
        raise InputError(f"{type(msg).__name__}: the minor-{minor} fields come together; "
                         f"missing {', '.join(missing)}")
    return all(given)


@dataclass(frozen=True)
class Hello:
    """Host -> MCU 0x01: open a session; the MCU answers :class:`HelloAck`.

    Attributes
    ----------
    host_minor : int or None
        Newest protocol minor version the host speaks (u8; the minor-1
        layout); None is the minor-0 Hello, without payload.
    """

    TYPE: ClassVar[MsgType] = MsgType.HELLO
    PAYLOAD_LAYOUTS: ClassVar[tuple[int, ...]] = (0, 1)
    host_minor: int | None = None

    def __post_init__(self) -> None:
        if self.host_minor is not None:
            _check_int(self.host_minor, "host_minor", _U8)

    def payload(self) -> bytes:
        """The payload bytes (none in the minor-0 layout)."""
        return b"" if self.host_minor is None else bytes([self.host_minor])

    @classmethod
    def from_payload(cls, payload: bytes) -> Hello:
        """Decode a payload of one of :attr:`PAYLOAD_LAYOUTS` bytes."""
        return cls(payload[0] if payload else None)


@dataclass(frozen=True)
class GetStatus(_Empty):
    """Host -> MCU 0x07: ask for a Status; does not feed the watchdog."""

    TYPE: ClassVar[MsgType] = MsgType.GET_STATUS

    @classmethod
    def from_payload(cls, payload: bytes) -> GetStatus:
        """Decode a payload of one of :attr:`PAYLOAD_LAYOUTS` bytes."""
        return cls()


@dataclass(frozen=True)
class SetMotorVelocity:
    """Host -> MCU 0x02: motor closing velocity.

    Attributes
    ----------
    velocity_um_s : int
        Closing velocity (µm/s, i32); negative opens.
    """

    TYPE: ClassVar[MsgType] = MsgType.SET_MOTOR_VELOCITY
    PAYLOAD_LAYOUTS: ClassVar[tuple[int, ...]] = (4,)
    _S: ClassVar[struct.Struct] = struct.Struct("<i")
    velocity_um_s: int

    def __post_init__(self) -> None:
        _check_int(self.velocity_um_s, "velocity_um_s", _I32)

    def payload(self) -> bytes:
        """The payload bytes."""
        return self._S.pack(self.velocity_um_s)

    @classmethod
    def from_payload(cls, payload: bytes) -> SetMotorVelocity:
        """Decode a payload of one of :attr:`PAYLOAD_LAYOUTS` bytes."""
        (v,) = cls._S.unpack(payload)
        return cls(v)

    @property
    def velocity_mm_s(self) -> float:
        """Closing velocity (mm/s)."""
        return self.velocity_um_s / 1000.0


@dataclass(frozen=True)
class SetHeaterDuty:
    """Host -> MCU 0x03: PWM duty of both heater films.

    Attributes
    ----------
    heater_duty_permyriad : tuple of int
        Duty of finger 0 and finger 1 (u16 each, 10000 = duty 1.0; the MCU
        clamps larger values to 10000).
    """

    TYPE: ClassVar[MsgType] = MsgType.SET_HEATER_DUTY
    PAYLOAD_LAYOUTS: ClassVar[tuple[int, ...]] = (4,)
    _S: ClassVar[struct.Struct] = struct.Struct("<HH")
    heater_duty_permyriad: tuple[int, int]

    def __post_init__(self) -> None:
        _check_duty_pair(self.heater_duty_permyriad, "heater_duty_permyriad")

    def payload(self) -> bytes:
        """The payload bytes."""
        return self._S.pack(*self.heater_duty_permyriad)

    @classmethod
    def from_payload(cls, payload: bytes) -> SetHeaterDuty:
        """Decode a payload of one of :attr:`PAYLOAD_LAYOUTS` bytes."""
        d0, d1 = cls._S.unpack(payload)
        return cls((d0, d1))

    @property
    def heater_duty(self) -> tuple[float, float]:
        """Duty of both heaters (0..1 when in range)."""
        d0, d1 = self.heater_duty_permyriad
        return duty_from_permyriad(d0), duty_from_permyriad(d1)


@dataclass(frozen=True)
class SetEnable:
    """Host -> MCU 0x04: enable (and clear latched faults) or disable the outputs.

    Attributes
    ----------
    enabled : bool
        Wire u8: 1 enables, 0 disables; any other value is VALUE_OUT_OF_RANGE.
    """

    TYPE: ClassVar[MsgType] = MsgType.SET_ENABLE
    PAYLOAD_LAYOUTS: ClassVar[tuple[int, ...]] = (1,)
    enabled: bool

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise InputError(f"enabled must be a bool, got {self.enabled!r}")

    def payload(self) -> bytes:
        """The payload bytes."""
        return b"\x01" if self.enabled else b"\x00"

    @classmethod
    def from_payload(cls, payload: bytes) -> SetEnable:
        """Decode a payload of one of :attr:`PAYLOAD_LAYOUTS` bytes."""
        if payload[0] > 1:
            raise FieldValueError(f"SetEnable value {payload[0]} is neither 0 nor 1", payload[0])
        return cls(payload[0] == 1)


@dataclass(frozen=True)
class SetWatchdog:
    """Host -> MCU 0x05: watchdog period.

    Attributes
    ----------
    period_ms : int
        Watchdog period (ms, u16); the MCU accepts 20..2000.
    """

    TYPE: ClassVar[MsgType] = MsgType.SET_WATCHDOG
    PAYLOAD_LAYOUTS: ClassVar[tuple[int, ...]] = (2,)
    _S: ClassVar[struct.Struct] = struct.Struct("<H")
    period_ms: int

    def __post_init__(self) -> None:
        _check_int(self.period_ms, "period_ms", _U16)

    def payload(self) -> bytes:
        """The payload bytes."""
        return self._S.pack(self.period_ms)

    @classmethod
    def from_payload(cls, payload: bytes) -> SetWatchdog:
        """Decode a payload of one of :attr:`PAYLOAD_LAYOUTS` bytes."""
        (ms,) = cls._S.unpack(payload)
        return cls(ms)


@dataclass(frozen=True)
class Command:
    """Host -> MCU 0x06: one control tick, motor velocity and both heater duties.

    Attributes
    ----------
    velocity_um_s : int
        Closing velocity (µm/s, i32); negative opens.
    heater_duty_permyriad : tuple of int
        Duty of finger 0 and finger 1 (u16 each, 10000 = duty 1.0).
    """

    TYPE: ClassVar[MsgType] = MsgType.COMMAND
    PAYLOAD_LAYOUTS: ClassVar[tuple[int, ...]] = (8,)
    _S: ClassVar[struct.Struct] = struct.Struct("<iHH")
    velocity_um_s: int
    heater_duty_permyriad: tuple[int, int] = (0, 0)

    def __post_init__(self) -> None:
        _check_int(self.velocity_um_s, "velocity_um_s", _I32)
        _check_duty_pair(self.heater_duty_permyriad, "heater_duty_permyriad")

    @classmethod
    def from_si(cls, velocity_mm_s: float, heater_duty: tuple[float, float]) -> Command:
        """Build from a velocity in mm/s and duties in [0, 1].

        Parameters
        ----------
        velocity_mm_s : float
            Closing velocity (mm/s), rounded to 1 µm/s.
        heater_duty : tuple of float
            Duty of both heaters, each in [0, 1], rounded to 1e-4.

        Returns
        -------
        Command
            The wire message.

        Raises
        ------
        InputError
            If a value is not finite, a duty is outside [0, 1] or the
            velocity does not fit an i32 in µm/s.
        """
        from relaxgrip.validate import check_finite

        v = check_finite(velocity_mm_s, "velocity_mm_s")
        if len(heater_duty) != 2:
            raise InputError(f"heater_duty needs 2 values, got {len(heater_duty)}")
        duties = (
            permyriad_from_duty(heater_duty[0], "heater_duty[0]"),
            permyriad_from_duty(heater_duty[1], "heater_duty[1]"),
        )
        return cls(round(v * 1000.0), duties)

    def payload(self) -> bytes:
        """The payload bytes."""
        return self._S.pack(self.velocity_um_s, *self.heater_duty_permyriad)

    @classmethod
    def from_payload(cls, payload: bytes) -> Command:
        """Decode a payload of one of :attr:`PAYLOAD_LAYOUTS` bytes."""
        v, d0, d1 = cls._S.unpack(payload)
        return cls(v, (d0, d1))

    @property
    def velocity_mm_s(self) -> float:
        """Closing velocity (mm/s)."""
        return self.velocity_um_s / 1000.0

    @property
    def heater_duty(self) -> tuple[float, float]:
        """Duty of both heaters (0..1 when in range)."""
        d0, d1 = self.heater_duty_permyriad
        return duty_from_permyriad(d0), duty_from_permyriad(d1)


FIRMWARE_ID_BYTES = 16


@dataclass(frozen=True)
class HelloAck:
    """MCU -> host 0x81: answer to Hello.

    Attributes
    ----------
    ack_seq : int
        Sequence number of the Hello answered (u16).
    watchdog_ms : int
        Watchdog period now in force (ms, u16).
    max_velocity_um_s : int
        The MCU's velocity limit (µm/s, i32, > 0 on a real MCU).
    firmware_id : str
        Firmware name and version, printable ASCII, at most 16 characters
        (NUL-padded on the wire).
    mcu_minor : int or None
        Minor-1 layout: newest protocol minor version the MCU speaks (u8);
        the session runs at the smaller of the host's and this.
    features : int or None
        Minor-1 layout: :class:`Feature` bits of the firmware build (u8).
    heater_duty_limit_permyriad : int or None
        Minor-1 layout: the MCU clamps every heater duty to this (u16, at
        most 10000).
    """

    TYPE: ClassVar[MsgType] = MsgType.HELLO_ACK
    PAYLOAD_LAYOUTS: ClassVar[tuple[int, ...]] = (24, 28)
    _S: ClassVar[struct.Struct] = struct.Struct("<HHi16s")
    _S1: ClassVar[struct.Struct] = struct.Struct("<BBH")
    _MINOR1: ClassVar[tuple[str, ...]] = ("mcu_minor", "features", "heater_duty_limit_permyriad")
    ack_seq: int
    watchdog_ms: int
    max_velocity_um_s: int
    firmware_id: str
    mcu_minor: int | None = None
    features: int | None = None
    heater_duty_limit_permyriad: int | None = None

    def __post_init__(self) -> None:
        _check_int(self.ack_seq, "ack_seq", _U16)
        _check_int(self.watchdog_ms, "watchdog_ms", _U16)
        _check_int(self.max_velocity_um_s, "max_velocity_um_s", _I32)
        fid = self.firmware_id
        if not isinstance(fid, str) or len(fid) > FIRMWARE_ID_BYTES:
            raise InputError(f"firmware_id must be a str of at most 16 characters, got {fid!r}")
        if not all(0x20 <= ord(c) < 0x7F for c in fid):
            raise InputError(f"firmware_id must be printable ASCII, got {fid!r}")
        if _all_or_none(self, self._MINOR1, 1):
            _check_int(self.mcu_minor, "mcu_minor", _U8)  # type: ignore[arg-type]
            _check_int(self.features, "features", _U8)  # type: ignore[arg-type]
            _check_int(self.heater_duty_limit_permyriad,  # type: ignore[arg-type]
                       "heater_duty_limit_permyriad", _U16)

    @property
    def layout_minor(self) -> int:
        """Minor version of this message's payload layout (0 or 1)."""
        return 0 if self.mcu_minor is None else 1

    def payload(self) -> bytes:
        """The payload bytes."""
        head = self._S.pack(
            self.ack_seq, self.watchdog_ms, self.max_velocity_um_s, self.firmware_id.encode("ascii")
        )
        if self.mcu_minor is None:
            return head
        return head + self._S1.pack(self.mcu_minor, self.features,
                                    self.heater_duty_limit_permyriad)

    @classmethod
    def from_payload(cls, payload: bytes) -> HelloAck:
        """Decode a payload of one of :attr:`PAYLOAD_LAYOUTS` bytes."""
        ack, wd, vmax, raw = cls._S.unpack(payload[: cls._S.size])
        text = raw.rstrip(b"\x00")
        if not all(0x20 <= b < 0x7F for b in text):
            raise InputError(f"firmware_id {raw!r} is not NUL-padded printable ASCII")
        if len(payload) == cls._S.size:
            return cls(ack, wd, vmax, text.decode("ascii"))
        minor, features, duty_limit = cls._S1.unpack(payload[cls._S.size :])
        return cls(ack, wd, vmax, text.decode("ascii"), minor, features, duty_limit)


@dataclass(frozen=True)
class Status:
    """MCU -> host 0x82: telemetry, the answer to every accepted host frame but Hello.

    Attributes
    ----------
    ack_seq : int
        Sequence number of the host frame answered (u16); for an unsolicited
        Status, the last one accepted.
    mcu_time_us : int
        MCU clock (µs, u32, wraps after 2**32 µs ≈ 71.6 min).
    encoder_position_um : int
        Motor position (µm from fully open, i32).
    velocity_um_s : int
        Velocity applied to the motor after clamping (µm/s, i32).
    heater_duty_permyriad : tuple of int
        Duty applied to both heaters (u16 each, 10000 = duty 1.0).
    fault_flags : int
        :class:`FaultFlag` bits (u16).
    state_flags : int
        :class:`StateFlag` bits (u8).
    rx_error_count : int
        Host frames rejected since the MCU started (u16, wraps).
    rx_gap_count : int
        Host frames missed according to sequence numbers (u16, wraps).
    load_cell_counts : int or None
        Minor-1 layout: the latest load-cell conversion, raw signed 24-bit
        ADC counts sign-extended (i32); 0 before the first.
    load_cell_time_us : int or None
        Minor-1 layout: MCU clock when that conversion was read (µs, u32).
    load_cell_samples : int or None
        Minor-1 layout: conversions read since power-up (u16, wraps): a new
        value means a new conversion.
    """

    TYPE: ClassVar[MsgType] = MsgType.STATUS
    PAYLOAD_LAYOUTS: ClassVar[tuple[int, ...]] = (25, 35)
    _S: ClassVar[struct.Struct] = struct.Struct("<HIiiHHHBHH")
    _S1: ClassVar[struct.Struct] = struct.Struct("<iIH")
    _MINOR1: ClassVar[tuple[str, ...]] = ("load_cell_counts", "load_cell_time_us",
                                          "load_cell_samples")
    ack_seq: int
    mcu_time_us: int
    encoder_position_um: int
    velocity_um_s: int
    heater_duty_permyriad: tuple[int, int]
    fault_flags: int
    state_flags: int
    rx_error_count: int = 0
    rx_gap_count: int = 0
    load_cell_counts: int | None = None
    load_cell_time_us: int | None = None
    load_cell_samples: int | None = None

    def __post_init__(self) -> None:
        _check_int(self.ack_seq, "ack_seq", _U16)
        _check_int(self.mcu_time_us, "mcu_time_us", _U32)
        _check_int(self.encoder_position_um, "encoder_position_um", _I32)
        _check_int(self.velocity_um_s, "velocity_um_s", _I32)
        _check_duty_pair(self.heater_duty_permyriad, "heater_duty_permyriad")
        _check_int(self.fault_flags, "fault_flags", _U16)
        _check_int(self.state_flags, "state_flags", _U8)
        _check_int(self.rx_error_count, "rx_error_count", _U16)
        _check_int(self.rx_gap_count, "rx_gap_count", _U16)
        if _all_or_none(self, self._MINOR1, 1):
            _check_int(self.load_cell_counts, "load_cell_counts", _I32)  # type: ignore[arg-type]
            _check_int(self.load_cell_time_us, "load_cell_time_us", _U32)  # type: ignore[arg-type]
            _check_int(self.load_cell_samples, "load_cell_samples", _U16)  # type: ignore[arg-type]

    @property
    def layout_minor(self) -> int:
        """Minor version of this message's payload layout (0 or 1)."""
        return 0 if self.load_cell_counts is None else 1

    def payload(self) -> bytes:
        """The payload bytes."""
        head = self._S.pack(
            self.ack_seq,
            self.mcu_time_us,
            self.encoder_position_um,
            self.velocity_um_s,
            *self.heater_duty_permyriad,
            self.fault_flags,
            self.state_flags,
            self.rx_error_count,
            self.rx_gap_count,
        )
        if self.load_cell_counts is None:
            return head
        return head + self._S1.pack(self.load_cell_counts, self.load_cell_time_us,
                                    self.load_cell_samples)

    @classmethod
    def from_payload(cls, payload: bytes) -> Status:
        """Decode a payload of one of :attr:`PAYLOAD_LAYOUTS` bytes."""
        ack, t, pos, vel, d0, d1, faults, state, errs, gaps = cls._S.unpack(
            payload[: cls._S.size])
        if len(payload) == cls._S.size:
            return cls(ack, t, pos, vel, (d0, d1), faults, state, errs, gaps)
        counts, t_cell, n_cell = cls._S1.unpack(payload[cls._S.size :])
        return cls(ack, t, pos, vel, (d0, d1), faults, state, errs, gaps, counts, t_cell, n_cell)

    @property
    def enabled(self) -> bool:
        """Whether the MCU drives its outputs."""
        return bool(self.state_flags & StateFlag.ENABLED)

    @property
    def unsolicited(self) -> bool:
        """Whether the MCU sent this Status on its own (a fault tripped)."""
        return bool(self.state_flags & StateFlag.UNSOLICITED)

    @property
    def faults(self) -> frozenset[str]:
        """Names of the fault bits set (``"BIT9"`` for a bit this version does not know)."""
        known = {int(f): str(f.name) for f in FaultFlag}
        return frozenset(
            known.get(1 << bit, f"BIT{bit}") for bit in range(16) if self.fault_flags & (1 << bit)
        )

    @property
    def position_mm(self) -> float:
        """Motor position (mm from fully open)."""
        return self.encoder_position_um / 1000.0

    @property
    def velocity_mm_s(self) -> float:
        """Applied motor velocity (mm/s)."""
        return self.velocity_um_s / 1000.0

    @property
    def heater_duty(self) -> tuple[float, float]:
        """Applied duty of both heaters (0..1)."""
        d0, d1 = self.heater_duty_permyriad
        return duty_from_permyriad(d0), duty_from_permyriad(d1)


@dataclass(frozen=True)
class ErrorReply:
    """MCU -> host 0x83: a host frame was rejected.

    Attributes
    ----------
    ack_seq : int
        Sequence number of the rejected frame (u16); 0 when unknown
        (``offending_type == 0``).
    code : int
        :class:`ErrorCode` (u8; a newer firmware may send codes this host
        does not know).
    offending_type : int
        Message type of the rejected frame, 0 when it could not be read (u8).
    detail : int
        Code-specific detail (u16): the received version for WRONG_VERSION,
        the payload length for WRONG_LENGTH, the value for
        VALUE_OUT_OF_RANGE, the last accepted seq for STALE_SEQUENCE, the
        fault flags for NOT_ENABLED, else 0.
    """

    TYPE: ClassVar[MsgType] = MsgType.ERROR
    PAYLOAD_LAYOUTS: ClassVar[tuple[int, ...]] = (6,)
    _S: ClassVar[struct.Struct] = struct.Struct("<HBBH")
    ack_seq: int
    code: int
    offending_type: int = 0
    detail: int = 0

    def __post_init__(self) -> None:
        _check_int(self.ack_seq, "ack_seq", _U16)
        _check_int(self.code, "code", _U8)
        _check_int(self.offending_type, "offending_type", _U8)
        _check_int(self.detail, "detail", _U16)

    def payload(self) -> bytes:
        """The payload bytes."""
        return self._S.pack(self.ack_seq, self.code, self.offending_type, self.detail)

    @classmethod
    def from_payload(cls, payload: bytes) -> ErrorReply:
        """Decode a payload of one of :attr:`PAYLOAD_LAYOUTS` bytes."""
        ack, code, typ, detail = cls._S.unpack(payload)
        return cls(ack, code, typ, detail)

    @property
    def code_name(self) -> str:
        """Name of the error code (``"CODE_42"`` if unknown)."""
        try:
            return ErrorCode(self.code).name
        except ValueError:
            return f"CODE_{self.code}"


Message = (
    Hello
    | SetMotorVelocity
    | SetHeaterDuty
    | SetEnable
    | SetWatchdog
    | Command
    | GetStatus
    | HelloAck
    | Status
    | ErrorReply
)

MESSAGE_CLASSES: dict[int, type[Message]] = {
    int(cls.TYPE): cls
    for cls in (
        Hello,
        SetMotorVelocity,
        SetHeaterDuty,
        SetEnable,
        SetWatchdog,
        Command,
        GetStatus,
        HelloAck,
        Status,
        ErrorReply,
    )
}


def type_name(msg_type: int) -> str:
    """Name of a message type byte (``"TYPE_0x42"`` if unknown)."""
    try:
        return MsgType(msg_type).name
    except ValueError:
        return f"TYPE_0x{msg_type:02X}"


# --------------------------------------------------------------------------- frames


@dataclass(frozen=True)
class Packet:
    """One decoded frame: the header fields and the message.

    Attributes
    ----------
    seq : int
        Sender's sequence number (u16).
    message : Message
        The decoded message.
    version : int
        Protocol version byte of the frame.
    """

    seq: int
    message: Message
    version: int = PROTOCOL_VERSION


@dataclass(frozen=True)
class FrameError:
    """A frame that could not be decoded (typed, never raised by :class:`FrameDecoder`).

    Attributes
    ----------
    code : ErrorCode
        What was wrong.
    reason : str
        One line naming the problem.
    raw : bytes
        The encoded frame without delimiter (at most 255 bytes kept).
    version, msg_type, seq : int or None
        Header fields, when the CRC proved them trustworthy.
    detail : int
        What an MCU puts in ErrorReply.detail: the received version
        (WRONG_VERSION), type (UNKNOWN_TYPE) or payload length (WRONG_LENGTH).
    """

    code: ErrorCode
    reason: str
    raw: bytes = b""
    version: int | None = None
    msg_type: int | None = None
    seq: int | None = None
    detail: int = 0

    def __str__(self) -> str:
        return f"{self.code.name}: {self.reason}"


DecodeResult = Packet | FrameError
_HEADER = struct.Struct("<BBH")
_CRC = struct.Struct("<H")


def encode_frame(
    message: Message,
    seq: int,
    *,
    version: int = PROTOCOL_VERSION,
    leading_delimiter: bool = False,
) -> bytes:
    """Frame ``message``: ``[0x00] COBS(header | payload | crc) 0x00``.

    Parameters
    ----------
    message : Message
        Any message dataclass.
    seq : int
        Sender's sequence number, 0..65535.
    version : int
        Protocol version byte (tests use other values to emulate a mismatch).
    leading_delimiter : bool
        Also put a 0x00 before the frame, which ends any partial frame the
        receiver holds (so a truncated frame never swallows this one).

    Returns
    -------
    bytes
        The bytes to write.

    Raises
    ------
    InputError
        If ``seq`` or ``version`` is out of range.
    """
    _check_int(seq, "seq", _U16)
    _check_int(version, "version", _U8)
    body = _HEADER.pack(version, int(message.TYPE), seq) + message.payload()
    raw = body + _CRC.pack(crc16_ccitt_false(body))
    encoded = cobs_encode(raw) + DELIMITER
    return DELIMITER + encoded if leading_delimiter else encoded


def _decode(encoded: bytes, expected_version: int, minor: int) -> DecodeResult:
    raw_kept = encoded[:MAX_ENCODED_FRAME_BYTES]
    if len(encoded) > MAX_ENCODED_FRAME_BYTES:
        return FrameError(
            ErrorCode.OVERSIZE,
            f"frame of {len(encoded)} encoded bytes exceeds {MAX_ENCODED_FRAME_BYTES}",
            raw_kept,
        )
    try:
        raw = cobs_decode(encoded)
    except InputError as exc:
        return FrameError(ErrorCode.BAD_COBS, str(exc), raw_kept)
    if len(raw) < HEADER_BYTES + CRC_BYTES:
        return FrameError(
            ErrorCode.TOO_SHORT,
            f"frame of {len(raw)} bytes is shorter than header + CRC "
            f"({HEADER_BYTES + CRC_BYTES} bytes)",
            raw_kept,
        )
    body = raw[:-CRC_BYTES]
    (crc_rx,) = _CRC.unpack(raw[-CRC_BYTES:])
    crc = crc16_ccitt_false(body)
    if crc != crc_rx:
        return FrameError(
            ErrorCode.BAD_CRC, f"CRC 0x{crc_rx:04X} received, 0x{crc:04X} computed", raw_kept
        )
    version, msg_type, seq = _HEADER.unpack(body[:HEADER_BYTES])
    payload = body[HEADER_BYTES:]

    def err(code: ErrorCode, reason: str, detail: int = 0) -> FrameError:
        return FrameError(code, reason, raw_kept, version, msg_type, seq, detail)

    if version != expected_version:
        return err(
            ErrorCode.WRONG_VERSION,
            f"frame of protocol version {version}, expected version {expected_version}",
            version,
        )
    cls = MESSAGE_CLASSES.get(msg_type)
    if cls is None:
        return err(ErrorCode.UNKNOWN_TYPE, f"unknown message type 0x{msg_type:02X}", msg_type)
    lengths = cls.PAYLOAD_LAYOUTS[: minor + 1]
    if len(payload) not in lengths:
        expected = " or ".join(str(n) for n in sorted(set(lengths)))
        return err(
            ErrorCode.WRONG_LENGTH,
            f"{cls.__name__} payload of {len(payload)} bytes, expected {expected}",
            len(payload),
        )
    try:
        message = cls.from_payload(payload)
    except InputError as exc:
        return err(ErrorCode.VALUE_OUT_OF_RANGE, str(exc),
                   exc.value if isinstance(exc, FieldValueError) else 0)
    return Packet(seq, message, version)


def decode_frame(encoded: bytes, *, expected_version: int = PROTOCOL_VERSION,
                 minor: int = PROTOCOL_MINOR) -> Packet:
    """Decode one COBS-encoded frame (without its 0x00 delimiter).

    Checks in this order: size, COBS, minimum length, CRC, version, type,
    payload length, field values.

    Parameters
    ----------
    encoded : bytes
        The frame as received, delimiter stripped.
    expected_version : int
        Protocol (major) version the receiver speaks.
    minor : int
        Newest minor version the receiver speaks: payloads of the layouts of
        minor versions up to it are accepted.

    Returns
    -------
    Packet
        The header fields and the message.

    Raises
    ------
    FrameDecodeError
        Naming the first check that failed; its ``error`` is the :class:`FrameError`.
    """
    result = _decode(bytes(encoded), expected_version, minor)
    if isinstance(result, FrameError):
        raise FrameDecodeError(result)
    return result


class FrameDecoder:
    """Streaming decoder: feed it byte chunks of any size, get packets and typed errors.

    Frames split across chunks, several frames per chunk, empty frames
    (repeated delimiters) and garbage between frames are all handled; no
    exception escapes :meth:`feed`.  A run of more than
    ``MAX_ENCODED_FRAME_BYTES`` bytes without a delimiter gives one OVERSIZE
    error and is skipped up to the next delimiter.

    Parameters
    ----------
    expected_version : int
        Protocol (major) version the receiver speaks.
    minor : int
        Newest minor version the receiver speaks (see :func:`decode_frame`).
    """

    def __init__(self, expected_version: int = PROTOCOL_VERSION,
                 minor: int = PROTOCOL_MINOR) -> None:
        self.expected_version = expected_version
        self.minor = minor
        self._buf = bytearray()
        self._skipping = False

    @property
    def pending_bytes(self) -> int:
        """Bytes of an unfinished frame held (a truncated frame shows here)."""
        return len(self._buf)

    def reset(self) -> None:
        """Drop any partial frame."""
        self._buf.clear()
        self._skipping = False

    def feed(self, data: bytes | bytearray | memoryview) -> list[DecodeResult]:
        """Consume ``data`` and return what it completed, in order.

        Parameters
        ----------
        data : bytes-like
            The next bytes of the stream.

        Returns
        -------
        list of Packet or FrameError
            One entry per completed non-empty frame.
        """
        out: list[DecodeResult] = []
        chunk = bytes(data)
        start = 0
        n = len(chunk)
        while start <= n:
            end = chunk.find(0, start)
            piece = chunk[start:] if end < 0 else chunk[start:end]
            self._append(piece, out)
            if end < 0:
                break
            if self._skipping:
                self._skipping = False
            elif self._buf:
                out.append(_decode(bytes(self._buf), self.expected_version, self.minor))
            self._buf.clear()
            start = end + 1
        return out

    def _append(self, piece: bytes, out: list[DecodeResult]) -> None:
        if self._skipping or not piece:
            return
        if len(self._buf) + len(piece) > MAX_ENCODED_FRAME_BYTES:
            kept = bytes(self._buf + piece)[:MAX_ENCODED_FRAME_BYTES]
            out.append(
                FrameError(
                    ErrorCode.OVERSIZE,
                    f"more than {MAX_ENCODED_FRAME_BYTES} bytes without a frame delimiter",
                    kept,
                )
            )
            self._buf.clear()
            self._skipping = True
            return
        self._buf += piece
