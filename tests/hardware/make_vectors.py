"""Write ``docs/protocol-vectors.json`` from the codec (a maintainer's tool, not a test).

Run ``python3 tests/hardware/make_vectors.py`` only when the protocol
changes on purpose (and bump PROTOCOL_VERSION or PROTOCOL_MINOR then, by the
rules of docs/protocol.md §12): the file is the frozen reference that
``test_vectors.py`` and the firmware's host tests check against.  A minor
version only adds vectors: the frames of older minors stay byte-identical.
"""

from __future__ import annotations

import dataclasses
import json
import struct
from pathlib import Path
from typing import Any

from relaxgrip.hardware.protocol import codec as c

OUT = Path(__file__).resolve().parents[2] / "docs" / "protocol-vectors.json"
I32_MIN, I32_MAX = -(1 << 31), (1 << 31) - 1


def fields(msg: c.Message) -> dict[str, Any]:
    out = {}
    for f in dataclasses.fields(msg):
        v = getattr(msg, f.name)
        out[f.name] = list(v) if isinstance(v, tuple) else v
    return out


def layout_minor(msg: c.Message) -> int:
    """The oldest minor version whose receiver decodes ``msg`` (its payload layout's)."""
    return type(msg).PAYLOAD_LAYOUTS.index(len(msg.payload()))


def valid(name: str, msg: c.Message, seq: int) -> dict[str, Any]:
    return {
        "name": name,
        "type": type(msg).__name__,
        "type_id": int(msg.TYPE),
        "seq": seq,
        "minor": layout_minor(msg),
        "fields": {k: v for k, v in fields(msg).items() if v is not None},
        "frame": c.encode_frame(msg, seq).hex(),
    }


def raw_frame(version: int, msg_type: int, seq: int, payload: bytes) -> bytes:
    body = struct.pack("<BBH", version, msg_type, seq) + payload
    return c.cobs_encode(body + struct.pack("<H", c.crc16_ccitt_false(body))) + b"\x00"


def main() -> None:
    V = [
        valid("hello", c.Hello(), 0),
        valid("hello, last seq before wrap", c.Hello(), 0xFFFF),
        valid("velocity 12.345 mm/s", c.SetMotorVelocity(12_345), 1),
        valid("velocity -20 mm/s (opening)", c.SetMotorVelocity(-20_000), 2),
        valid("velocity zero (COBS of zeros)", c.SetMotorVelocity(0), 3),
        valid("velocity i32 min", c.SetMotorVelocity(I32_MIN), 4),
        valid("velocity i32 max", c.SetMotorVelocity(I32_MAX), 5),
        valid("heater duty 0 and 1.0", c.SetHeaterDuty((0, 10_000)), 6),
        valid("heater duty 0.5 and 0.25", c.SetHeaterDuty((5_000, 2_500)), 7),
        valid("heater duty above full scale (MCU clamps)", c.SetHeaterDuty((65_535, 1)), 8),
        valid("enable", c.SetEnable(True), 9),
        valid("disable", c.SetEnable(False), 10),
        valid("watchdog 200 ms (default)", c.SetWatchdog(200), 11),
        valid("watchdog 20 ms (minimum)", c.SetWatchdog(20), 12),
        valid("watchdog 2000 ms (maximum)", c.SetWatchdog(2_000), 13),
        valid("watchdog 0 ms (codec-valid, MCU rejects)", c.SetWatchdog(0), 14),
        valid("command 5 mm/s, duty 0.5 and 1.0", c.Command(5_000, (5_000, 10_000)), 42),
        valid("command all zero", c.Command(0, (0, 0)), 0),
        valid("command opening, heaters off", c.Command(-20_000, (0, 0)), 0x1234),
        valid("command extremes", c.Command(I32_MIN, (65_535, 65_535)), 0xFFFF),
        valid("get status", c.GetStatus(), 100),
        valid("hello naming minor 1", c.Hello(1), 0),
        valid("hello naming minor 255", c.Hello(255), 0xFFFF),
        valid("hello ack", c.HelloAck(0, 200, 20_000, "relaxgrip-fw 1.0"), 0),
        valid("hello ack, empty firmware id", c.HelloAck(0xFFFF, 20, 1, ""), 1),
        valid("hello ack minor 1, load cell",
              c.HelloAck(0, 200, 20_000, "relaxgrip-fw 1.1", 1, 0x01, 10_000), 0),
        valid("hello ack minor 1, no load cell, duty limit 0.6",
              c.HelloAck(3, 200, 20_000, "relaxgrip-fw 1.1", 1, 0x00, 6_000), 1),
        valid("hello ack minor 1, extremes",
              c.HelloAck(0xFFFF, 0xFFFF, I32_MAX, "0123456789abcdef", 0xFF, 0xFF, 0xFFFF), 2),
        valid(
            "status, enabled, gripping",
            c.Status(42, 1_234_567, 31_250, 5_000, (5_000, 10_000), 0, 0x01, 0, 0),
            17,
        ),
        valid(
            "status after watchdog trip (unsolicited)",
            c.Status(42, 1_434_567, 32_250, 0, (0, 0), 0x0001, 0x02, 3, 1),
            18,
        ),
        valid("status all zero", c.Status(0, 0, 0, 0, (0, 0), 0, 0, 0, 0), 0),
        valid(
            "status extremes",
            c.Status(
                0xFFFF,
                0xFFFF_FFFF,
                I32_MIN,
                I32_MAX,
                (65_535, 65_535),
                0xFFFF,
                0xFF,
                0xFFFF,
                0xFFFF,
            ),
            0xFFFF,
        ),
    ]
    V += [
        valid(
            "status minor 1, load cell reading",
            c.Status(42, 1_234_567, 31_250, 5_000, (5_000, 10_000), 0, 0x05, 0, 0,
                     548_123, 1_230_001, 77),
            19,
        ),
        valid(
            "status minor 1, no conversion yet",
            c.Status(1, 1_000, 0, 0, (0, 0), 0x0002, 0x00, 0, 0, 0, 0, 0),
            20,
        ),
        valid(
            "status minor 1, negative 24-bit extreme",
            c.Status(7, 0xFFFF_FFFF, I32_MIN, I32_MAX, (65_535, 65_535), 0xFFFF, 0xFF,
                     0xFFFF, 0xFFFF, -(1 << 23), 0xFFFF_FFFF, 0xFFFF),
            21,
        ),
    ]
    for code in c.ErrorCode:
        known = code not in (
            c.ErrorCode.BAD_COBS,
            c.ErrorCode.BAD_CRC,
            c.ErrorCode.TOO_SHORT,
            c.ErrorCode.OVERSIZE,
        )
        V.append(
            valid(
                f"error reply {code.name}",
                c.ErrorReply(9 if known else 0, int(code), 0x06 if known else 0, int(code) * 3),
                200 + int(code),
            )
        )
    good = c.encode_frame(c.Command(5_000, (5_000, 10_000)), 42)
    bad_crc = bytearray(c.cobs_decode(good[:-1]))
    bad_crc[-1] ^= 0x01
    invalid = [
        {
            "name": "bad CRC (last CRC byte flipped)",
            "frame": (c.cobs_encode(bytes(bad_crc)) + b"\x00").hex(),
            "error": "BAD_CRC",
        },
        {
            "name": "bad COBS (code byte runs past the frame end)",
            "frame": "0511223300",
            "error": "BAD_COBS",
        },
        {
            "name": "too short (3 bytes: no room for header and CRC)",
            "frame": (c.cobs_encode(b"\x01\x01\x00") + b"\x00").hex(),
            "error": "TOO_SHORT",
        },
        {
            "name": "wrong version (a version-2 Hello)",
            "frame": raw_frame(2, 0x01, 0, b"").hex(),
            "error": "WRONG_VERSION",
            "version": 2,
            "type_id": 0x01,
            "seq": 0,
        },
        {
            "name": "unknown type 0x42",
            "frame": raw_frame(1, 0x42, 5, b"\x01\x02").hex(),
            "error": "UNKNOWN_TYPE",
            "version": 1,
            "type_id": 0x42,
            "seq": 5,
        },
        {
            "name": "wrong length (Command with 7 payload bytes)",
            "frame": raw_frame(1, 0x06, 6, bytes(7)).hex(),
            "error": "WRONG_LENGTH",
            "version": 1,
            "type_id": 0x06,
            "seq": 6,
        },
        {
            "name": "value out of range (SetEnable 2)",
            "frame": raw_frame(1, 0x04, 7, b"\x02").hex(),
            "error": "VALUE_OUT_OF_RANGE",
            "version": 1,
            "type_id": 0x04,
            "seq": 7,
        },
        {
            "name": "value out of range (HelloAck firmware id not ASCII)",
            "frame": raw_frame(1, 0x81, 8, struct.pack("<HHi16s", 0, 200, 20000, b"\xff")).hex(),
            "error": "VALUE_OUT_OF_RANGE",
            "version": 1,
            "type_id": 0x81,
            "seq": 8,
        },
        {
            "name": "wrong length (Status with 30 payload bytes: no minor has that layout)",
            "frame": raw_frame(1, 0x82, 9, bytes(30)).hex(),
            "error": "WRONG_LENGTH",
            "version": 1,
            "type_id": 0x82,
            "seq": 9,
        },
        {
            "name": "wrong length for a minor-0 receiver (a minor-1 Hello)",
            "frame": c.encode_frame(c.Hello(1), 10).hex(),
            "error": "WRONG_LENGTH",
            "receiver_minor": 0,
            "version": 1,
            "type_id": 0x01,
            "seq": 10,
        },
        {
            "name": "oversize (300 bytes without a delimiter)",
            "frame": (b"\x01" * 300 + b"\x00").hex(),
            "error": "OVERSIZE",
        },
    ]
    doc = {
        "description": "relaxgrip MCU protocol test vectors; see docs/protocol.md. "
        "'frame' is the exact wire bytes in hex, including the trailing 0x00 delimiter. "
        "Field values are the wire integers (velocity in um/s, duty in permyriad). "
        "'minor' is the oldest protocol minor version whose receiver decodes the frame "
        "(its payload layout's); an invalid frame's 'receiver_minor' (default: the file's "
        "protocol_minor) is the receiver that rejects it.",
        "protocol_version": c.PROTOCOL_VERSION,
        "protocol_minor": c.PROTOCOL_MINOR,
        "crc": {
            "name": "CRC-16/CCITT-FALSE",
            "poly": "0x1021",
            "init": "0xFFFF",
            "refin": False,
            "refout": False,
            "xorout": "0x0000",
            "check_input_ascii": "123456789",
            "check": "0x29B1",
        },
        "cobs": [
            {"decoded": d.hex(), "encoded": c.cobs_encode(d).hex()}
            for d in (
                b"",
                b"\x00",
                b"\x00\x00",
                b"\x11\x22\x00\x33",
                b"\x11\x22\x33\x44",
                b"\x11\x00\x00\x00",
                bytes(range(1, 255)),
                bytes(range(0, 255)),
                bytes(range(1, 256)),
            )
        ],
        "valid": V,
        "invalid": invalid,
    }
    OUT.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {OUT} ({len(V)} valid, {len(invalid)} invalid)")


if __name__ == "__main__":
    main()
