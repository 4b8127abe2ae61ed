"""``make-board``, ``calibrate-camera`` and ``zero-pose`` from the command line."""

from __future__ import annotations

import json
import re
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

import relaxgrip.cli.camera as camera
from relaxgrip.backend import Command, Frame
from relaxgrip.board import CharucoBoard
from relaxgrip.clock import VirtualClock
from relaxgrip.experiments.camera_calibration import BLUR_SIGMA_PX, TRUTH
from relaxgrip.hardware.rig_file import load_rig
from relaxgrip.twin import GripperTwin, TwinConfig
from relaxgrip.twin.render_board import BoardRenderer, board_poses
from relaxgrip.twin.sensors import RgbSensorConfig
from tests.clitools import assert_one_error_line, run_main

DOCS = Path(__file__).resolve().parents[2] / "docs"
PT_PER_MM = 72.0 / 25.4


# -- make-board -------------------------------------------------------------------------

def _filled_groups(pdf: bytes) -> tuple[tuple[float, float], list[np.ndarray]]:
    """The page size (pt) and each filled path's rectangles (x0, y0, x1, y1 in pt)."""
    media = re.search(rb"MediaBox \[ *([\d.]+) +([\d.]+) +([\d.]+) +([\d.]+) *\]", pdf)
    assert media is not None
    page = (float(media[3]) - float(media[1]), float(media[4]) - float(media[2]))
    groups = []
    for stream in re.finditer(rb"stream\r?\n(.*?)\r?\nendstream", pdf, re.S):
        try:
            text = zlib.decompress(stream[1]).decode("latin-1")
        except zlib.error:
            continue
        if " re W n" not in text:  # the page's content, not a font's glyphs
            continue
        for block in re.split(r"\n\s*f\n", text)[:-1]:
            quads = re.findall(r"([\d.]+) ([\d.]+) m\n([\d.]+) ([\d.]+) l\n([\d.]+) ([\d.]+) l\n"
                               r"([\d.]+) ([\d.]+) l\nh", block)
            if quads:
                xy = np.array(quads, dtype=np.float64).reshape(-1, 4, 2)
                rects = np.c_[xy[:, :, 0].min(1), xy[:, :, 1].min(1),
                              xy[:, :, 0].max(1), xy[:, :, 1].max(1)]
                if not np.allclose(rects, [[0.0, 0.0, *page]], atol=1e-3):  # the white page
                    groups.append(rects)
    return page, groups


def test_the_printed_sheet_is_at_true_scale(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_main(["make-board", "--out", tmp_path / "sheet.pdf"], monkeypatch,
                              capsys)
    assert code == 0, err
    assert "--squares 9x7 --square-mm 10 --marker-mm 7 --dictionary 5X5_100" in out
    page, (board, marker, bar) = _filled_groups((tmp_path / "sheet.pdf").read_bytes())
    assert page == pytest.approx((210.0 * PT_PER_MM, 297.0 * PT_PER_MM), abs=1e-3)
    sides = np.c_[board[:, 2] - board[:, 0], board[:, 3] - board[:, 1]]
    squares = sides[np.asarray(np.isclose(sides, 10.0 * PT_PER_MM, atol=2e-3)).all(axis=1)]
    assert len(squares) == 32  # the black half of 9 x 7, none of the markers' runs
    extent = board[:, 2:].max(0) - board[:, :2].min(0)
    assert extent == pytest.approx((90.0 * PT_PER_MM, 70.0 * PT_PER_MM), abs=2e-3)
    # The finger marker: its black square 12 mm; the scale bar 50 mm.
    assert marker[:, 2:].max(0) - marker[:, :2].min(0) == pytest.approx(
        (12.0 * PT_PER_MM,) * 2, abs=2e-3)
    assert float((bar[:, 2] - bar[:, 0]).max()) == pytest.approx(50.0 * PT_PER_MM, abs=2e-3)
    with Image.open(tmp_path / "sheet.png") as png:
        assert png.info["dpi"] == pytest.approx((300.0, 300.0), abs=0.01)
        # Whole pixels of the page (matplotlib rounds down): within a pixel, 0.085 mm.
        assert np.abs(np.subtract(png.size, (210 / 25.4 * 300, 297 / 25.4 * 300))).max() < 1.0
    # The PNG shows the board the detector knows.
    gray = cv2.imread(str(tmp_path / "sheet.png"), cv2.IMREAD_GRAYSCALE)
    assert gray is not None
    small = cv2.resize(gray, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
    _, ids, _, _ = cv2.aruco.CharucoDetector(CharucoBoard().cv_board).detectBoard(small)
    assert ids is not None
    assert len(ids) == 48


def test_the_sheet_takes_the_marker_from_the_rig_and_the_paper_asked(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text((DOCS / "rigs" / "relaxgrip.toml").read_text(encoding="utf-8")
                   .replace("id = 0", "id = 7").replace("size_mm = 12.0", "size_mm = 15.0"),
                   encoding="utf-8")
    code, out, err = run_main(["make-board", "--out", tmp_path / "s", "--rig", rig,
                               "--paper", "letter", "--square-mm", "20", "--marker-mm", "15",
                               "--squares", "8x6"], monkeypatch, capsys)
    assert code == 0, err
    assert "finger marker: DICT_4X4_50 id 7, 15 mm" in out
    page, (board, marker, _) = _filled_groups((tmp_path / "s.pdf").read_bytes())
    assert page == pytest.approx((612.0, 792.0), abs=1e-3)
    assert board[:, 2:].max(0) - board[:, :2].min(0) == pytest.approx(
        (160.0 * PT_PER_MM, 120.0 * PT_PER_MM), abs=2e-3)
    assert marker[:, 2:].max(0) - marker[:, :2].min(0) == pytest.approx(
        (15.0 * PT_PER_MM,) * 2, abs=2e-3)


@pytest.mark.parametrize(("args", "expected"), [
    (["--paper", "A5", "--square-mm", "30", "--marker-mm", "22"],
     "270 x 210 mm) and the 12 mm finger marker need 294 x 294 mm, more than A5 "
     "(148 x 210 mm) holds"),
    (["--paper", "B5"], "--paper must be one of A3, A4, A5, letter, legal"),
    (["--rig", str(DOCS / "rigs" / "relaxgrip.toml"), "--marker-id", "3"], "not both"),
    (["--marker-id", "50"], "--marker-id must be 0 to 49 for DICT_4X4_50"),
    (["--squares", "9by7"], "--squares must be COLUMNSxROWS"),
    (["--marker-mm", "12"], "board marker must be 20-95 % of the square"),
    (["--out", "/nonexistent/dir/sheet"], "directory /nonexistent/dir does not exist"),
])
def test_make_board_bad_input(args: list[str], expected: str, tmp_path: Path,
                              monkeypatch: pytest.MonkeyPatch,
                              capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    assert_one_error_line(*run_main(["make-board", *args], monkeypatch, capsys), expected)
    assert not list(tmp_path.iterdir())


# -- calibrate-camera -------------------------------------------------------------------

def _rendered(n: int, seed: int) -> list[np.ndarray]:
    board = CharucoBoard()
    rng = np.random.default_rng(seed)
    renderer = BoardRenderer(board, TRUTH, RgbSensorConfig(blur_sigma_px=BLUR_SIGMA_PX))
    return [renderer.render(p, rng) for p in board_poses(board, TRUTH, n, rng)]


@pytest.fixture(scope="module")
def views_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("views")
    for k, image in enumerate(_rendered(16, 11)):
        cv2.imwrite(str(folder / f"view-{k:02d}.png"), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    (folder / "notes.txt").write_text("not an image: skipped\n", encoding="utf-8")
    return folder


def _rig(tmp_path: Path, zero_pose: bool = False) -> Path:
    rig = tmp_path / "rig.toml"
    text = (DOCS / "rigs" / "relaxgrip.toml").read_text(encoding="utf-8")
    if zero_pose:
        text += ("\n[zero_pose]\nposition_mm = [1.0, 2.0, 80.0]\nrotation_deg = [0, 0, 0]\n"
                 "frames = 30\nspread_mm = 0.01\n")
    rig.write_text(text, encoding="utf-8")
    return rig


def test_calibrate_a_folder_and_write_the_rig_file(views_dir: Path, tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    rig = _rig(tmp_path, zero_pose=True)
    code, out, err = run_main(["calibrate-camera", views_dir, "--rig", rig, "--write"],
                              monkeypatch, capsys)
    assert code == 0, err
    assert "RMS reprojection error" in out
    assert "view-00.png" in out
    assert f"wrote fx_px, fy_px, cx_px, cy_px and dist into [rgb] of {rig}" in out
    assert "removed [zero_pose]" in out
    spec = load_rig(rig)
    intr = spec.rgb.mount.intrinsics
    assert intr.fx_px == pytest.approx(TRUTH.fx_px, rel=0.005)
    assert intr.cy_px == pytest.approx(TRUTH.cy_px, rel=0.005)
    assert len(intr.dist) == 5
    assert spec.zero_pose is None
    assert "# OpenCV k1 k2 p1 p2 [k3 ...]; empty: none" in rig.read_text(encoding="utf-8")
    # Printed, not written: one JSON object with the same figures.
    before = rig.read_bytes()
    code, out, err = run_main(["calibrate-camera", views_dir, "--json", "--dist-model",
                               "k1k2p1p2"], monkeypatch, capsys)
    assert code == 0, err
    result = json.loads(out)
    assert result["written"] is None
    assert len(result["dist"]) == 4
    assert result["fx_px"] == pytest.approx(TRUTH.fx_px, rel=0.005)
    assert result["rms_px"] <= 0.3
    assert len(result["views"]) == result["n_views"]
    assert rig.read_bytes() == before


def test_calibrate_camera_bad_input(views_dir: Path, tmp_path: Path,
                                    monkeypatch: pytest.MonkeyPatch,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    blank = tmp_path / "blank"
    blank.mkdir()
    for k in range(3):
        noise = np.random.default_rng(k).integers(0, 255, (480, 640), dtype=np.uint8)
        cv2.imwrite(str(blank / f"b{k}.png"), noise)
    few = tmp_path / "few"
    few.mkdir()
    for name in sorted(p.name for p in views_dir.glob("*.png"))[:5]:
        (few / name).write_bytes((views_dir / name).read_bytes())
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "a.png").write_bytes((views_dir / "view-00.png").read_bytes())
    (broken / "b.png").write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    no_rgb = tmp_path / "no-rgb.toml"
    text = (DOCS / "rigs" / "relaxgrip.toml").read_text(encoding="utf-8")
    no_rgb.write_text(re.sub(r"\[rgb\].*?(?=\[ir\])", "", text, flags=re.S), encoding="utf-8")
    small = tmp_path / "small.toml"
    small.write_text(text.replace("width_px = 640\nheight_px = 480",
                                  "width_px = 320\nheight_px = 240")
                     .replace("cx_px = 319.5", "cx_px = 159.5")
                     .replace("cy_px = 239.5", "cy_px = 119.5")
                     .replace("fx_px = 600.0\nfy_px = 600.0", "fx_px = 300.0\nfy_px = 300.0"),
                     encoding="utf-8")
    cases: list[tuple[list[str | Path], str]] = [
        ([empty], "empty: no image files (.png"),
        ([tmp_path / "missing"], "no such folder of board images"),
        ([blank], "no ChArUco board (9x7 squares of 10 mm, 7 mm markers, DICT_5X5_100 ids "
                  "0-30) found in any of its 3 images"),
        ([few], "too few views: the board is in 5, at least 12 needed"),
        ([broken], "b.png: not an image OpenCV can read"),
        ([views_dir, "--rig", no_rgb], "table [rgb] is missing"),
        ([views_dir, "--rig", small], "the views are 640x480, the rig file's [rgb] camera is "
                                      "320x240"),
        ([views_dir, "--write"], "--write needs --rig RIG.toml"),
        (["--live"], "--live needs --rig RIG.toml"),
        ([], "give a folder of board images, or --rig RIG.toml --live"),
        ([views_dir, "--dist-model", "k9"], "--dist-model must be one of"),
        ([views_dir, "--min-views", "20"], "too few views: the board is in"),
    ]
    for args, expected in cases:
        assert_one_error_line(*run_main(["calibrate-camera", *args], monkeypatch, capsys),
                              expected)


def test_a_read_only_rig_file_is_left_untouched(views_dir: Path, tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    rig = _rig(tmp_path)
    before = rig.read_bytes()
    rig.chmod(0o444)
    try:
        assert_one_error_line(*run_main(["calibrate-camera", views_dir, "--rig", rig, "--write"],
                                        monkeypatch, capsys), "is not writable (mode 0444)")
        assert_one_error_line(*run_main(["zero-pose", "--rig", rig, "--write"], monkeypatch,
                                        capsys), "is not writable (mode 0444)")
    finally:
        rig.chmod(0o644)
    assert rig.read_bytes() == before


class _Replay:
    """An RGB camera showing each view for a few frames, then nothing new."""

    name = "RGB"
    stall_s = 1.0

    def __init__(self, images: list[np.ndarray], repeat: int = 3) -> None:
        self._frames = [image for image in images for _ in range(repeat)]
        self._seq = -1
        self.closed = False

    def start(self) -> None:
        pass

    def read(self, now_s: float) -> Frame | None:
        self._seq = min(self._seq + 1, len(self._frames) - 1)
        return Frame(now_s, self._seq, self._frames[self._seq])

    def close(self) -> None:
        self.closed = True


class _TickingClock(VirtualClock):
    """A virtual clock a frame period further on every time it is read."""

    def now(self) -> float:
        self.advance(1.0 / 30.0)
        return super().now()


def test_live_views_are_kept_saved_and_calibrate_again(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    replay = _Replay(_rendered(24, 12), repeat=8)
    monkeypatch.setattr(camera, "_open_rgb_source", lambda rig, clock: replay)
    monkeypatch.setattr(camera, "_new_clock", _TickingClock)
    rig, saved = _rig(tmp_path), tmp_path / "saved"
    code, out, err = run_main(["calibrate-camera", "--rig", rig, "--live", "--json",
                               "--min-views", "10", "--max-s", "120", "--save-views", saved],
                              monkeypatch, capsys)
    assert code == 0, err
    assert replay.closed
    assert "views kept" in err  # the progress display, beside the JSON
    live = json.loads(out)
    assert live["n_views"] >= 10
    assert live["fx_px"] == pytest.approx(TRUTH.fx_px, rel=0.005)
    assert len(list(saved.glob("view-*.png"))) == live["n_views"]
    code, out, err = run_main(["calibrate-camera", saved, "--json"], monkeypatch, capsys)
    assert code == 0, err
    again = json.loads(out)  # the same views: the same fit (OpenCV's sums vary in the 11th digit)
    assert again["n_views"] == live["n_views"]
    assert again["fx_px"] == pytest.approx(live["fx_px"], rel=1e-8)
    assert again["rms_px"] == pytest.approx(live["rms_px"], rel=1e-6)


# -- zero-pose --------------------------------------------------------------------------

@pytest.fixture
def twin_gripper(monkeypatch: pytest.MonkeyPatch) -> GripperTwin:
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(), 0, clock)
    twin.reset()
    monkeypatch.setattr(camera, "_open_gripper", lambda rig: (twin, clock))
    return twin


def test_zero_pose_is_measured_and_written(twin_gripper: GripperTwin, tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    rig = _rig(tmp_path)
    before = rig.read_text(encoding="utf-8")
    code, out, err = run_main(["zero-pose", "--rig", rig, "--write"], monkeypatch, capsys)
    assert code == 0, err
    assert "marker at rest over 30 of 30 frames" in out
    assert f"wrote [zero_pose] into {rig}" in out
    spec = load_rig(rig)
    assert spec.zero_pose is not None
    truth = spec.geometry.marker2cam()[:3, 3]
    assert np.linalg.norm(np.asarray(spec.zero_pose.position_m) - truth) < 1e-4
    assert rig.read_text(encoding="utf-8").startswith(before)


def test_zero_pose_refuses_heaters_on_and_writes_nothing(
        twin_gripper: GripperTwin, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    rig = _rig(tmp_path)
    before = rig.read_bytes()
    twin_gripper.act(Command(heater_duty=(1.0, 0.0)))
    assert_one_error_line(*run_main(["zero-pose", "--rig", rig, "--write"], monkeypatch, capsys),
                          "heaters on (duty 1.00, 0.00)")
    assert rig.read_bytes() == before
    assert_one_error_line(*run_main(["zero-pose", "--rig", rig, "--frames", "3"], monkeypatch,
                                    capsys), "--frames must be 5 to 10000")


def test_zero_pose_through_the_emulated_mcu(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    from relaxgrip.hardware.emulator import open_emulated_gripper

    def emulated(rig: object) -> tuple[object, VirtualClock]:
        clock = VirtualClock()
        gripper, _ = open_emulated_gripper(TwinConfig(), 0, clock)
        gripper.reset()
        return gripper, clock

    monkeypatch.setattr(camera, "_open_gripper", emulated)
    code, out, err = run_main(["zero-pose", "--rig", _rig(tmp_path), "--json", "--frames", "10"],
                              monkeypatch, capsys)
    assert code == 0, err
    result = json.loads(out)
    assert result["frames"] == 10
    assert result["written"] is None
    assert result["max_force_n"] < 0.1
    assert result["offset_from_mounts_mm"] < 0.1
