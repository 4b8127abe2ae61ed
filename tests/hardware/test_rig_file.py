"""Rig files: the shipped examples load, every bad field is one line naming it."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import pytest

from relaxgrip.errors import InputError
from relaxgrip.hardware.rig_file import load_rig, parse_rig
from relaxgrip.rig import RigGeometry

DOCS = Path(__file__).resolve().parents[2] / "docs"


def _example() -> dict[str, Any]:
    return tomllib.loads((DOCS / "rig-example.toml").read_text(encoding="utf-8"))


def test_examples_load_and_match_the_twin_geometry() -> None:
    real = load_rig(DOCS / "rig-example.toml")
    emu = load_rig(DOCS / "rig-emulator.toml")
    # A rig reads its fingers bent as they are, and so does the emulator, whose twin draws the bend.
    assert real.geometry == RigGeometry()
    assert real.geometry.ir_follow_bend
    assert emu.geometry == RigGeometry()
    assert (real.rgb.source, real.ir.source) == ("opencv", "uvc")
    assert (emu.rgb.source, emu.ir.source) == ("emulator", "emulator")
    assert real.ir.temp_c(30000) == pytest.approx(26.85)  # centi-kelvin
    assert real.serial.reply_timeout_s == pytest.approx(0.1)
    assert real.serial.boot_wait_s == pytest.approx(2.5)
    assert emu.emulator is not None
    assert emu.emulator.socket.endswith(".sock")
    assert real.rgb.exposure == -6
    assert emu.rgb.exposure is None
    softer = _example()
    softer["marker"]["max_travel_mm"] = 35.0
    assert parse_rig(softer, "x.toml").geometry.marker.max_travel_m == pytest.approx(0.035)


@pytest.mark.parametrize(("table", "key", "value", "message"), [
    ("serial", "baud", "fast", r"\[serial\] baud must be an integer"),
    ("serial", "port", "", r"\[serial\] port must be a non-empty string"),
    ("serial", "boot_wait_ms", -1, r"\[serial\] boot_wait_ms must be >= 0"),
    ("rgb", "fps", -30, r"\[rgb\] fps must be > 0"),
    ("rgb", "source", "webcam", r"\[rgb\] source must be one of opencv, emulator"),
    ("rgb", "fx_px", 0, r"\[rgb\] fx_px must be > 0"),
    ("rgb", "dist", [0.1, 0.2], r"\[rgb\] dist needs 0, 4, 5, 8, 12 or 14"),
    ("rgb", "dist", [1e308, 0, 0, 0], r"\[rgb\] distortion coefficients must be finite and "
                                     r"within ±1000, got 1e\+308,0,0,0"),
    ("rgb", "dist", [0, 0, 1000, 0], r"\[rgb\] distortion 0,0,1000,0 undistorts the image's "
                                     r"edges to no pinhole view"),
    ("rgb", "fx_px", 1e9, r"\[rgb\] fx_px must be 1 to 1e\+06 pixels"),
    ("rgb", "position_mm", [1, 2], r"\[rgb\] position_mm needs 3 numbers"),
    ("rgb", "stall_ms", 10, r"\[rgb\] stall_ms must exceed one frame period"),
    ("ir", "scale", 0, r"\[ir\] scale must not be 0"),
    ("ir", "width_px", 0, r"\[ir\] width_px must be in 1..16384"),
    ("ir", "follow_bend", "yes", r"\[ir\] follow_bend must be true or false, got 'yes'"),
    ("marker", "dictionary", "4X4_9", r"\[marker\] dictionary is not an OpenCV ArUco"),
    ("marker", "id", 60, r"\[marker\] id must be below 50"),
    ("marker", "id", -1, r"\[marker\] id must be >= 0, got -1$"),
    ("rig", "open_aperture_mm", 1e308, r"\[rig\] open_aperture_mm must be <= 1000, got 1e\+308"),
    ("rig", "open_aperture_mm", 1001, r"\[rig\] open_aperture_mm must be <= 1000"),
    ("marker", "size_mm", -1, r"\[marker\] size_mm must be > 0"),
    ("marker", "max_travel_mm", 0, r"\[marker\] max_travel_mm must be > 0"),
    ("finger", "beam_positions_mm", [200.0], r"\[finger\] beam_positions_mm must lie on"),
    ("finger", "length_mm", 1e308, r"\[finger\] length_mm must be <= 1000, got 1e\+308"),
    ("finger", "contact_mm", 120.0, r"\[finger\] contact_mm must be <= 110, got 120"),
    ("finger", "contact_mm", 0, r"\[finger\] contact_mm must be > 0"),
    ("limits", "heater_duty_limit", 1.5, r"\[limits\] heater_duty_limit must be <= 1"),
    ("limits", "max_temp_c", "hot", r"\[limits\] max_temp_c must be a number"),
    ("rgb", "fsp", 30, r"\[rgb\] has unknown key 'fsp'"),
])
def test_bad_field_is_one_line_naming_it(table: str, key: str, value: Any,
                                         message: str) -> None:
    data = _example()
    data[table][key] = value
    with pytest.raises(InputError, match=message) as info:
        parse_rig(data, "x.toml")
    assert "\n" not in str(info.value)
    assert str(info.value).startswith("x.toml: ")


def test_missing_tables_and_fields() -> None:
    data = _example()
    del data["serial"]
    with pytest.raises(InputError, match=r"table \[serial\] is missing"):
        parse_rig(data)
    data = _example()
    del data["marker"]["size_mm"]
    with pytest.raises(InputError, match=r"\[marker\] size_mm is missing"):
        parse_rig(data)
    data = _example()
    data["rgb"]["source"] = "emulator"
    del data["rgb"]["device"]
    with pytest.raises(InputError, match=r"table \[emulator\] \(its socket\) is missing"):
        parse_rig(data)
    data = _example()
    data["marker"]["position_mm"] = 150.0
    with pytest.raises(InputError, match=r"\[marker\] position_mm 150 is beyond"):
        parse_rig(data)


def test_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"rig file .* not found"):
        load_rig(tmp_path / "none.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[serial\nport = 1\n", encoding="utf-8")
    with pytest.raises(InputError, match="is not valid TOML"):
        load_rig(bad)
