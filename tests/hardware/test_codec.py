"""Codec layer: CRC, COBS, messages and single frames (pure, fixed bytes and properties)."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from relaxgrip.errors import InputError
from relaxgrip.hardware.protocol import codec as c
from relaxgrip.hardware.protocol.errors import FrameDecodeError

from .strategies import messages, packets


def crc16_bitwise(data: bytes) -> int:
    """Reference CRC-16/CCITT-FALSE, bit by bit, independent of binascii."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def test_crc_check_value() -> None:
    assert c.crc16_ccitt_false(b"123456789") == 0x29B1
    assert c.crc16_ccitt_false(b"") == 0xFFFF


@given(st.binary(max_size=300))
def test_crc_matches_bitwise_reference(data: bytes) -> None:
    assert c.crc16_ccitt_false(data) == crc16_bitwise(data)


# Examples from Cheshire & Baker's COBS as listed on the COBS Wikipedia page.
COBS_EXAMPLES = [
    (b"\x00", b"\x01\x01"),
    (b"\x00\x00", b"\x01\x01\x01"),
    (b"\x00\x11\x00", b"\x01\x02\x11\x01"),
    (b"\x11\x22\x00\x33", b"\x03\x11\x22\x02\x33"),
    (b"\x11\x22\x33\x44", b"\x05\x11\x22\x33\x44"),
    (b"\x11\x00\x00\x00", b"\x02\x11\x01\x01\x01"),
    (bytes(range(1, 255)), b"\xff" + bytes(range(1, 255))),
    (bytes(range(0, 255)), b"\x01\xff" + bytes(range(1, 255))),
    (bytes(range(1, 256)), b"\xff" + bytes(range(1, 255)) + b"\x02\xff"),
    (bytes(range(2, 256)) + b"\x00", b"\xff" + bytes(range(2, 256)) + b"\x01\x01"),
    (bytes(range(3, 256)) + b"\x00\x01", b"\xfe" + bytes(range(3, 256)) + b"\x02\x01"),
]


@pytest.mark.parametrize(("decoded", "encoded"), COBS_EXAMPLES)
def test_cobs_known_examples(decoded: bytes, encoded: bytes) -> None:
    assert c.cobs_encode(decoded) == encoded
    assert c.cobs_decode(encoded) == decoded


@given(st.binary(max_size=1000))
def test_cobs_round_trip_and_no_zero(data: bytes) -> None:
    enc = c.cobs_encode(data)
    assert 0 not in enc
    assert len(enc) <= len(data) + 1 + len(data) // 254
    assert c.cobs_decode(enc) == data


@pytest.mark.parametrize(
    ("encoded", "words"),
    [(b"", "empty"), (b"\x05\x11\x22", "past the frame end"), (b"\x03\x11\x00", "zero byte")],
)
def test_cobs_decode_rejects_bad_input(encoded: bytes, words: str) -> None:
    with pytest.raises(InputError, match=words):
        c.cobs_decode(encoded)


@given(packets)
def test_frame_round_trip_every_message(packet: c.Packet) -> None:
    frame = c.encode_frame(packet.message, packet.seq)
    assert frame.endswith(b"\x00")
    assert 0 not in frame[:-1]
    assert len(frame) - 1 <= c.MAX_ENCODED_FRAME_BYTES
    assert c.decode_frame(frame[:-1]) == packet


@given(messages)
def test_frame_layout(message: c.Message) -> None:
    raw = c.cobs_decode(c.encode_frame(message, 0x1234)[:-1])
    assert raw[0] == c.PROTOCOL_VERSION
    assert raw[1] == int(message.TYPE)
    assert raw[2:4] == b"\x34\x12"  # little-endian seq
    assert len(raw) == 4 + len(message.payload()) + 2
    assert len(message.payload()) in type(message).PAYLOAD_LAYOUTS
    assert struct.unpack("<H", raw[-2:])[0] == crc16_bitwise(raw[:-2])


def test_message_type_ids_are_unique_and_directional() -> None:
    ids = [int(t) for t in c.MsgType]
    assert len(set(ids)) == len(ids)
    assert set(c.MESSAGE_CLASSES) == set(ids)
    assert all(i == c.MESSAGE_CLASSES[i].TYPE for i in ids)


@pytest.mark.parametrize(
    ("build", "words"),
    [
        (lambda: c.SetMotorVelocity(1 << 31), "velocity_um_s 2147483648 is outside"),
        (lambda: c.SetMotorVelocity(1.5), "must be an integer"),  # type: ignore[arg-type]
        (lambda: c.SetHeaterDuty((1, 2, 3)), "needs 2 values"),  # type: ignore[arg-type]
        (lambda: c.SetHeaterDuty((-1, 0)), r"heater_duty_permyriad\[0\] -1 is outside"),
        (lambda: c.SetEnable(1), "must be a bool"),  # type: ignore[arg-type]
        (lambda: c.SetWatchdog(70_000), "period_ms 70000 is outside"),
        (lambda: c.HelloAck(0, 200, 1, "x" * 17), "at most 16"),
        (lambda: c.HelloAck(0, 200, 1, "fw\x00"), "printable ASCII"),
        (lambda: c.Status(0, -1, 0, 0, (0, 0), 0, 0), "mcu_time_us -1 is outside"),
        (lambda: c.ErrorReply(0, 256), "code 256 is outside"),
        (lambda: c.Command.from_si(1.0, (0.5, 1.5)), r"heater_duty\[1\] 1.5 is outside 0-1"),
        (
            lambda: c.Command.from_si(float("nan"), (0.0, 0.0)),
            "velocity_mm_s must be a finite number",
        ),
        (lambda: c.encode_frame(c.Hello(), 65_536), "seq 65536 is outside"),
    ],
)
def test_bad_values_give_one_line_errors(build, words: str) -> None:
    with pytest.raises(InputError, match=words) as info:
        build()
    assert "\n" not in str(info.value)


def test_si_conversions() -> None:
    cmd = c.Command.from_si(-12.3456, (0.5, 0.00004))
    assert cmd == c.Command(-12_346, (5_000, 0))
    assert cmd.velocity_mm_s == pytest.approx(-12.346)
    assert cmd.heater_duty == (0.5, 0.0)
    st_ = c.Status(1, 2, 31_250, -5_000, (10_000, 2_500), 0b101, 1)
    assert st_.position_mm == 31.25
    assert st_.velocity_mm_s == -5.0
    assert st_.heater_duty == (1.0, 0.25)
    assert st_.enabled
    assert not st_.unsolicited
    assert st_.faults == frozenset({"WATCHDOG", "VELOCITY_CLAMPED"})
    assert c.Status(0, 0, 0, 0, (0, 0), 1 << 12, 0).faults == frozenset({"BIT12"})
    assert c.ErrorReply(0, 200).code_name == "CODE_200"


def test_decode_frame_raises_typed_one_line_error() -> None:
    frame = bytearray(c.encode_frame(c.Command(1, (2, 3)), 4)[:-1])
    frame[3] ^= 0x40
    with pytest.raises(FrameDecodeError, match=r"^BAD_CRC: CRC 0x") as info:
        c.decode_frame(bytes(frame))
    assert info.value.error.code is c.ErrorCode.BAD_CRC
    assert "\n" not in str(info.value)


def test_wrong_version_keeps_header_fields() -> None:
    frame = c.encode_frame(c.Hello(), 77, version=9)[:-1]
    with pytest.raises(FrameDecodeError) as info:
        c.decode_frame(frame)
    err = info.value.error
    assert (err.code, err.version, err.msg_type, err.seq, err.detail) == (
        c.ErrorCode.WRONG_VERSION,
        9,
        0x01,
        77,
        9,
    )
    assert c.decode_frame(frame, expected_version=9) == c.Packet(77, c.Hello(), 9)


def test_an_undecodable_value_is_the_error_s_detail() -> None:
    """docs/protocol.md §4: VALUE_OUT_OF_RANGE carries the offending value."""
    vectors = json.loads((Path(__file__).resolve().parents[2] / "docs" / "protocol-vectors.json")
                         .read_text(encoding="utf-8"))
    (vector,) = [v for v in vectors["invalid"] if v["name"] == "value out of range (SetEnable 2)"]
    with pytest.raises(FrameDecodeError) as info:
        c.decode_frame(bytes.fromhex(vector["frame"])[:-1])
    err = info.value.error
    assert (err.code, err.msg_type, err.seq, err.detail) == (
        c.ErrorCode.VALUE_OUT_OF_RANGE, 0x04, 7, 2)


def test_leading_delimiter() -> None:
    assert c.encode_frame(c.Hello(), 0, leading_delimiter=True) == b"\x00" + c.encode_frame(
        c.Hello(), 0
    )
