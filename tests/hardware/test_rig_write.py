"""Writing into a rig file: comments and layout kept, the values read back, all or nothing."""

from __future__ import annotations

import os
import stat
import tomllib
from pathlib import Path

import pytest
import tomlkit

from relaxgrip.errors import InputError
from relaxgrip.hardware.rig_file import ZeroPoseSpec, load_rig, parse_rig, read_rig_text
from relaxgrip.hardware.rig_write import (
    check_rig_writable,
    remove_zero_pose,
    set_rgb_intrinsics,
    set_zero_pose,
    update_rig_file,
)
from relaxgrip.rig import CameraIntrinsics

DOCS = Path(__file__).resolve().parents[2] / "docs"
CAMERA = CameraIntrinsics(640, 480, 612.0312345, 608.01, 324.4567, 236.0,
                          (-0.21, 0.08, 0.0008, -0.0006, -0.02))
ZERO = ZeroPoseSpec((0.0012, -0.0021, 0.0843), (0.1, -0.2, 0.3), 30, 1.2e-5)


def _copy(tmp_path: Path, name: str = "rigs/relaxgrip.toml") -> Path:
    rig = tmp_path / "rig.toml"
    rig.write_bytes((DOCS / name).read_bytes())
    return rig


def _changed_lines(before: str, after: str) -> list[tuple[str, str]]:
    return [(a, b) for a, b in zip(before.splitlines(), after.splitlines(), strict=False)
            if a != b]


def test_intrinsics_are_written_with_every_comment_kept(tmp_path: Path) -> None:
    rig = _copy(tmp_path)
    before = read_rig_text(rig)
    written = update_rig_file(rig, before, lambda doc: set_rgb_intrinsics(doc, CAMERA))
    after = rig.read_text(encoding="utf-8")
    # Only the five values changed, line for line; every comment is where it was.
    changed = _changed_lines(before, after)
    assert [a.split("=")[0].strip() for a, _ in changed] == ["fx_px", "fy_px", "cx_px", "cy_px",
                                                             "dist"]
    assert len(after.splitlines()) == len(before.splitlines())
    assert [line.split("#", 1)[1] for line in before.splitlines() if "#" in line] == \
        [line.split("#", 1)[1] for line in after.splitlines() if "#" in line]
    assert "dist = [-0.21, 0.08, 0.0008, -0.0006, -0.02]" in after
    loaded = load_rig(rig)
    assert loaded == written
    intr = loaded.rgb.mount.intrinsics
    assert (intr.fx_px, intr.fy_px, intr.cx_px, intr.cy_px) == (612.031, 608.01, 324.457, 236.0)
    assert intr.dist == CAMERA.dist
    assert loaded.geometry.marker_zero_m is None


def test_the_zero_pose_is_written_read_and_removed(tmp_path: Path) -> None:
    rig = _copy(tmp_path)
    before = read_rig_text(rig)
    update_rig_file(rig, before, lambda doc: set_zero_pose(doc, ZERO))
    text = rig.read_text(encoding="utf-8")
    assert text.startswith(before)
    assert "\n[zero_pose]\n" in text
    loaded = load_rig(rig)
    assert loaded.zero_pose is not None
    assert loaded.zero_pose.position_m == pytest.approx(ZERO.position_m, abs=1e-7)
    assert loaded.zero_pose.rotation_rvec == pytest.approx(ZERO.rotation_rvec, abs=1e-6)
    assert loaded.geometry.marker_zero_m == loaded.geometry.marker_home_m
    assert loaded.geometry.marker_home_m == pytest.approx(ZERO.position_m, abs=1e-7)
    # Measured again: the table's values change in place.
    again = ZeroPoseSpec((0.001, 0.0, 0.08), (0.0, 0.0, 0.0), 60, 0.0)
    update_rig_file(rig, text, lambda doc: set_zero_pose(doc, again))
    assert load_rig(rig).zero_pose == ZeroPoseSpec((0.001, 0.0, 0.08), (0.0, 0.0, 0.0), 60, 0.0)
    assert rig.read_text(encoding="utf-8").count("\n[zero_pose]\n") == 1
    doc = tomlkit.parse(rig.read_text(encoding="utf-8"))
    assert remove_zero_pose(doc)
    assert not remove_zero_pose(doc)
    assert parse_rig(tomllib.loads(tomlkit.dumps(doc)), "x").zero_pose is None


def test_a_read_only_rig_file_is_refused_untouched(tmp_path: Path) -> None:
    rig = _copy(tmp_path)
    before = read_rig_text(rig)
    rig.chmod(0o444)
    try:
        with pytest.raises(InputError, match=r"rig file .* is not writable \(mode 0444\): "
                                              "nothing written"):
            update_rig_file(rig, before, lambda doc: set_rgb_intrinsics(doc, CAMERA))
        with pytest.raises(InputError, match="is not writable"):
            check_rig_writable(rig)
        assert rig.read_text(encoding="utf-8") == before
    finally:
        rig.chmod(0o644)


def test_a_rig_file_changed_since_it_was_read_is_not_overwritten(tmp_path: Path) -> None:
    rig = _copy(tmp_path)
    before = read_rig_text(rig)
    edited = before.replace("[rig]\n", "[rig]\n# edited meanwhile\n", 1)
    assert edited != before
    rig.write_text(edited, encoding="utf-8")
    with pytest.raises(InputError, match="changed since it was read: nothing written"):
        update_rig_file(rig, before, lambda doc: set_rgb_intrinsics(doc, CAMERA))
    assert rig.read_text(encoding="utf-8") == edited


def test_an_edit_that_breaks_the_rig_file_writes_nothing(tmp_path: Path) -> None:
    rig = _copy(tmp_path)
    before = read_rig_text(rig)
    bad = CameraIntrinsics(320, 240, 300.0, 300.0, 159.5, 119.5)

    def wrong_size(doc: tomlkit.TOMLDocument) -> None:
        set_rgb_intrinsics(doc, bad)
        doc["rgb"]["cx_px"] = 2000.0

    with pytest.raises(InputError, match=r"\[rgb\] cx_px must lie within the image"):
        update_rig_file(rig, before, wrong_size)
    assert rig.read_text(encoding="utf-8") == before


def test_permissions_line_ends_and_links_are_kept(tmp_path: Path) -> None:
    rig = _copy(tmp_path)
    crlf = rig.read_bytes().replace(b"\n", b"\r\n")
    rig.write_bytes(crlf)
    rig.chmod(0o640)
    link = tmp_path / "link.toml"
    link.symlink_to(rig.name)
    update_rig_file(link, read_rig_text(link), lambda doc: set_rgb_intrinsics(doc, CAMERA))
    assert link.is_symlink()
    raw = rig.read_bytes()
    assert raw.count(b"\r\n") == crlf.count(b"\r\n")
    assert b"\n" not in raw.replace(b"\r\n", b"")
    assert stat.S_IMODE(os.stat(rig).st_mode) == 0o640
    assert load_rig(rig).rgb.mount.intrinsics.fx_px == 612.031
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.parametrize(("table", "message"), [
    ("position_mm = [0.0, 0.0, -5.0]\nrotation_deg = [0, 0, 0]\nframes = 30\nspread_mm = 0.0",
     r"\[zero_pose\] position_mm must be in front of the RGB camera"),
    ("position_mm = [0.0, 0.0, 80.0]\nrotation_deg = [200, 0, 0]\nframes = 30\nspread_mm = 0.0",
     r"\[zero_pose\] rotation_deg must be a rotation vector of at most 180"),
    ("position_mm = [0.0, 0.0, 80.0]\nrotation_deg = [0, 0, 0]\nspread_mm = 0.0",
     r"\[zero_pose\] lacks frames \(a count\)"),
    ("position_mm = [0.0, 80.0]\nrotation_deg = [0, 0, 0]\nframes = 3\nspread_mm = 0.0",
     r"\[zero_pose\] position_mm needs 3 numbers"),
    ("position_mm = [0.0, 0.0, 80.0]\nrotation_deg = [0, 0, 0]\nframes = 3\nspread_mm = 0.0\n"
     "when = 1", r"\[zero_pose\] has unknown key 'when'"),
])
def test_bad_zero_poses_are_named(tmp_path: Path, table: str, message: str) -> None:
    rig = _copy(tmp_path)
    rig.write_text(rig.read_text(encoding="utf-8") + "\n[zero_pose]\n" + table + "\n",
                   encoding="utf-8")
    with pytest.raises(InputError, match=message):
        load_rig(rig)



def test_the_measured_home_travels_with_the_geometry(tmp_path: Path) -> None:
    import json
    from dataclasses import asdict

    from relaxgrip.recording.reader import rig_from_dict
    from relaxgrip.rig import RigGeometry

    rig = _copy(tmp_path)
    update_rig_file(rig, read_rig_text(rig), lambda doc: set_zero_pose(doc, ZERO))
    geometry = load_rig(rig).geometry
    # As a recording stores it: JSON, and back.
    assert rig_from_dict(json.loads(json.dumps(asdict(geometry)))) == geometry
    assert RigGeometry().marker_home_m == pytest.approx(RigGeometry().marker2cam()[:3, 3])
    with pytest.raises(InputError, match="in front of the RGB camera"):
        RigGeometry(marker_zero_m=(0.0, 0.0, -0.01))
