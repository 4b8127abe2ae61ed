"""Rig files: the shipped examples load, every bad field is one line naming it."""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

import pytest

from relaxgrip.errors import InputError
from relaxgrip.hardware.rig_file import RIG_SCHEMA, load_rig, parse_rig
from relaxgrip.physics.beam import FingerParams, local_stiffness_n_per_m
from relaxgrip.rig import RigGeometry
from relaxgrip.twin import TwinConfig

DOCS = Path(__file__).resolve().parents[2] / "docs"
OURS = DOCS / "rigs" / "relaxgrip.toml"
LAB = DOCS / "rigs" / "lab-125mm.toml"

#: Keys of a real rig that are settings, not properties of the gripper: they may be left out.
SETTINGS = {("rig", "name"), ("serial", "baud"), ("serial", "reply_timeout_ms"),
            ("serial", "boot_wait_ms"), ("rgb", "fps"), ("rgb", "exposure"),
            ("rgb", "stall_ms"), ("ir", "fps"), ("ir", "stall_ms"), ("ir", "follow_bend"),
            ("marker", "max_travel_mm"), ("finger", "contact_mm"),
            *(("limits", key) for key in ("max_target_n", "max_force_n", "min_setpoint_c",
                                          "max_setpoint_c", "max_temp_c", "heater_duty_limit",
                                          "max_motor_speed_mm_s", "stroke_mm"))}


def _load(path: Path) -> dict[str, Any]:
    return tomllib.loads(path.read_text(encoding="utf-8"))


def _example() -> dict[str, Any]:
    return _load(OURS)


def test_examples_load_and_ours_is_the_twins_gripper() -> None:
    real = load_rig(OURS)
    emu = load_rig(DOCS / "rig-emulator.toml")
    twin = TwinConfig()
    # A rig reads its fingers bent as they are, and so does the emulator, whose twin draws the bend.
    assert real.geometry == RigGeometry() == twin.rig
    assert real.geometry.ir_follow_bend
    assert emu.geometry == RigGeometry()
    assert (real.schema, emu.schema) == (RIG_SCHEMA, RIG_SCHEMA)
    assert (real.stiffness, real.relax, real.heat, real.motor) == (
        twin.finger, twin.relax, twin.heat, twin.motor)
    assert real.force_ball == twin.force_ball
    assert real.force_ref.sensor == twin.force_sensor
    assert real.from_twin == ()
    # The emulator rig leaves the gripper to the twin, and says what it left.
    assert {"finger stiffness", "motor", "heaters", "force_ball"} <= set(emu.from_twin)
    assert (real.rgb.source, real.ir.source) == ("opencv", "uvc")
    assert (emu.rgb.source, emu.ir.source) == ("emulator", "emulator")
    assert not real.emulated
    assert emu.emulated
    assert real.ir.temp_c(30000) == pytest.approx(26.85)  # centi-kelvin
    assert real.serial.reply_timeout_s == pytest.approx(0.1)
    assert real.serial.boot_wait_s == pytest.approx(2.5)
    assert emu.emulator is not None
    assert emu.emulator.socket.endswith(".sock")
    assert real.rgb.exposure == -6
    assert emu.rgb.exposure is None
    assert (real.force_ref.source, real.force_ref.port) == ("serial", "/dev/ttyUSB0")
    softer = _example()
    softer["marker"]["max_travel_mm"] = 35.0
    assert parse_rig(softer, "x.toml").geometry.marker.max_travel_m == pytest.approx(0.035)


def test_the_second_rig_differs_and_its_measured_k80_is_its_finger() -> None:
    ours, lab = load_rig(OURS), load_rig(LAB)
    for name in ("finger", "marker", "rgb", "ir"):
        assert getattr(lab.geometry, name) != getattr(ours.geometry, name), name
    assert lab.finger.length_m != ours.finger.length_m
    assert lab.marker.marker_id != ours.marker.marker_id
    assert lab.marker.size_m != ours.marker.size_m
    assert lab.marker.position_m != ours.marker.position_m
    assert lab.rgb.mount.intrinsics != ours.rgb.mount.intrinsics
    assert lab.rgb.mount.position_m != ours.rgb.mount.position_m
    assert lab.stiffness.smp != ours.stiffness.smp
    assert lab.relax != ours.relax
    assert lab.force_ref.source == "mcu"
    # The stiffness was given as measured k80 = F / z(80 mm) at 5 N, 27 and 60 °C: the
    # derived beam model gives those back.
    data = _load(LAB)["finger"]
    for k80, temp in zip(data["k80_n_per_mm"], data["k80_temps_c"], strict=True):
        assert local_stiffness_n_per_m(5.0, temp, lab.stiffness) / 1e3 == pytest.approx(
            k80, rel=1e-9)


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
    ("rig", "open_aperture_mm", 1e308, r"\[rig\] open_aperture_mm must be 5 to 1000 mm for a "
                                       r"gripper's opening, got 1e\+308"),
    ("rig", "open_aperture_mm", 1001, r"\[rig\] open_aperture_mm must be 5 to 1000 mm"),
    ("rig", "schema", "2", r"\[rig\] schema must be an integer, got '2'"),
    ("rig", "schema", 3, r"\[rig\] schema 3 is not a version this relaxgrip reads \(1 or 2\)"),
    ("marker", "size_mm", -1, r"\[marker\] size_mm must be 2 to 200 mm for a marker's side"),
    ("marker", "max_travel_mm", 0, r"\[marker\] max_travel_mm must be > 0"),
    ("finger", "beam_positions_mm", [200.0], r"\[finger\] beam_positions_mm must lie on"),
    ("finger", "length_mm", 1e308, r"\[finger\] length_mm must be 20 to 1000 mm for a finger"),
    ("finger", "contact_mm", 120.0, r"\[finger\] contact_mm must be <= 110, got 120"),
    ("finger", "contact_mm", 0, r"\[finger\] contact_mm must be > 0"),
    ("finger", "ei_skeleton_base_n_m2", "stiff", r"\[finger\] ei_skeleton_base_n_m2 must be a "
                                                 r"number, got 'stiff'"),
    ("finger", "skeleton_taper", 1.0, r"\[finger\] skeleton_taper must be <= 0.99"),
    ("finger", "k80_n_per_mm", [1.4, 0.9], r"\[finger\] k80_n_per_mm and ei_skeleton_base_n_m2 "
                                           r"/ smp_ratio_base describe the same stiffness"),
    ("finger", "material", "smp.json", r"\[finger\] material and \[finger.smp\] both describe"),
    ("motor", "stroke_mm", 160.0, r"\[motor\] stroke_mm 160 exceeds \[rig\] open_aperture_mm "
                                  r"150: the fingers would cross"),
    ("motor", "lag_ms", 0, r"\[motor\] lag_ms must be > 0"),
    ("heaters", "resistance_ohm", -20, r"\[heaters\] resistance_ohm must be > 0"),
    ("force_ref", "source", "twin", r"\[force_ref\] source 'twin' reads the twin's force ball: "
                                    r"only an emulator rig"),
    ("force_ref", "source", "gauge", r"\[force_ref\] source must be one of mcu, serial, twin"),
    ("force_ref", "scale", 0, r"\[force_ref\] scale must not be 0"),
    ("force_ball", "friction", 0, r"\[force_ball\] friction must be > 0"),
    ("limits", "heater_duty_limit", 1.5, r"\[limits\] heater_duty_limit must be <= 1"),
    ("limits", "max_temp_c", "hot", r"\[limits\] max_temp_c must be a number"),
    ("rgb", "fsp", 30, r"\[rgb\] has unknown key 'fsp'"),
    ("heaters", "supply_volts", 12, r"\[heaters\] has unknown key 'supply_volts'"),
])
def test_bad_field_is_one_line_naming_it(table: str, key: str, value: Any,
                                         message: str) -> None:
    data = _example()
    data[table][key] = value
    with pytest.raises(InputError, match=message) as info:
        parse_rig(data, "x.toml")
    assert "\n" not in str(info.value)
    assert str(info.value).startswith("x.toml: ")


@pytest.mark.parametrize(("table", "key", "value", "message"), [
    ("finger", "length_mm", 0.11, r"\[finger\] length_mm is 0.11 mm, not a length a finger has "
                                  r"\(20 to 1000 mm\): written in metres\? 0.11 metres is "
                                  r"110 mm$"),
    ("finger", "thickness_mm", 0.012, r"\[finger\] thickness_mm .* written in metres\? 0.012 "
                                      r"metres is 12 mm"),
    ("finger", "height_mm", 200.1, r"\[finger\] height_mm must be 2 to 200 mm for a finger's "
                                   r"height, got 200.1$"),
    ("marker", "position_mm", 0.06, r"\[marker\] position_mm .* written in metres\? 0.06 metres "
                                    r"is 60 mm"),
    ("marker", "size_mm", 12000.0, r"\[marker\] size_mm .* written in micrometres\?"),
    ("finger", "beam_positions_mm", [0.011, 0.033, 0.055, 0.077, 0.099],
     r"\[finger\] beam_positions_mm all lie within 1 mm of the root .* in mm they are 11, 33"),
    ("rgb", "position_mm", [-0.025, 0.0, 0.0], r"\[rgb\] position_mm is within 1 mm of the "
                                               r"origin .* in mm it is -25, 0, 0"),
    ("motor", "encoder_mm_per_count", 5.0, r"\[motor\] encoder_mm_per_count .* written in "
                                           r"micrometres\? 5 micrometres is 0.005 mm"),
    ("motor", "max_speed_mm_s", 0.02, r"\[motor\] max_speed_mm_s is 0.02 mm/s.* written in "
                                      r"metres\? 0.02 metres is 20 mm/s"),
    ("force_ball", "diameter_mm", 0.06, r"\[force_ball\] diameter_mm .* written in metres\?"),
])
def test_a_length_in_the_wrong_unit_is_named(table: str, key: str, value: Any,
                                             message: str) -> None:
    data = _example()
    data[table][key] = value
    with pytest.raises(InputError, match=message) as info:
        parse_rig(data, "x.toml")
    assert "\n" not in str(info.value)


def _keys(data: dict[str, Any], prefix: tuple[str, ...] = ()
          ) -> list[tuple[tuple[str, ...], str]]:
    out = []
    for key, value in data.items():
        if isinstance(value, dict):
            out += _keys(value, (*prefix, key))
        elif prefix:
            out.append((prefix, key))
    return out


@pytest.mark.parametrize("rig", [OURS, LAB], ids=["ours", "lab"])
def test_a_real_rig_lacking_any_property_of_its_gripper_names_it_and_its_unit(rig: Path
                                                                              ) -> None:
    full = _load(rig)
    for tables, key in _keys(full):
        data = copy.deepcopy(full)
        holder = data
        for name in tables:
            holder = holder[name]
        del holder[key]
        where = ".".join(tables)
        if (where, key) in SETTINGS:
            parse_rig(data, "x.toml")  # a setting: its default serves
            continue
        if (where, key) == ("rig", "schema"):
            message = r"a schema 1 rig file \(no \[rig\] schema\)"
        elif where == "finger" and key.startswith("k80_"):
            message = rf"\[finger\] lacks {key} \(.+\) beside k80_"
        elif (where, key) == ("finger", "k80_n_per_mm"):
            message = r"\[finger\] lacks ei_skeleton_base_n_m2"
        else:
            message = rf"\[{where}\] lacks {key} \(.+\)"
        with pytest.raises(InputError, match=message) as info:
            parse_rig(data, "x.toml")
        assert "\n" not in str(info.value), (where, key)


def test_missing_tables_and_fields() -> None:
    data = _example()
    del data["serial"]
    with pytest.raises(InputError, match=r"table \[serial\] is missing"):
        parse_rig(data)
    data = _example()
    del data["finger"]["ei_skeleton_base_n_m2"]
    with pytest.raises(InputError, match=r"^rig.toml: \[finger\] lacks ei_skeleton_base_n_m2 "
                                         r"\(N m\^2\); or give the measured k80_n_per_mm"):
        parse_rig(data, "rig.toml")
    for table in ("motor", "heaters", "force_ref", "force_ball", "marker"):
        data = _example()
        del data[table]
        with pytest.raises(InputError, match=rf"table \[{table}\] is missing"):
            parse_rig(data)
    data = _example()
    del data["finger"]["thermal"]
    with pytest.raises(InputError, match=r"table \[finger.thermal\] is missing \(the finger's "
                                         r"heat model"):
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
    data = _example()
    data["force_ref"] = {"source": "serial", "rate_hz": 50.0, "noise_n": 0.01, "scale": 1.0,
                         "offset_n": 0.0}
    with pytest.raises(InputError, match=r"\[force_ref\] lacks port \(a path\)"):
        parse_rig(data)
    data["force_ref"] = {"source": "mcu", "rate_hz": 80.0, "noise_n": 0.02, "scale": 2e-5,
                         "offset_n": 0.0, "port": "/dev/ttyUSB0"}
    with pytest.raises(InputError, match=r"\[force_ref\] port is only used with source = "
                                         r"'serial'"):
        parse_rig(data)
    data = _example()
    data["finger"]["smp"]["e_rubbery_mpa"] = 2000.0
    with pytest.raises(InputError, match=r"\[finger.smp\] e_glassy_mpa 1200 must exceed "
                                         r"e_rubbery_mpa 2000"):
        parse_rig(data)
    data = _example()
    data["finger"]["smp"]["branch_weights"] = [0.5, 0.6, 0.2]
    with pytest.raises(InputError, match=r"\[finger.smp\] branch_weights must be >= 0 and "
                                         r"sum to 1"):
        parse_rig(data)


def test_a_measured_k80_this_smp_cannot_give_is_refused() -> None:
    data = _load(LAB)
    data["finger"]["k80_n_per_mm"] = [2.0, 0.01]  # more than the SMP's modulus falls
    with pytest.raises(InputError, match=r"\[finger\] k80_n_per_mm k80 falls 99.5 % from 27 to "
                                         r"60 °C; this finger's SMP gives .* to .* %"):
        parse_rig(data, "x.toml")
    data["finger"]["k80_n_per_mm"] = [2.0, 2.5]
    with pytest.raises(InputError, match=r"k80 falls -25.0 %"):
        parse_rig(data, "x.toml")
    data["finger"]["k80_temps_c"] = [60.0, 27.0]
    with pytest.raises(InputError, match=r"the temperatures must rise"):
        parse_rig(data, "x.toml")


def test_schema_1_reads_on_an_emulator_rig_and_is_refused_with_what_to_add_on_a_real_one(
) -> None:
    v1 = _example()
    del v1["rig"]["schema"]
    with pytest.raises(InputError, match=r"^x.toml: a schema 1 rig file \(no \[rig\] schema\) "
                                         r"describes the geometry only: add schema = 2 to "
                                         r"\[rig\], the tables \[motor\]") as info:
        parse_rig(v1, "x.toml")
    assert "\n" not in str(info.value)
    emu = _load(DOCS / "rig-emulator.toml")
    del emu["rig"]["schema"]
    old = parse_rig(emu, "emu.toml")
    assert old.schema == 1
    assert old.stiffness == FingerParams()
    assert old.geometry == RigGeometry()


@pytest.mark.parametrize(("changes", "message"), [
    ({("rgb", "toe_in_deg"): -40.0}, r"\[marker\] is outside the RGB camera's view at rest: a "
                                     r"corner falls at \(-?\d+, -?\d+\) px of a 640x480 image; "
                                     r"check \[marker\] position_mm"),
    ({("rgb", "position_mm"): [-25.0, 0.0, 60.0]}, r"\[marker\] is outside the RGB camera's view "
                                                   r"at rest"),
    # In view unbent, out of it bent by the force limit, hot (the marker 10.5 mm out).
    ({("rgb", "cx_px"): 420.0}, r"\[marker\] is outside the RGB camera's view bent 10.5 mm by "
                                r"12 N at the tip at 65 °C"),
    ({("rgb", "fx_px"): 40.0, ("rgb", "fy_px"): 40.0},
     r"\[marker\] spans \d.\d px on the RGB image at rest, too few to detect"),
    ({("rgb", "position_mm"): [80.0, 0.0, 0.0]}, r"\[marker\] is behind the RGB camera at rest"),
])
def test_a_marker_the_camera_does_not_see_is_refused(changes: dict[tuple[str, str], Any],
                                                     message: str) -> None:
    data = _example()
    for (table, key), value in changes.items():
        data[table][key] = value
    with pytest.raises(InputError, match=message) as info:
        parse_rig(data, "x.toml")
    assert "\n" not in str(info.value)
    ours = _example()
    ours["rgb"]["cx_px"] = 400.0  # near the edge, but in view however the finger bends
    parse_rig(ours, "x.toml")


def test_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"rig file .* not found"):
        load_rig(tmp_path / "none.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[serial\nport = 1\n", encoding="utf-8")
    with pytest.raises(InputError, match="is not valid TOML"):
        load_rig(bad)


def test_an_emulator_rig_takes_what_it_gives_and_leaves_the_rest_to_the_twin() -> None:
    emu = _load(DOCS / "rig-emulator.toml")
    lab = _load(LAB)
    for table in ("marker", "finger", "motor", "heaters", "force_ball"):
        emu[table] = lab[table]
    emu["rgb"].update({k: v for k, v in lab["rgb"].items() if k not in ("source", "device")})
    rig = parse_rig(emu, "emu.toml")
    assert rig.finger == load_rig(LAB).finger
    assert rig.stiffness == load_rig(LAB).stiffness
    assert rig.force_ref.source == "twin"
    assert set(rig.from_twin) == {"force_ref"}
    longer = _load(DOCS / "rig-emulator.toml")
    longer["finger"] = {"length_mm": 125.0}  # the twin's beams are along a 110 mm finger
    with pytest.raises(InputError, match=r"\[finger\] lacks beam_positions_mm \(mm\)"):
        parse_rig(longer, "emu.toml")
    narrow = _load(DOCS / "rig-emulator.toml")
    narrow["rig"]["open_aperture_mm"] = 100.0
    with pytest.raises(InputError, match=r"open_aperture_mm 100 is less than the twin's stroke "
                                         r"of 148 mm: give the rig's \[motor\]"):
        parse_rig(narrow, "emu.toml")
