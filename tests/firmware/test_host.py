"""The firmware's protocol core compiled for the host (gcc): the test vectors and a fuzz.

``firmware/src/rg_proto.c`` and ``rg_mcu.c`` are the code the MCU runs; here they are
built with the address and undefined-behaviour sanitizers, so that an out-of-bounds
access or an overflow fails the run, not only a wrong answer.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest

from relaxgrip.hardware.protocol import codec as c

ROOT = Path(__file__).resolve().parents[2]
FIRMWARE = ROOT / "firmware"
VECTORS = json.loads((ROOT / "docs" / "protocol-vectors.json").read_text(encoding="utf-8"))
SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all"]

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None,
                                reason="gcc is not installed: the firmware's host tests need it")


def _build(tmp: Path, name: str, sources: list[str]) -> Path:
    exe = tmp / name
    cmd = ["gcc", "-std=c99", "-O1", "-g", "-Wall", "-Wextra", "-Werror", "-Wconversion",
           *SANITIZE, f"-I{FIRMWARE / 'src'}", *(str(FIRMWARE / s) for s in sources),
           "-o", str(exe)]
    run = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert run.returncode == 0, run.stderr
    return exe


def _flat_fields(fields: dict[str, Any]) -> list[str]:
    out: list[str] = []
    for value in fields.values():
        if isinstance(value, str):
            out.append("h:" + (value.encode("ascii").hex() or ""))
        elif isinstance(value, list):
            out += [str(v) for v in value]
        elif isinstance(value, bool):
            out.append(str(int(value)))
        else:
            out.append(str(value))
    return out


def vector_lines() -> list[str]:
    """docs/protocol-vectors.json as the flat lines the C test reads."""
    crc = VECTORS["crc"]
    lines = [f"crc {crc['check_input_ascii']} {crc['check']}"]
    lines += [f"cobs {v['decoded'] or '-'} {v['encoded']}" for v in VECTORS["cobs"]]
    for i, v in enumerate(VECTORS["valid"]):
        fields = " ".join(_flat_fields(v["fields"]))
        lines.append(f"valid {i} {v['type_id']} {v['seq']} {v['minor']} {v['frame']} {fields}")
    for i, v in enumerate(VECTORS["invalid"]):
        header = "seq" in v
        code = int(c.ErrorCode[v["error"]])
        minor = v.get("receiver_minor", VECTORS["protocol_minor"])
        lines.append(f"invalid {i} {code} {minor} {int(header)} {v.get('version', 0)} "
                     f"{v.get('type_id', 0)} {v.get('seq', 0)} {v['frame']}")
    return lines


def test_every_vector_decodes_reencodes_or_is_rejected_with_its_error(tmp_path: Path) -> None:
    exe = _build(tmp_path, "test_vectors", ["test/test_vectors.c", "src/rg_proto.c"])
    lines = vector_lines()
    run = subprocess.run([str(exe)], input="\n".join(lines) + "\n", capture_output=True,
                         text=True, timeout=60)
    assert run.returncode == 0, run.stdout + run.stderr
    assert run.stdout.strip().splitlines()[-1] == f"ok {len(lines)}"
    assert len(VECTORS["valid"]) >= 40


def test_the_c_test_catches_a_wrong_vector(tmp_path: Path) -> None:
    """The checker can fail: a field changed, a byte of a frame flipped."""
    exe = _build(tmp_path, "test_vectors", ["test/test_vectors.c", "src/rg_proto.c"])
    line = next(x for x in vector_lines() if x.startswith("valid ") and " 6 42 " in x)
    wrong_field = line.rsplit(" ", 1)[0] + " 9999"
    parts = line.split(" ")
    frame = bytearray.fromhex(parts[5])
    frame[3] ^= 0x10
    wrong_frame = " ".join([*parts[:5], frame.hex(), *parts[6:]])
    for bad in (wrong_field, wrong_frame):
        run = subprocess.run([str(exe)], input=bad + "\n", capture_output=True, text=True,
                             timeout=60)
        assert run.returncode == 1
        assert "FAIL" in run.stdout


def test_fuzz_the_decoder_and_the_state_machine(tmp_path: Path) -> None:
    exe = _build(tmp_path, "fuzz_proto", ["test/fuzz_proto.c", "src/rg_proto.c",
                                          "src/rg_mcu.c"])
    run = subprocess.run([str(exe), "200000", "7"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    assert run.stdout.startswith("fuzzed 200000 inputs")
    assert "runtime error" not in run.stderr
