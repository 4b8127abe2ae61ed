"""The printable calibration sheet: the ChArUco board and the finger's marker at true scale.

The sheet is drawn in millimetres on a page of the paper's size, so a PDF
printed at 100 % puts every square where :class:`relaxgrip.board.CharucoBoard`
says it is: the page is the paper (its ``MediaBox`` in points, 72 to the
inch), and the black is vector rectangles.  The PNG is the same page at a
stated resolution (its ``pHYs`` chunk), for printers fed from an image.
The sheet says what is on it: the board's squares, sizes and dictionary and
the ``calibrate-camera`` options that describe it, the finger marker's
dictionary, id and size, and a 50 mm scale bar to check the print with a
ruler.
"""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from relaxgrip.board import CharucoBoard, marker_rectangles
from relaxgrip.errors import InputError
from relaxgrip.fileio import write_files_atomically
from relaxgrip.rig import MarkerMount

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["PAPER_SIZES_MM", "SCALE_BAR_MM", "sheet_figure", "sheet_options", "write_sheet"]

#: Paper sizes (width, height in portrait, mm).
PAPER_SIZES_MM: dict[str, tuple[float, float]] = {
    "A3": (297.0, 420.0),
    "A4": (210.0, 297.0),
    "A5": (148.0, 210.0),
    "letter": (215.9, 279.4),
    "legal": (215.9, 355.6),
}
#: Length of the scale bar (mm).
SCALE_BAR_MM = 50.0
#: Margin kept clear of the paper's edge, where printers do not print (mm).
_MARGIN_MM = 12.0
#: Room above the board for the sheet's text (mm).
_HEADER_MM = 34.0
#: Room below the board: the finger marker, the scale bar and their labels (mm).
_FOOTER_MM = 20.0
_MM_PER_INCH = 25.4


def sheet_options(board: CharucoBoard) -> str:
    """The ``calibrate-camera`` options that describe ``board``."""
    return (f"--squares {board.squares_x}x{board.squares_y} --square-mm {board.square_m * 1e3:g} "
            f"--marker-mm {board.marker_m * 1e3:g} --dictionary {board.dictionary}")


def _layout(board: CharucoBoard, marker: MarkerMount, paper: str) -> tuple[float, float]:
    """The page's width and height (mm): portrait, or landscape if only that fits."""
    if paper not in PAPER_SIZES_MM:
        raise InputError(f"unknown paper {paper!r}; known: {', '.join(PAPER_SIZES_MM)}")
    bw, bh = (v * 1e3 for v in board.size_m)
    quiet = marker.size_m * 1e3 * (1.0 + 2.0 / (marker.aruco_dictionary.markerSize + 2))
    need_w = max(bw, quiet + SCALE_BAR_MM + 20.0) + 2 * _MARGIN_MM
    need_h = _HEADER_MM + bh + max(_FOOTER_MM, quiet + 10.0) + 2 * _MARGIN_MM
    w, h = PAPER_SIZES_MM[paper]
    for page in ((w, h), (h, w)):
        if need_w <= page[0] and need_h <= page[1]:
            return page
    raise InputError(f"the board ({board.describe()}: {bw:g} x {bh:g} mm) and the "
                     f"{marker.size_m * 1e3:g} mm finger marker need {need_w:.0f} x "
                     f"{need_h:.0f} mm, more than {paper} ({w:g} x {h:g} mm) holds: choose a "
                     "larger --paper or smaller squares")


def _fill(ax: Axes, rects_mm: np.ndarray) -> None:
    """Fill rectangles ``(x0, y0, x1, y1)`` (mm) black, as one vector path."""
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path as MplPath

    x0, y0, x1, y1 = (rects_mm[:, k] for k in range(4))
    verts = np.stack([np.c_[x0, y0], np.c_[x1, y0], np.c_[x1, y1], np.c_[x0, y1],
                      np.c_[x0, y0]], axis=1).reshape(-1, 2)
    codes = np.tile([MplPath.MOVETO, MplPath.LINETO, MplPath.LINETO, MplPath.LINETO,
                     MplPath.CLOSEPOLY], len(rects_mm))
    path = MplPath(verts, codes)
    path.should_simplify = False  # every corner where it is, none merged
    ax.add_patch(PathPatch(path, facecolor="black", edgecolor="none", linewidth=0.0))


def sheet_figure(board: CharucoBoard, marker: MarkerMount, paper: str = "A4") -> Figure:
    """The calibration sheet as a figure of the paper's size, drawn in millimetres.

    Parameters
    ----------
    board : CharucoBoard
        The board.
    marker : MarkerMount
        The finger's marker (dictionary, id, size).
    paper : str
        A key of :data:`PAPER_SIZES_MM`.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    InputError
        An unknown paper, or a board and marker that do not fit on it.
    """
    from matplotlib.figure import Figure

    page_w, page_h = _layout(board, marker, paper)
    fig = Figure(figsize=(page_w / _MM_PER_INCH, page_h / _MM_PER_INCH))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0.0, page_w)
    ax.set_ylim(page_h, 0.0)  # y down, as the board frame
    ax.set_axis_off()
    bw, bh = (v * 1e3 for v in board.size_m)
    left, top = 0.5 * (page_w - bw), _MARGIN_MM + _HEADER_MM
    text: dict[str, Any] = {"fontsize": 8.0, "va": "top", "ha": "left", "family": "DejaVu Sans"}
    lines = [
        (f"relaxgrip ChArUco calibration board: {board.describe()}", 10.0),
        (f"board {bw:g} x {bh:g} mm, {board.n_corners} inner corners; "
         f"paper {paper} {page_w:g} x {page_h:g} mm", 8.0),
        ("Print at 100 % (no fit-to-page); check the scale bar and a square with a ruler, and "
         "give the measured sizes.", 8.0),
        ("Glue it flat on rigid card. relaxgrip calibrate-camera " + sheet_options(board), 8.0),
    ]
    y = _MARGIN_MM
    for line, size in lines:
        ax.text(_MARGIN_MM, y, line, **{**text, "fontsize": size})
        y += 6.0
    _fill(ax, board.black_rectangles() * 1e3 + np.array([left, top, left, top]))

    # The finger's marker with one white module round it, inside a grey cut line.
    size = marker.size_m * 1e3
    module = size / (marker.aruco_dictionary.markerSize + 2)
    mx, my = _MARGIN_MM + module, top + bh + 8.0 + module
    _fill(ax, marker_rectangles(marker.aruco_dictionary, marker.marker_id, (mx, my), size))
    from matplotlib.patches import Rectangle

    ax.add_patch(Rectangle((mx - module, my - module), size + 2 * module, size + 2 * module,
                           fill=False, edgecolor="0.6", linewidth=0.3, linestyle=(0, (3, 2))))
    label_x = mx + size + module + 4.0
    ax.text(label_x, my - module, f"finger marker: DICT_{marker.dictionary} id "
            f"{marker.marker_id}, {size:g} mm black square", **text)
    ax.text(label_x, my - module + 4.5, "cut on the grey line, keeping the white border",
            **text)
    # The scale bar: 50 mm with a tick every 10 mm.
    bar_y = my - module + 11.0
    bar = [[label_x, bar_y, label_x + SCALE_BAR_MM, bar_y + 0.5]]
    bar += [[label_x + k * 10.0 - 0.15, bar_y - 1.5, label_x + k * 10.0 + 0.15, bar_y]
            for k in range(math.floor(SCALE_BAR_MM / 10.0) + 1)]
    _fill(ax, np.asarray(bar))
    ax.text(label_x + SCALE_BAR_MM + 3.0, bar_y - 1.5, f"{SCALE_BAR_MM:g} mm", **text)
    return fig


def write_sheet(pdf_path: Path, png_path: Path, board: CharucoBoard, marker: MarkerMount,
                paper: str = "A4", dpi: int = 300) -> tuple[float, float]:
    """Write the sheet as a PDF and a PNG, each whole (atomically).

    Into one folder, both are written before either is renamed into place:
    a failure while writing leaves neither.

    Parameters
    ----------
    pdf_path, png_path : Path
        The files (in existing folders).
    board : CharucoBoard
        The board.
    marker : MarkerMount
        The finger's marker.
    paper : str
        A key of :data:`PAPER_SIZES_MM`.
    dpi : int
        The PNG's resolution (dots per inch).

    Returns
    -------
    (float, float)
        The page's width and height (mm).

    Raises
    ------
    InputError
        See :func:`sheet_figure`.
    OSError
        From the file system.
    """
    fig = sheet_figure(board, marker, paper)
    files = []
    for path, fmt, res in ((pdf_path, "pdf", 72), (png_path, "png", dpi)):
        buffer = io.BytesIO()
        # A fixed creation date and no software version: the same sheet gives the same bytes.
        metadata = {"CreationDate": None} if fmt == "pdf" else {"Software": None}
        fig.savefig(buffer, format=fmt, dpi=res, metadata=metadata)
        files.append((Path(path), buffer.getvalue()))
    if files[0][0].parent == files[1][0].parent:
        write_files_atomically(files[0][0].parent, [(p.name, data) for p, data in files])
    else:
        for path, data in files:
            write_files_atomically(path.parent, [(path.name, data)])
    w_in, h_in = fig.get_size_inches()
    return float(w_in) * _MM_PER_INCH, float(h_in) * _MM_PER_INCH
