"""``relaxgrip perceive IMAGE``: ArUco markers and their poses in any image."""

from __future__ import annotations

import io
import math
import re
import struct
import warnings
from pathlib import Path
from typing import Annotated, Any

import cv2
import numpy as np
import typer
from rich.table import Table

from relaxgrip.cli._app import app, console, emit_json, float_option
from relaxgrip.errors import InputError
from relaxgrip.fileio import check_input_file
from relaxgrip.perception.marker import (
    PoseSolver,
    detect_markers,
    make_detector,
    refine_corners_by_edges,
    to_gray,
)
from relaxgrip.rig import ARUCO_DICTIONARIES, MAX_DIST_COEFF, CameraIntrinsics, MarkerMount

__all__ = ["perceive"]

#: EXIF's Orientation tag (TIFF tag 274).
_ORIENTATION_TAG = 0x0112


def _exif_orientation(data: bytes) -> int:
    """The orientation (1-8) an image file's EXIF gives it (Pillow reads a JPEG's APP1, a
    PNG's ``eXIf`` and a WebP's ``EXIF`` chunk); 1 (as stored) for none, a value outside
    1-8, a file Pillow cannot read or EXIF it cannot parse, and a TIFF, whose decoder in
    OpenCV turns it itself."""
    from PIL import Image, UnidentifiedImageError

    # OpenCV has decoded the pixels already and only the EXIF is read here: Pillow's pixel
    # limit (a 200 MP phone photo is over it) and its warnings on damaged EXIF do not apply.
    limit = Image.MAX_IMAGE_PIXELS
    Image.MAX_IMAGE_PIXELS = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(io.BytesIO(data)) as image:
                if image.format == "TIFF":
                    return 1
                value = image.getexif().get(_ORIENTATION_TAG, 1)
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError, struct.error):
        return 1
    finally:
        Image.MAX_IMAGE_PIXELS = limit
    return value if isinstance(value, int) and 1 <= value <= 8 else 1


def _as_shown(image: np.ndarray[Any, Any], orientation: int) -> np.ndarray[Any, Any]:
    """``image`` turned and mirrored as EXIF ``orientation`` (1-8) says it is shown.

    The transforms of OpenCV's ``ExifTransform`` (what ``cv2.imread`` applies):
    5-8 transpose first; then 2, 3, 6, 7 flip left-right and 3, 4, 7, 8 flip
    upside down (6 is a quarter turn clockwise, 8 anticlockwise).
    """
    if orientation >= 5:
        image = image.swapaxes(0, 1)
    if orientation in (2, 3, 6, 7):
        image = image[:, ::-1]
    if orientation in (3, 4, 7, 8):
        image = image[::-1]
    return np.ascontiguousarray(image)


def _decode(data: np.ndarray[Any, np.dtype[np.uint8]]) -> np.ndarray[Any, Any] | None:
    """Decode an image file's bytes, turned as its EXIF orientation says it is shown.

    A JPEG has no alpha: decoded grey or colour, depth kept.  Other formats
    are decoded unchanged, alpha kept, and ``cv2.imdecode`` then ignores their
    orientation (it turns an image only for flags other than
    ``IMREAD_UNCHANGED``).  So every format is decoded as stored and turned
    here, as its EXIF says.
    """
    if not data.size:
        return None
    jpeg = data[:2].tobytes() == b"\xff\xd8"
    flags = (cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR | cv2.IMREAD_IGNORE_ORIENTATION if jpeg
             else cv2.IMREAD_UNCHANGED)
    image = cv2.imdecode(data, flags)
    if image is None or image.size == 0:
        return None
    return _as_shown(image, _exif_orientation(data.tobytes()))


def _read_gray(path: Path) -> np.ndarray[Any, np.dtype[np.uint8]]:
    """Read any image OpenCV can decode as 8-bit grey.

    Transparent pixels are taken as white (a marker printed on nothing); a
    16-bit or float image is stretched between its 0.1st and 99.9th
    percentiles, so that one hot or dead pixel does not flatten the rest.
    Every format is turned as its EXIF orientation says, as image viewers and
    ``cv2.imread`` show it (a phone's portrait photo), see :func:`_decode`.
    """
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not an image file")
    check_input_file(path, "file", InputError)  # a FIFO or a device: named, not read
    data = np.fromfile(path, dtype=np.uint8)
    log = cv2.utils.logging
    previous = log.getLogLevel()
    log.setLogLevel(log.LOG_LEVEL_SILENT)  # a truncated file: our error line, not also OpenCV's
    try:
        image = _decode(data)
    finally:
        log.setLogLevel(previous)
    if image is None:
        raise InputError(f"{path}: not an image OpenCV can read")
    if image.ndim == 3 and image.shape[2] in (2, 4):  # an alpha channel: over white
        white = float(np.iinfo(image.dtype).max) if image.dtype.kind in "iu" else 1.0
        alpha = image[..., -1:].astype(np.float32) / white
        colour = image[..., :-1].astype(np.float32)
        image = (colour * alpha + white * (1.0 - alpha)).astype(image.dtype)
    if image.ndim == 3:  # grey first: the scaling below then touches one channel
        if image.shape[2] > 1 and image.dtype not in (np.uint8, np.uint16, np.float32):
            image = image.astype(np.float32)  # a float64 or integer TIFF: cvtColor takes neither
        image = image[..., 0] if image.shape[2] == 1 else cv2.cvtColor(
            image, cv2.COLOR_BGR2GRAY)
    if image.dtype != np.uint8:  # 16-bit or float images: scale to 8 bits
        values = image.astype(np.float32)
        finite = np.isfinite(values)
        if not finite.any():
            raise InputError(f"{path}: no finite pixel value")
        lo, hi = (float(v) for v in np.percentile(values[finite], [0.1, 99.9]))
        values[~finite] = lo
        np.subtract(values, lo, out=values)
        np.multiply(values, 255.0 / max(hi - lo, 1e-12), out=values)
        image = np.clip(values, 0.0, 255.0, out=values).astype(np.uint8)
    return to_gray(np.asarray(image, dtype=np.uint8))


def _parse_dist(text: str | None) -> tuple[float, ...]:
    """Distortion coefficients from ``k1,k2,p1,p2[,k3...]`` (commas or spaces); none if omitted.

    Raises
    ------
    InputError
        An empty item, a non-number, or a coefficient that is not finite or beyond
        ±:data:`MAX_DIST_COEFF`.
    """
    if text is None:
        return ()
    items = re.split(r"\s*,\s*|\s+", text.strip())
    if "" in items:
        raise InputError(f"--dist has an empty item in {text!r}: give k1,k2,p1,p2[,k3...]")
    try:
        values = tuple(float(v) for v in items)
    except ValueError:
        raise InputError(f"--dist must be numbers separated by commas, got {text!r}") from None
    for value in values:
        if not (math.isfinite(value) and abs(value) <= MAX_DIST_COEFF):
            raise InputError(f"--dist coefficients must be finite and within "
                             f"±{MAX_DIST_COEFF:g}, got {value:g}")
    return values


@app.command("perceive")
def perceive(
    image: Annotated[Path, typer.Argument(metavar="IMAGE", help="Any image file (PNG, JPEG, ...).",
                                          show_default=False)],
    fx: Annotated[float | None, float_option(
        "--fx", help="Focal length x (pixels; default 600).", show_default=False)] = None,
    fy: Annotated[float | None, float_option("--fy", help="Focal length y (pixels; default fx).",
                                             show_default=False)] = None,
    cx: Annotated[float | None, float_option("--cx", help="Principal point x (default centre).",
                                             show_default=False)] = None,
    cy: Annotated[float | None, float_option("--cy", help="Principal point y (default centre).",
                                             show_default=False)] = None,
    marker_mm: Annotated[float | None, float_option(
        "--marker-mm", help="Marker side (mm; default 12).", show_default=False)] = None,
    dictionary: Annotated[str | None, typer.Option(
        "--dict", help="ArUco dictionary, e.g. 4X4_50 (the default).", show_default=False)
    ] = None,
    dist: Annotated[str | None, typer.Option(
        "--dist", help="Distortion coefficients k1,k2,p1,p2[,k3...].", show_default=False)] = None,
    edge_refine: Annotated[bool, typer.Option(
        "--edge-refine/--no-edge-refine",
        help="Refine corners by fitting lines to the marker's edges.")] = True,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    rig: Annotated[Path | None, typer.Option(
        "--rig", help="Take the camera's intrinsics and the marker from this rig file "
                      "(instead of --fx ... --dict).", show_default=False)] = None,
) -> None:
    """Detect ArUco markers in an image and estimate each one's pose (SOLVEPNP_IPPE_SQUARE)."""
    rig_camera: CameraIntrinsics | None = None
    if rig is not None:
        from relaxgrip.hardware.rig_file import load_rig

        given = [flag for flag, value in (("--fx", fx), ("--fy", fy), ("--cx", cx), ("--cy", cy),
                                          ("--dist", dist), ("--marker-mm", marker_mm),
                                          ("--dict", dictionary)) if value is not None]
        if given:
            raise InputError(f"--rig gives the camera and the marker: leave out {given[0]}")
        spec = load_rig(rig)
        rig_camera = spec.rgb.mount.intrinsics
        dictionary, marker_mm = spec.marker.dictionary, spec.marker.size_m * 1e3
    dictionary = "4X4_50" if dictionary is None else dictionary
    marker_mm = 12.0 if marker_mm is None else marker_mm
    name = dictionary.upper().removeprefix("DICT_")
    if name not in ARUCO_DICTIONARIES:
        raise InputError(f"--dict {dictionary!r} is not an ArUco dictionary; "
                         f"known: {', '.join(ARUCO_DICTIONARIES)}")
    if not (math.isfinite(marker_mm) and 0.1 <= marker_mm <= 10_000.0):
        raise InputError(f"--marker-mm must be 0.1-10000 mm, got {marker_mm}")
    gray = _read_gray(image)
    h, w = gray.shape
    if rig_camera is not None:
        if rig_camera.shape != (h, w):
            raise InputError(f"{image} is {w}x{h} pixels, the rig's RGB camera "
                             f"{rig_camera.width_px}x{rig_camera.height_px}")
        intrinsics = rig_camera
    else:
        focal = 600.0 if fx is None else fx
        intrinsics = CameraIntrinsics(
            w, h, focal, focal if fy is None else fy,
            (w - 1) / 2.0 if cx is None else cx, (h - 1) / 2.0 if cy is None else cy,
            _parse_dist(dist),
        )
    marker = MarkerMount(dictionary=name, size_m=marker_mm * 1e-3)
    solver = PoseSolver(marker.size_m, intrinsics)
    found = []
    for det in detect_markers(gray, make_detector(marker.aruco_dictionary)):
        corners = det.corners_px
        if edge_refine:
            refined = refine_corners_by_edges(
                gray, corners, intrinsics, modules=int(marker.aruco_dictionary.markerSize) + 2)
            corners = corners if refined is None else refined
        pose = solver.solve(corners)
        found.append({  # a marker whose corners give no pose is listed with none (null)
            "id": det.marker_id,
            "rvec": pose.rvec.tolist(),
            "tvec_m": pose.tvec_m.tolist(),
            "corners_px": corners.tolist(),
            "reprojection_px": pose.reprojection_px,
        })
    found.sort(key=lambda m: int(m["id"]))
    if json_out:
        emit_json({"image": str(image), "width_px": w, "height_px": h, "dictionary": name,
                   "marker_m": marker.size_m, "markers": found})
        return
    table = Table(title=f"{image.name}: {len(found)} marker(s), DICT_{name}, {marker_mm:g} mm")
    for col in ("id", "t (mm, camera frame)", "rvec (rad)", "distance (mm)", "reproj. (px)"):
        table.add_column(col, justify="right")
    for m in found:
        t = np.asarray(m["tvec_m"]) * 1e3
        table.add_row(str(m["id"]), " ".join(f"{v:8.2f}" for v in t),
                      " ".join(f"{v:7.4f}" for v in m["rvec"]), f"{np.linalg.norm(t):.1f}",
                      f"{m['reprojection_px']:.3f}")
    console.print(table)
