"""The codec against the frozen test vectors of docs/protocol-vectors.json, both ways."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from relaxgrip.hardware.protocol import codec as c

VECTORS = json.loads(
    (Path(__file__).resolve().parents[2] / "docs" / "protocol-vectors.json").read_text()
)


def build(vector: dict[str, Any]) -> c.Message:
    cls = c.MESSAGE_CLASSES[vector["type_id"]]
    assert cls.__name__ == vector["type"]
    kwargs: dict[str, Any] = {
        k: tuple(v) if isinstance(v, list) else v for k, v in vector["fields"].items()
    }
    return cls(**kwargs)


def test_header_of_the_file() -> None:
    assert VECTORS["protocol_version"] == c.PROTOCOL_VERSION
    assert VECTORS["protocol_minor"] == c.PROTOCOL_MINOR
    crc = VECTORS["crc"]
    check = c.crc16_ccitt_false(crc["check_input_ascii"].encode("ascii"))
    assert check == int(crc["check"], 16)


def test_every_message_type_has_vectors() -> None:
    assert {v["type_id"] for v in VECTORS["valid"]} == {int(t) for t in c.MsgType}
    assert {v["error"] for v in VECTORS["invalid"]} >= {
        "BAD_CRC",
        "BAD_COBS",
        "TOO_SHORT",
        "WRONG_VERSION",
        "UNKNOWN_TYPE",
        "WRONG_LENGTH",
        "VALUE_OUT_OF_RANGE",
        "OVERSIZE",
    }


@pytest.mark.parametrize("vector", VECTORS["cobs"], ids=lambda v: v["decoded"][:12] or "empty")
def test_cobs_vectors(vector: dict[str, str]) -> None:
    assert c.cobs_encode(bytes.fromhex(vector["decoded"])).hex() == vector["encoded"]
    assert c.cobs_decode(bytes.fromhex(vector["encoded"])).hex() == vector["decoded"]


def test_every_minor_layout_has_vectors() -> None:
    seen = {(v["type_id"], v["minor"]) for v in VECTORS["valid"]}
    wanted = {(int(cls.TYPE), minor) for cls in c.MESSAGE_CLASSES.values()
              for minor in range(len(cls.PAYLOAD_LAYOUTS))}
    assert seen == wanted


@pytest.mark.parametrize("vector", VECTORS["valid"], ids=lambda v: v["name"])
def test_valid_vector_both_ways(vector: dict[str, Any]) -> None:
    message = build(vector)
    frame = bytes.fromhex(vector["frame"])
    assert c.encode_frame(message, vector["seq"]) == frame
    assert c.decode_frame(frame[:-1]) == c.Packet(vector["seq"], message)
    assert c.FrameDecoder().feed(frame) == [c.Packet(vector["seq"], message)]
    # A receiver of the frame's own minor decodes it; an older one (if any) refuses it.
    minor = vector["minor"]
    assert c.decode_frame(frame[:-1], minor=minor) == c.Packet(vector["seq"], message)
    if minor > 0:
        (older,) = c.FrameDecoder(minor=minor - 1).feed(frame)
        assert isinstance(older, c.FrameError)
        assert older.code is c.ErrorCode.WRONG_LENGTH


@pytest.mark.parametrize("vector", VECTORS["invalid"], ids=lambda v: v["name"])
def test_invalid_vector(vector: dict[str, Any]) -> None:
    frame = bytes.fromhex(vector["frame"])
    minor = vector.get("receiver_minor", VECTORS["protocol_minor"])
    (result,) = c.FrameDecoder(minor=minor).feed(frame)
    assert isinstance(result, c.FrameError)
    assert result.code.name == vector["error"]
    if "seq" in vector:
        assert (result.version, result.msg_type, result.seq) == (
            vector["version"],
            vector["type_id"],
            vector["seq"],
        )
    else:
        assert result.seq is None
