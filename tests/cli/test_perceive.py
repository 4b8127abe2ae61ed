"""``relaxgrip perceive``: markers and poses from image files."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np
import pytest

from relaxgrip.rig import RigGeometry
from relaxgrip.twin.render_rgb import RgbRenderer
from relaxgrip.twin.sensors import RgbSensorConfig
from tests.clitools import assert_one_error_line, run_cli, run_main
from tests.rigs import RIG_FILES, twin_of

if TYPE_CHECKING:
    from PIL import Image

RIG = RigGeometry()


@pytest.fixture
def marker_png(tmp_path: Path) -> tuple[Path, np.ndarray]:
    pose = RIG.marker2cam(0.003, 0.04)
    image = RgbRenderer(RIG, RgbSensorConfig(), 0).render(0, pose)
    path = tmp_path / "marker.png"
    cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    return path, pose


def test_json_pose_matches_the_rendered_pose(marker_png: tuple[Path, np.ndarray]) -> None:
    path, pose = marker_png
    proc = run_cli("perceive", path, "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    (marker,) = out["markers"]
    assert marker["id"] == 0
    assert np.asarray(marker["corners_px"]).shape == (4, 2)
    assert np.allclose(marker["tvec_m"], pose[:3, 3], atol=5e-5)
    rot, _ = cv2.Rodrigues(np.asarray(marker["rvec"]))
    assert np.allclose(rot, pose[:3, :3], atol=2e-3)


def test_the_rigs_camera_and_marker_read_a_frame_of_its_twin(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = twin_of("lab").rig
    pose = rig.marker2cam(0.004, 0.05)
    image = RgbRenderer(rig, RgbSensorConfig(), 0).render(0, pose)
    path = tmp_path / "lab.png"
    cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    code, out, err = run_main(["perceive", path, "--rig", RIG_FILES["lab"], "--json"],
                              monkeypatch, capsys)
    assert code == 0, err
    got = json.loads(out)
    assert (got["dictionary"], got["marker_m"]) == ("4X4_50", rig.marker.size_m)
    (marker,) = got["markers"]
    assert marker["id"] == 7
    assert np.allclose(marker["tvec_m"], pose[:3, 3], atol=5e-5)
    code, out, err = run_main(["perceive", path, "--rig", RIG_FILES["lab"], "--fx", "600"],
                              monkeypatch, capsys)
    assert_one_error_line(code, out, err, "--rig gives the camera and the marker: leave out --fx")
    code, out, err = run_main(["perceive", path, "--rig", RIG_FILES["ours"]], monkeypatch, capsys)
    assert_one_error_line(code, out, err, "is 800x600 pixels, the rig's RGB camera 640x480")


def test_image_without_markers_is_an_empty_list(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "plain.jpg"
    cv2.imwrite(str(path), np.full((120, 160, 3), 90, np.uint8))
    code, out, _ = run_main(["perceive", path, "--json"], monkeypatch, capsys)
    assert code == 0
    assert json.loads(out)["markers"] == []


def test_table_output(
    marker_png: tuple[Path, np.ndarray],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, out, _ = run_main(["perceive", marker_png[0], "--fx", "600", "--dist", "0,0,0,0"],
                            monkeypatch, capsys)
    assert code == 0
    assert "1 marker(s)" in out


@pytest.mark.parametrize("dist", ["-0.3,0.1,0.001,0.001,-0.02", "-0.4 0.2 0 0",
                                  "2,1,0,0,0,2.3,1.5,0.3"])
def test_a_real_lens_distortion_is_taken(
    marker_png: tuple[Path, np.ndarray],
    dist: str,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, out, err = run_main(["perceive", marker_png[0], "--json", "--dist", dist],
                              monkeypatch, capsys)
    assert code == 0, err
    assert err == ""
    (marker,) = json.loads(out)["markers"]
    assert all(np.isfinite(marker["tvec_m"]))


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["missing.png"], "no such file"),
        (["notes.txt"], "not an image OpenCV can read"),
        (["{png}", "--dict", "9X9"], "not an ArUco dictionary"),
        (["{png}", "--dist", "1,x"], "--dist must be numbers"),
        (["{png}", "--dist", "1,2,3"], "distortion needs 4, 5, 8"),
        (["{png}", "--dist", ",,,,"], "--dist has an empty item"),
        (["{png}", "--dist", ""], "--dist has an empty item"),
        (["{png}", "--dist", "0,0,,0,0"], "--dist has an empty item"),
        (["{png}", "--dist", "1e308,0,0,0"], "--dist coefficients must be finite and within"),
        (["{png}", "--dist", "0,0,0,0,inf"], "--dist coefficients must be finite and within"),
        (["{png}", "--dist", "0,0,1000,0"], "undistorts the image's edges to no pinhole view"),
        (["{png}", "--dist", "0,0,0,0,0,0,1000,0"], "undistorts the image's edges to no pinhole"),
        (["adir"], "adir: is a directory, not an image file"),
        (["{png}", "--fx", "-3"], "fx_px must be 1 to 1e+06 pixels"),
        (["{png}", "--fx", "1e300"], "fx_px must be 1 to 1e+06 pixels"),
        (["{png}", "--fx", "1e-300"], "fx_px must be 1 to 1e+06 pixels"),
        (["{png}", "--cx", "1e300"], "cx_px must lie within the image"),
        (["{png}", "--marker-mm", "1e100"], "--marker-mm must be 0.1-10000 mm"),
        (["{png}", "--marker-mm", "0"], "--marker-mm must be 0.1-10000 mm"),
    ],
)
def test_bad_input(
    tmp_path: Path,
    marker_png: tuple[Path, np.ndarray],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    expected: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_text("not an image\n")
    (tmp_path / "adir").mkdir()
    argv = [a.replace("{png}", str(marker_png[0])) for a in args]
    code, out, err = run_main(["perceive", *argv], monkeypatch, capsys)
    assert_one_error_line(code, out, err, expected)


def _assert_same_pose(plain: str | Path, other: str | Path, monkeypatch: pytest.MonkeyPatch,
                      capsys: pytest.CaptureFixture[str]) -> None:
    """``perceive`` finds the one marker of image ``other`` where it finds that of ``plain``."""
    code, want_out, _ = run_main(["perceive", plain, "--json"], monkeypatch, capsys)
    code2, got_out, err = run_main(["perceive", other, "--json"], monkeypatch, capsys)
    assert (code, code2) == (0, 0), err
    (want,), (got,) = json.loads(want_out)["markers"], json.loads(got_out)["markers"]
    assert np.allclose(got["tvec_m"], want["tvec_m"], atol=2e-5)


@pytest.mark.parametrize("variant", ["rgba-transparent", "16-bit-hot-pixel", "float-nan"])
def test_images_as_labs_save_them_read_as_the_plain_one(
    marker_png: tuple[Path, np.ndarray], tmp_path: Path, variant: str,
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    """A transparent background is white paper; one hot or not-a-number pixel does not
    flatten a 16-bit or float image's contrast."""
    path, _ = marker_png
    grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    assert grey is not None
    if variant == "rgba-transparent":  # the marker opaque, the rest transparent and black
        alpha = np.where(grey < 200, 255, 0).astype(np.uint8)
        image = cv2.merge([np.where(alpha > 0, grey, 0)] * 3 + [alpha])
        out = tmp_path / "marker.png"
    elif variant == "16-bit-hot-pixel":  # 10-bit data in a 16-bit file, one pixel saturated
        image = (grey.astype(np.uint16) * 4)
        image[0, 0] = 65535
        out = tmp_path / "marker16.png"
    else:
        image = grey.astype(np.float32) / 255.0
        image[0, 0] = np.nan
        out = tmp_path / "marker.tiff"
    assert cv2.imwrite(str(out), image)
    _assert_same_pose(path, out, monkeypatch, capsys)


@pytest.mark.parametrize("ext", ["jpg", "png", "webp"])
def test_a_phone_picture_is_read_turned_as_its_exif_orientation_says(
    marker_png: tuple[Path, np.ndarray], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str], ext: str,
) -> None:
    """A PNG or WebP was read as stored: cv2.imdecode(IMREAD_UNCHANGED) ignores EXIF."""
    from PIL import Image  # matplotlib's dependency

    path, _ = marker_png
    image = Image.open(path)
    exif = image.getexif()
    exif[0x0112] = 6  # turn 90° clockwise to display
    turned = tmp_path / f"portrait.{ext}"
    image.save(turned, exif=exif, quality=95, lossless=True)
    code, out, err = run_main(["perceive", turned, "--json"], monkeypatch, capsys)
    assert code == 0, err
    found = json.loads(out)
    assert (found["width_px"], found["height_px"]) == (480, 640)
    shown = cv2.imread(str(turned), cv2.IMREAD_GRAYSCALE)
    assert shown is not None
    assert shown.shape == (640, 480)
    from relaxgrip.perception.marker import detect_markers, make_detector
    from relaxgrip.rig import MarkerMount

    (marker,) = found["markers"]
    (seen,) = detect_markers(np.asarray(shown, np.uint8),
                             make_detector(MarkerMount().aruco_dictionary))
    # The same corners as in the picture as shown (within the edge fit's refinement).
    assert np.abs(np.asarray(marker["corners_px"]) - seen.corners_px).max() < 1.0


#: PIL's transposes that undo each EXIF orientation (what ``ImageOps.exif_transpose`` does).
_UNDO = {2: "FLIP_LEFT_RIGHT", 3: "ROTATE_180", 4: "FLIP_TOP_BOTTOM", 5: "TRANSPOSE",
         6: "ROTATE_270", 7: "TRANSVERSE", 8: "ROTATE_90"}


def _stored_as(upright: Image.Image, orientation: int, path: Path) -> None:
    """Save ``upright`` as a camera that writes ``orientation`` would: turned, tagged."""
    from PIL import Image

    stored = upright
    if orientation != 1:  # the inverse of the transpose that shows it (6 and 8 swap)
        inverse = {6: 8, 8: 6}.get(orientation, orientation)
        stored = upright.transpose(getattr(Image.Transpose, _UNDO[inverse]))
    exif = stored.getexif()
    exif[0x0112] = orientation
    stored.save(path, exif=exif, quality=95, lossless=True)


@pytest.mark.parametrize("orientation", range(1, 9))
@pytest.mark.parametrize("ext", ["png", "webp", "jpg"])
def test_every_exif_orientation_is_read_as_shown(
    marker_png: tuple[Path, np.ndarray], tmp_path: Path, ext: str, orientation: int
) -> None:
    from PIL import Image, ImageOps

    from relaxgrip.cli.perceive import _read_gray

    upright = Image.open(marker_png[0]).convert("RGB")
    path = tmp_path / f"o{orientation}.{ext}"
    _stored_as(upright, orientation, path)
    got = _read_gray(path)
    if ext == "jpg":  # lossy: as OpenCV shows it (it turns JPEG itself)
        shown = cv2.imread(str(path), cv2.IMREAD_COLOR)
        assert shown is not None
        assert np.array_equal(got, cv2.cvtColor(shown, cv2.COLOR_BGR2GRAY))
        return
    # Lossless: exactly the upright picture, as PIL's viewer-side transpose also shows it.
    assert np.array_equal(np.asarray(ImageOps.exif_transpose(Image.open(path))),
                          np.asarray(upright))
    assert np.array_equal(got, cv2.cvtColor(np.asarray(upright), cv2.COLOR_RGB2GRAY))


def test_a_transparent_png_is_turned_with_its_alpha(
    marker_png: tuple[Path, np.ndarray], tmp_path: Path
) -> None:
    from PIL import Image

    from relaxgrip.cli.perceive import _read_gray

    grey = np.asarray(Image.open(marker_png[0]).convert("L"))
    alpha = np.where(grey < 200, 255, 0).astype(np.uint8)
    rgba = Image.fromarray(np.dstack([np.where(alpha > 0, grey, 0)] * 3 + [alpha]), "RGBA")
    upright, turned = tmp_path / "upright.png", tmp_path / "turned.png"
    _stored_as(rgba, 1, upright)
    _stored_as(rgba, 8, turned)
    assert np.array_equal(_read_gray(turned), _read_gray(upright))


def test_an_orientation_that_is_none_leaves_the_image_as_stored(
    marker_png: tuple[Path, np.ndarray], tmp_path: Path
) -> None:
    """A value outside 1-8, a TIFF (OpenCV's decoder turns it itself) and bytes that are
    no image read as stored."""
    from PIL import Image

    from relaxgrip.cli.perceive import _exif_orientation

    upright = Image.open(marker_png[0]).convert("RGB")
    for name, value in (("bad.png", 9), ("turned.tif", 6)):
        exif = upright.getexif()
        exif[0x0112] = value
        upright.save(tmp_path / name, exif=exif)
        assert _exif_orientation((tmp_path / name).read_bytes()) == 1
    assert _exif_orientation(b"not an image at all") == 1


@pytest.mark.parametrize(("dtype", "scale", "alpha"), [
    (np.float64, 1.0 / 255.0, False), (np.int32, 1000.0, False), (np.int16, 100.0, False),
    (np.float64, 1.0 / 255.0, True), (np.int32, 1000.0, True), (np.int16, 100.0, True),
])
def test_a_colour_tiff_of_any_depth_reads_as_the_plain_one(
    marker_png: tuple[Path, np.ndarray], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str], dtype: type, scale: float, alpha: bool,
) -> None:
    """cv2.cvtColor takes 8-bit, 16-bit and float32 colour only: a float64 or signed
    integer colour TIFF was a traceback; a signed one's opaque alpha (its type's largest
    value) was read as far beyond opaque, and the marker lost."""
    path, _ = marker_png
    colour = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert colour is not None
    image: np.ndarray = (colour * scale).astype(dtype)
    if alpha:
        opaque = np.iinfo(dtype).max if np.dtype(dtype).kind == "i" else 1.0
        image = np.dstack([image, np.full(image.shape[:2], opaque, dtype)])
    out = tmp_path / "marker.tiff"
    assert cv2.imwrite(str(out), image)
    _assert_same_pose(path, out, monkeypatch, capsys)


def _png_with_exif(exif: bytes) -> bytes:
    """A small PNG whose ``eXIf`` chunk holds ``exif``."""
    import io
    import struct
    import zlib

    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGB", (8, 6)).save(buf, "PNG")
    png = buf.getvalue()
    body = b"eXIf" + exif
    chunk = struct.pack(">I", len(exif)) + body + struct.pack(">I", zlib.crc32(body))
    return png[:33] + chunk + png[33:]  # after the signature and IHDR


@pytest.mark.parametrize("exif", [
    b"II*\x00",  # cut off before its first directory's offset: a struct.error in Pillow
    # an orientation whose 1000 values lie beyond the data: a warning from Pillow
    b"II*\x00\x08\x00\x00\x00\x01\x00\x12\x01\x03\x00\xe8\x03\x00\x00\x00\x01\x00\x00",
])
def test_damaged_exif_reads_the_image_as_stored(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    recwarn: pytest.WarningsRecorder, exif: bytes,
) -> None:
    path = tmp_path / "damaged.png"
    path.write_bytes(_png_with_exif(exif))
    code, out, err = run_main(["perceive", path, "--json"], monkeypatch, capsys)
    assert (code, err) == (0, "")
    assert not recwarn.list  # on the command line, two lines on stderr
    assert (json.loads(out)["width_px"], json.loads(out)["height_px"]) == (8, 6)


def test_a_picture_over_pillows_pixel_limit_is_turned_too(
    marker_png: tuple[Path, np.ndarray], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str], recwarn: pytest.WarningsRecorder,
) -> None:
    """Pillow refuses to open a picture of over twice its MAX_IMAGE_PIXELS (a 200 MP phone
    photo), and warns over it: only its EXIF is read, OpenCV has decoded it."""
    from PIL import Image

    turned = tmp_path / "portrait.png"
    _stored_as(Image.open(marker_png[0]).convert("RGB"), 6, turned)
    for limit in (480 * 640 // 3, 480 * 640 // 2 + 1):  # refused; warned
        monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", limit)
        code, out, err = run_main(["perceive", turned, "--json"], monkeypatch, capsys)
        assert (code, err) == (0, "")
        assert (json.loads(out)["width_px"], json.loads(out)["height_px"]) == (640, 480)
        assert limit == Image.MAX_IMAGE_PIXELS  # put back
    assert not recwarn.list
