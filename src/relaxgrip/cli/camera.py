"""``relaxgrip make-board``, ``calibrate-camera`` and ``zero-pose``: a rig's RGB camera, measured.

``make-board`` prints the ChArUco board and the finger's marker at true
scale; ``calibrate-camera`` fits the camera's intrinsics and distortion to
views of the board (a folder of images, or the rig's camera live) and
writes them into the rig file; ``zero-pose`` measures where the marker sits
on the unloaded, cold finger and writes that too.  See
``docs/camera-calibration.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
import typer
from rich.table import Table
from rich.text import Text

from relaxgrip.cli._app import app, console, emit_json, err_console, float_option, int_option
from relaxgrip.errors import InputError

if TYPE_CHECKING:
    from relaxgrip.backend import Gripper
    from relaxgrip.board import CharucoBoard
    from relaxgrip.clock import Clock
    from relaxgrip.hardware.cameras import FrameSource
    from relaxgrip.hardware.rig_file import RigFile
    from relaxgrip.perception.camera_calibration import BoardView, CameraCalibration
    from relaxgrip.perception.zero_pose import ZeroPose
    from relaxgrip.rig import MarkerMount

__all__ = ["IMAGE_SUFFIXES", "calibrate_camera_command", "make_board", "zero_pose_command"]

PANEL = "Rig bring-up"
#: Image files ``calibrate-camera`` reads from a folder.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm")
#: The most images read from a folder: a calibration needs tens.
MAX_IMAGES = 1000
#: A live view is kept only if its corners moved less than this since the last frame (px).
_STILL_PX = 1.0
#: Least time between two views kept live (s).
_LIVE_GAP_S = 0.5
#: A live view adds coverage if it reaches this share of the image not reached before.
_NEW_COVERAGE = 0.02
#: Tilted views wanted live in each of the four directions (left, down, right, up).
_PER_DIRECTION = 2


def _board(squares: str, square_mm: float, marker_mm: float, dictionary: str) -> CharucoBoard:
    from relaxgrip.board import CharucoBoard, parse_squares

    across, down = parse_squares(squares)
    return CharucoBoard(across, down, square_mm * 1e-3, marker_mm * 1e-3,
                        dictionary.upper().removeprefix("DICT_"))


def _board_options() -> dict[str, Any]:
    return {
        "squares": typer.Option("--squares", help="Board squares, COLUMNSxROWS."),
        "square_mm": float_option("--square-mm", help="Side of a square (mm; as printed)."),
        "marker_mm": float_option("--marker-mm", help="Side of a board marker (mm; as printed)."),
        "dictionary": typer.Option("--dictionary", help="The board markers' ArUco dictionary."),
    }


_OPT = _board_options()


# -- make-board ---------------------------------------------------------------------------

def _finger_marker(rig: Path | None, marker_dict: str | None, marker_id: int | None,
                   marker_size_mm: float | None) -> MarkerMount:
    from relaxgrip.hardware.rig_file import load_rig
    from relaxgrip.rig import MarkerMount

    if rig is not None:
        if (marker_dict, marker_id, marker_size_mm) != (None, None, None):
            raise InputError("give the finger marker by --rig or by --marker-dict, --marker-id "
                             "and --marker-size-mm, not both")
        return load_rig(rig).marker
    dictionary = (marker_dict or "4X4_50").upper().removeprefix("DICT_")
    size = 12.0 if marker_size_mm is None else marker_size_mm
    if not (math.isfinite(size) and 1.0 <= size <= 200.0):
        raise InputError(f"--marker-size-mm must be 1 to 200 mm, got {size:g}")
    mount = MarkerMount(dictionary=dictionary, size_m=size * 1e-3)
    ident = 0 if marker_id is None else marker_id
    n_ids = int(mount.aruco_dictionary.bytesList.shape[0])
    if not 0 <= ident < n_ids:
        raise InputError(f"--marker-id must be 0 to {n_ids - 1} for DICT_{dictionary}, "
                         f"got {ident}")
    return MarkerMount(dictionary=dictionary, marker_id=ident, size_m=size * 1e-3)


@app.command("make-board", rich_help_panel=PANEL)
def make_board(
    out: Annotated[Path, typer.Option(
        "--out", help="Where to write: OUT.pdf and OUT.png (a .pdf or .png suffix is dropped).")
    ] = Path("charuco-board"),
    paper: Annotated[str, typer.Option("--paper", help="A3, A4, A5, letter or legal.")] = "A4",
    squares: Annotated[str, _OPT["squares"]] = "9x7",
    square_mm: Annotated[float, _OPT["square_mm"]] = 10.0,
    marker_mm: Annotated[float, _OPT["marker_mm"]] = 7.0,
    dictionary: Annotated[str, _OPT["dictionary"]] = "5X5_100",
    rig: Annotated[Path | None, typer.Option(
        "--rig", help="Rig file whose \\[marker] (dictionary, id, size) is printed.",
        show_default=False)] = None,
    marker_dict: Annotated[str | None, typer.Option(
        "--marker-dict", help="Finger marker's dictionary without --rig (default 4X4_50).",
        show_default=False)] = None,
    marker_id: Annotated[int | None, int_option(
        "--marker-id", help="Finger marker's id without --rig (default 0).",
        show_default=False)] = None,
    marker_size_mm: Annotated[float | None, float_option(
        "--marker-size-mm", help="Finger marker's black square without --rig (mm; default 12).",
        show_default=False)] = None,
    dpi: Annotated[int, int_option("--dpi", help="The PNG's resolution (dots per inch).")] = 300,
) -> None:
    """Write a printable ChArUco board and the finger's marker at true scale (PDF and PNG)."""
    from relaxgrip.fileio import check_writable
    from relaxgrip.plots.board_sheet import PAPER_SIZES_MM, sheet_options, write_sheet

    if paper not in PAPER_SIZES_MM:
        raise InputError(f"--paper must be one of {', '.join(PAPER_SIZES_MM)}, got {paper!r}")
    if not 72 <= dpi <= 1200:
        raise InputError(f"--dpi must be 72 to 1200, got {dpi}")
    board = _board(squares, square_mm, marker_mm, dictionary)
    marker = _finger_marker(rig, marker_dict, marker_id, marker_size_mm)
    stem = out.with_suffix("") if out.suffix.lower() in (".pdf", ".png") else out
    pdf, png = Path(f"{stem}.pdf"), Path(f"{stem}.png")
    for path in (pdf, png):
        if not path.parent.is_dir():
            raise InputError(f"{path}: directory {path.parent} does not exist")
        check_writable(path, InputError)
    width_mm, height_mm = write_sheet(pdf, png, board, marker, paper, dpi)
    console.print(f"wrote {pdf} and {png} ({paper}, {width_mm:.0f} x {height_mm:.0f} mm; PNG at "
                  f"{dpi} dpi)", highlight=False, markup=False, soft_wrap=True)
    console.print(f"board: {board.describe()}", highlight=False, markup=False)
    console.print(f"finger marker: DICT_{marker.dictionary} id {marker.marker_id}, "
                  f"{marker.size_m * 1e3:g} mm", highlight=False, markup=False)
    console.print(f"print at 100 %, measure a square, then: relaxgrip calibrate-camera DIR "
                  f"{sheet_options(board)}", highlight=False, markup=False, soft_wrap=True)


# -- calibrate-camera ---------------------------------------------------------------------

def _image_files(folder: Path) -> list[Path]:
    if not folder.exists():
        raise InputError(f"{folder}: no such folder of board images")
    if not folder.is_dir():
        raise InputError(f"{folder}: is not a folder (give the folder of board images)")
    try:
        files = sorted(p for p in folder.iterdir()
                       if p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith("."))
    except OSError as exc:
        raise InputError(f"{folder}: cannot list it ({exc.strerror or exc})") from None
    if not files:
        raise InputError(f"{folder}: no image files ({', '.join(IMAGE_SUFFIXES)})")
    if len(files) > MAX_IMAGES:
        raise InputError(f"{folder}: {len(files)} images, at most {MAX_IMAGES} are read")
    return files


def _views_from_folder(folder: Path, board: CharucoBoard
                       ) -> tuple[list[BoardView], tuple[int, int], list[str]]:
    """The board in every image of the folder; the images' size; the images without it."""
    from relaxgrip.cli.perceive import _read_gray  # the reader ``perceive`` uses: EXIF, depth
    from relaxgrip.perception.camera_calibration import detect_board, make_board_detector

    files = _image_files(folder)
    detector = make_board_detector(board)
    views, missing = [], []
    size: tuple[int, int] | None = None
    first = ""
    for path in files:
        gray = _read_gray(path)
        h, w = gray.shape
        if size is None:
            size, first = (w, h), path.name
        elif (w, h) != size:
            raise InputError(f"{path}: is {w}x{h}, {first} is {size[0]}x{size[1]}: give the "
                             "views of one camera at one resolution")
        view = detect_board(gray, board, path.name, detector=detector)
        if view is None:
            missing.append(path.name)
        else:
            views.append(view)
    assert size is not None
    if not views:
        raise InputError(f"{folder}: no ChArUco board ({board.describe()}) found in any of its "
                         f"{len(files)} images: check --squares, --square-mm, --marker-mm and "
                         "--dictionary against the printed sheet")
    return views, size, missing


@dataclass
class _LiveState:
    """The views a live calibration has kept, and what they cover."""

    target: int
    min_views: int
    image_size: tuple[int, int]
    min_coverage: float
    min_tilt_deg: float
    views: list[BoardView] = field(default_factory=list)
    images: list[np.ndarray] = field(default_factory=list)
    directions: list[int] = field(default_factory=lambda: [0, 0, 0, 0])
    coverage: float = 0.0
    frames: int = 0
    status: str = "waiting for the first frame"
    last_kept_s: float = -math.inf

    def done(self) -> bool:
        """``target`` views, or enough of them tilted every way over enough of the image."""
        return len(self.views) >= self.target or (
            len(self.views) >= self.min_views and self.coverage >= self.min_coverage
            and min(self.directions) >= _PER_DIRECTION)

    def table(self) -> Table:
        table = Table(title="calibrate-camera: views from the rig's RGB camera", show_header=False)
        table.add_column("what")
        table.add_column("value")
        table.add_row("views kept", f"{len(self.views)} of {self.target}")
        table.add_row("image coverage", f"{100 * self.coverage:.0f} % "
                      f"(at least {100 * self.min_coverage:.0f} %)")
        left, down, right, up = self.directions
        table.add_row(f"tilted ≥ {self.min_tilt_deg:g}°",
                      f"left {left}, right {right}, up {up}, down {down} "
                      f"({_PER_DIRECTION} each wanted)")
        table.add_row("frames", str(self.frames))
        table.add_row("last frame", self.status)
        return table


def _tilt_bin(view: BoardView, board: CharucoBoard, rig: RigFile, min_tilt_deg: float
              ) -> int | None:
    """Which way the board leans (0 left, 1 down, 2 right, 3 up in the image), by the rig
    file's present intrinsics; None if it is nearly face-on or no pose is found."""
    import cv2

    from relaxgrip.perception.camera_calibration import board_tilt

    intr = rig.rgb.mount.intrinsics
    ok, rvec, _ = cv2.solvePnP(board.corners_m[view.ids], view.corners_px, intr.matrix,
                               intr.dist_coeffs)
    if not ok:
        return None
    tilt, direction = board_tilt(np.asarray(rvec, dtype=np.float64).ravel())
    if tilt < min_tilt_deg:
        return None
    return int(((direction + 180.0 + 45.0) % 360.0) // 90.0)


def _collect_live(source: FrameSource, clock: Clock, board: CharucoBoard, rig: RigFile,
                  state: _LiveState, max_s: float) -> None:
    """Keep still views of the board that add coverage or tilt, showing progress."""
    from rich.live import Live

    from relaxgrip.perception.camera_calibration import (
        coverage_mask,
        detect_board,
        make_board_detector,
    )
    from relaxgrip.perception.marker import to_gray

    detector = make_board_detector(board)
    previous: BoardView | None = None
    last_seq: int | None = None
    start = clock.now()
    with Live(state.table(), console=err_console, refresh_per_second=4,
              transient=False) as live:
        while not state.done() and clock.now() - start < max_s:
            now = clock.now()
            frame = source.read(now)
            if frame is None or frame.seq == last_seq:
                clock.sleep_until(now + 0.01)
                continue
            last_seq = frame.seq
            state.frames += 1
            image = np.asarray(frame.image, dtype=np.uint8)
            view = detect_board(to_gray(image), board, f"live {state.frames}", detector=detector)
            state.status, keep, direction = _judge_live(view, previous, state, board, rig, now)
            previous = view
            if keep and view is not None:
                if direction is not None:
                    state.directions[direction] += 1
                state.views.append(view)
                state.images.append(image)
                state.coverage = float(coverage_mask(state.views, state.image_size).mean())
                state.last_kept_s = now
            live.update(state.table())


def _judge_live(view: BoardView | None, previous: BoardView | None, state: _LiveState,
                board: CharucoBoard, rig: RigFile, now: float
                ) -> tuple[str, bool, int | None]:
    """What a live frame shows, whether it is kept, and which way it is tilted."""
    from relaxgrip.perception.camera_calibration import coverage_mask

    if view is None:
        return "no board", False, None
    if previous is None:
        return f"board, {view.n_corners} corners: hold it still", False, None
    common, here, there = np.intersect1d(view.ids, previous.ids, return_indices=True)
    if common.size < 4:
        return f"board, {view.n_corners} corners: hold it still", False, None
    moved = float(np.linalg.norm(view.corners_px[here] - previous.corners_px[there],
                                 axis=1).max())
    if moved > _STILL_PX:
        return f"board moving ({moved:.1f} px a frame): hold it still", False, None
    if now - state.last_kept_s < _LIVE_GAP_S:
        return f"board, {view.n_corners} corners, still", False, None
    direction = _tilt_bin(view, board, rig, state.min_tilt_deg)
    gained = (float(coverage_mask([*state.views, view], state.image_size).mean())
              - state.coverage)
    wanted_tilt = direction is not None and state.directions[direction] < _PER_DIRECTION
    if gained < _NEW_COVERAGE and not wanted_tilt and len(state.views) >= 3:
        return f"board, {view.n_corners} corners: nothing new here, move or tilt it", False, None
    return f"kept: {view.n_corners} corners", True, direction


def _save_views(folder: Path, images: list[np.ndarray]) -> None:
    import cv2

    from relaxgrip.fileio import made_directory, write_files_atomically

    files = []
    for k, image in enumerate(images):
        ok, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        if not ok:  # pragma: no cover - an RGB uint8 frame always encodes
            raise InputError(f"cannot encode view {k} as PNG")
        files.append((f"view-{k:03d}.png", data.tobytes()))
    with made_directory(folder):
        write_files_atomically(folder, files)


def _new_clock() -> Clock:
    """The live collection's clock; tests replace it."""
    from relaxgrip.clock import WallClock

    return WallClock()


def _open_rgb_source(rig: RigFile, clock: Clock) -> FrameSource:
    """The rig's RGB camera (not started); tests replace it."""
    from relaxgrip.hardware.cameras import open_frame_sources

    return open_frame_sources(rig, clock)[0]


def _print_calibration(result: CameraCalibration, missing: list[str]) -> None:
    table = Table(title=f"{len(result.views)} views, {result.board.describe()}")
    for col in ("view", "corners", "dropped", "RMS (px)", "tilt (°)", "distance (mm)"):
        table.add_column(col, justify="left" if col == "view" else "right")
    worst = 3.0 * float(np.median([v.rms_px for v in result.views]))
    for v in result.views:
        flag = " !" if v.rms_px > worst else ""
        table.add_row(Text(v.name), str(v.n_corners), str(v.n_dropped), f"{v.rms_px:.3f}{flag}",
                      f"{v.tilt_deg:.0f}", f"{v.distance_m * 1e3:.0f}")
    console.print(table)
    intr = result.intrinsics
    sfx, sfy, scx, scy = result.std_px
    lines = [
        f"RMS reprojection error {result.rms_px:.3f} px over "
        f"{sum(v.n_corners for v in result.views)} corners ({result.n_dropped} dropped as "
        "outliers); ! marks a view over 3x the median",
        f"image {intr.width_px}x{intr.height_px}, coverage {100 * result.coverage:.0f} %",
        f"fx_px = {intr.fx_px:.3f} ± {sfx:.3f}   fy_px = {intr.fy_px:.3f} ± {sfy:.3f}",
        f"cx_px = {intr.cx_px:.3f} ± {scx:.3f}   cy_px = {intr.cy_px:.3f} ± {scy:.3f}",
        f"dist = [{', '.join(f'{d:.6g}' for d in intr.dist)}]   ({result.model})",
    ]
    if missing:
        lines.append(f"no board in {len(missing)} image(s): {', '.join(missing[:8])}"
                     f"{', ...' if len(missing) > 8 else ''}")
    for line in lines:
        console.print(line, highlight=False, markup=False, soft_wrap=True)


@app.command("calibrate-camera", rich_help_panel=PANEL)
def calibrate_camera_command(
    images: Annotated[Path | None, typer.Argument(
        metavar="[IMAGES]", help="Folder of board images (or --rig RIG.toml --live).",
        show_default=False)] = None,
    rig: Annotated[Path | None, typer.Option(
        "--rig", help="Rig file: its RGB camera (--live), its image size, where --write goes.",
        show_default=False)] = None,
    live: Annotated[bool, typer.Option(
        "--live", help="Grab the views from the rig's RGB camera.")] = False,
    write: Annotated[bool, typer.Option(
        "--write", help="Write the intrinsics and distortion into the rig file's \\[rgb].")
    ] = False,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    squares: Annotated[str, _OPT["squares"]] = "9x7",
    square_mm: Annotated[float, _OPT["square_mm"]] = 10.0,
    marker_mm: Annotated[float, _OPT["marker_mm"]] = 7.0,
    dictionary: Annotated[str, _OPT["dictionary"]] = "5X5_100",
    model: Annotated[str, typer.Option(
        "--dist-model", help="k1k2p1p2, k1k2p1p2k3 or rational (8 coefficients).")
    ] = "k1k2p1p2k3",
    min_views: Annotated[int, int_option(
        "--min-views", help="Fewest views with the board to calibrate from.")] = 12,
    views_wanted: Annotated[int, int_option(
        "--views", help="Most views to collect live (fewer, from --min-views, once they cover "
                        "the image tilted every way).")] = 25,
    max_s: Annotated[float, float_option(
        "--max-s", help="Longest live collection (s).")] = 600.0,
    save_views: Annotated[Path | None, typer.Option(
        "--save-views", help="Save the live views kept into this new folder (PNG).",
        show_default=False)] = None,
) -> None:
    """Fit the RGB camera's intrinsics and distortion to views of the ChArUco board.

    Refuses a poorly constrained calibration (too few views, too little image
    coverage or tilt, too uncertain, too large an error), saying which.
    """
    from relaxgrip.fileio import check_output_dir
    from relaxgrip.hardware.rig_write import read_rig_for_edit
    from relaxgrip.perception.camera_calibration import (
        DIST_MODELS,
        CalibrationLimits,
        calibrate_camera,
    )

    if (images is None) == (not live):
        raise InputError("give a folder of board images, or --rig RIG.toml --live (not both)")
    if (live or write) and rig is None:
        raise InputError(f"{'--live' if live else '--write'} needs --rig RIG.toml")
    if model not in DIST_MODELS:
        raise InputError(f"--dist-model must be one of {', '.join(DIST_MODELS)}, got {model!r}")
    if not 3 <= min_views <= MAX_IMAGES:
        raise InputError(f"--min-views must be 3 to {MAX_IMAGES}, got {min_views}")
    if live and not min_views <= views_wanted <= MAX_IMAGES:
        raise InputError(f"--views must be --min-views ({min_views}) to {MAX_IMAGES}, "
                         f"got {views_wanted}")
    if not (math.isfinite(max_s) and 1.0 <= max_s <= 3600.0):
        raise InputError(f"--max-s must be 1 to 3600 s, got {max_s:g}")
    if save_views is not None:
        if not live:
            raise InputError("--save-views is for --live (a folder's images are saved already)")
        if save_views.exists() and (not save_views.is_dir() or any(save_views.iterdir())):
            raise InputError(f"--save-views {save_views} exists and is not an empty folder")
        check_output_dir(save_views, "views", (), InputError)
    board = _board(squares, square_mm, marker_mm, dictionary)
    limits = CalibrationLimits(min_views=min_views)
    spec: RigFile | None = None
    text = ""
    if rig is not None:
        spec, text = read_rig_for_edit(rig)
    if write:
        from relaxgrip.hardware.rig_write import check_rig_writable

        assert rig is not None
        check_rig_writable(rig)  # before the views are taken, not after
    missing: list[str] = []
    if live:
        assert spec is not None
        intr = spec.rgb.mount.intrinsics
        clock = _new_clock()
        source = _open_rgb_source(spec, clock)
        state = _LiveState(views_wanted, min_views, (intr.width_px, intr.height_px),
                           limits.min_coverage, limits.min_tilt_deg)
        source.start()
        try:
            _collect_live(source, clock, board, spec, state, max_s)
        finally:
            source.close()
        if save_views is not None and state.images:
            _save_views(save_views, state.images)
        views, size = state.views, state.image_size
    else:
        assert images is not None
        views, size, missing = _views_from_folder(images, board)
    if spec is not None:
        intr = spec.rgb.mount.intrinsics
        if size != (intr.width_px, intr.height_px):
            raise InputError(f"the views are {size[0]}x{size[1]}, the rig file's [rgb] camera "
                             f"is {intr.width_px}x{intr.height_px}: take the views at the "
                             "resolution the rig uses")
    if len(views) < limits.min_views:
        without = f" ({len(missing)} images without it)" if missing else ""
        raise InputError(f"too few views: the board is in {len(views)}{without}, at least "
                         f"{limits.min_views} needed: take more, in every part of the view")
    result = calibrate_camera(views, size, board, model=model, limits=limits)
    removed = False
    if write:
        assert rig is not None
        removed = _write_intrinsics(rig, text, result)
    if json_out:
        emit_json({**result.to_dict(), "images_without_board": missing,
                   "written": str(rig) if write else None, "zero_pose_removed": removed})
        return
    _print_calibration(result, missing)
    if write:
        console.print(f"wrote fx_px, fy_px, cx_px, cy_px and dist into [rgb] of {rig}",
                      highlight=False, markup=False, soft_wrap=True)
        if removed:
            console.print("removed [zero_pose]: it was measured through the old intrinsics; "
                          f"measure it again: relaxgrip zero-pose --rig {rig} --write",
                          highlight=False, markup=False, soft_wrap=True)


def _write_intrinsics(rig: Path, text: str, result: CameraCalibration) -> bool:
    """Write the calibration into the rig file; whether a zero pose was dropped with it."""
    from relaxgrip.hardware.rig_write import remove_zero_pose, set_rgb_intrinsics, update_rig_file

    removed: list[bool] = []

    def edit(doc: Any) -> None:
        set_rgb_intrinsics(doc, result.intrinsics)
        removed.append(remove_zero_pose(doc))

    update_rig_file(rig, text, edit)
    return removed[0]


# -- zero-pose ----------------------------------------------------------------------------

def _open_gripper(rig: RigFile) -> tuple[Gripper, Clock]:
    """The rig's gripper, reset (cameras streaming), and its clock; tests replace it."""
    from relaxgrip.clock import WallClock
    from relaxgrip.hardware.gripper import open_rig_gripper

    clock = WallClock()
    gripper = open_rig_gripper(rig, clock)
    try:
        gripper.reset()
    except BaseException:
        gripper.close()
        raise
    return gripper, clock


def _print_zero_pose(zero: ZeroPose) -> None:
    d = zero.to_dict()
    force = "no force reference" if zero.max_force_n is None else f"{zero.max_force_n:.3f} N"
    temp = "no infrared frame" if d["finger_temp_c"] is None else f"{zero.finger_temp_c:.1f} °C"
    lines = [
        f"marker at rest over {zero.frames} of {zero.frames_seen} frames: position_mm = "
        f"[{', '.join(f'{v:.4f}' for v in d['position_mm'])}], rotation_deg = "
        f"[{', '.join(f'{v:.4f}' for v in d['rotation_deg'])}]",
        f"spread {d['spread_mm']:.4f} mm, {d['spread_deg']:.4f}°; force reference {force}; "
        f"warmest finger {temp}",
        f"{d['offset_from_mounts_mm']:.2f} mm from where the rig file's mounts put the marker",
    ]
    for line in lines:
        console.print(line, highlight=False, markup=False, soft_wrap=True)


@app.command("zero-pose", rich_help_panel=PANEL)
def zero_pose_command(
    rig: Annotated[Path, typer.Option("--rig", help="Rig file (TOML).", show_default=False)],
    write: Annotated[bool, typer.Option(
        "--write", help="Write the zero pose into the rig file's \\[zero_pose].")] = False,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    frames: Annotated[int, int_option("--frames", help="RGB frames averaged.")] = 30,
    max_force_n: Annotated[float, float_option(
        "--max-force-n", help="Largest force-reference reading at rest (N).")] = 0.1,
    max_temp_c: Annotated[float, float_option(
        "--max-temp-c", help="Warmest finger at rest (°C).")] = 35.0,
    max_spread_mm: Annotated[float, float_option(
        "--max-spread-mm", help="Farthest a frame's marker may lie from the mean (mm).")] = 0.1,
    max_spread_deg: Annotated[float, float_option(
        "--max-spread-deg", help="Farthest a frame's marker may turn from the mean (°).")] = 0.3,
    no_force_ref: Annotated[bool, typer.Option(
        "--no-force-ref", help="The rig has no force reference: nothing touches the fingers "
                               "(checked by eye).")] = False,
) -> None:
    """Measure the marker's pose on the unloaded, cold finger: perception's reference.

    Refuses unless the gripper is at rest: heaters off and fingers cool, the
    force reference near zero, the marker found and still over the frames.
    """
    from relaxgrip.hardware.rig_file import ZeroPoseSpec
    from relaxgrip.hardware.rig_write import read_rig_for_edit
    from relaxgrip.perception.zero_pose import ZeroPoseLimits, measure_zero_pose

    limits = ZeroPoseLimits(frames=frames, max_force_n=max_force_n, max_temp_c=max_temp_c,
                            max_spread_mm=max_spread_mm, max_spread_deg=max_spread_deg)
    spec, text = read_rig_for_edit(rig)
    if write:
        from relaxgrip.hardware.rig_write import check_rig_writable

        check_rig_writable(rig)
    gripper, clock = _open_gripper(spec)
    try:
        zero = measure_zero_pose(gripper, clock, spec.geometry, limits,
                                 require_force_ref=not no_force_ref)
    finally:
        gripper.close()  # motor stopped, heaters off
    if write:
        from relaxgrip.hardware.rig_write import set_zero_pose, update_rig_file

        record = ZeroPoseSpec(zero.position_m, zero.rotation_rvec, zero.frames, zero.spread_m)
        update_rig_file(rig, text, lambda doc: set_zero_pose(doc, record))
    if json_out:
        emit_json({**zero.to_dict(), "written": str(rig) if write else None})
        return
    _print_zero_pose(zero)
    if write:
        console.print(f"wrote [zero_pose] into {rig}", highlight=False, markup=False,
                      soft_wrap=True)
