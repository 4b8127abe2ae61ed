"""The ChArUco calibration board: one description for the printed sheet, the twin and the detector.

A ChArUco board is a chessboard whose white squares hold ArUco markers, so
that every chessboard corner seen is identified even when the board is only
partly in view.  :class:`CharucoBoard` names its squares, their size, the
markers' size and dictionary; :attr:`CharucoBoard.cv_board` is OpenCV's
board (what :class:`cv2.aruco.CharucoDetector` and calibration match
against) and :meth:`CharucoBoard.black_rectangles` is the same board as
the black rectangles a printer lays down or the twin renders.  Both come
from OpenCV's own layout, so the sheet printed, the views rendered and the
corners detected cannot disagree.

Board frame (OpenCV's): origin at the board's top-left outer corner, ``x``
right along the columns, ``y`` down the rows, ``z`` into the board; lengths
in m.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.rig import ARUCO_DICTIONARIES

FloatArray = NDArray[np.float64]

__all__ = ["MAX_SQUARES", "CharucoBoard", "marker_rectangles", "parse_squares"]

#: The most squares along a side taken: a board of more is a typo, not a print.
MAX_SQUARES = 40


def parse_squares(text: str) -> tuple[int, int]:
    """``"7x5"`` as ``(7, 5)``: squares across and down.

    Raises
    ------
    InputError
        Not two integers joined by ``x``.
    """
    parts = text.lower().replace("×", "x").split("x")
    try:
        if len(parts) != 2:
            raise ValueError
        across, down = (int(p.strip()) for p in parts)
    except ValueError:
        raise InputError(f"--squares must be COLUMNSxROWS such as 7x5, got {text!r}") from None
    return across, down


def marker_rectangles(dictionary: cv2.aruco.Dictionary, marker_id: int,
                      top_left: tuple[float, float], size: float) -> FloatArray:
    """An ArUco marker's black modules as rectangles ``(x0, y0, x1, y1)`` in horizontal runs.

    Parameters
    ----------
    dictionary : cv2.aruco.Dictionary
        Its dictionary.
    marker_id : int
        Its id.
    top_left : (float, float)
        Where its black square's top-left corner is (``x`` right, ``y`` down).
    size : float
        Side of its black square (the same unit).

    Returns
    -------
    ndarray, shape (N, 4)
        The image :func:`cv2.aruco.generateImageMarker` draws, as rectangles.
    """
    modules = int(dictionary.markerSize) + 2
    # One pixel a module, black (0) where the marker is inked; row 0 is the marker's top.
    bits = cv2.aruco.generateImageMarker(dictionary, marker_id, modules, borderBits=1) < 128
    x0, y0 = top_left
    step = size / modules
    rects = []
    for r in range(modules):
        changes = np.flatnonzero(np.diff(np.r_[0, bits[r].astype(np.int8), 0]))
        for a, b in zip(changes[::2].tolist(), changes[1::2].tolist(), strict=True):
            rects.append([x0 + a * step, y0 + r * step, x0 + b * step, y0 + (r + 1) * step])
    return np.asarray(rects, dtype=np.float64).reshape(-1, 4)


@dataclass(frozen=True)
class CharucoBoard:
    """A ChArUco board.

    Attributes
    ----------
    squares_x, squares_y : int
        Squares across (columns) and down (rows), 3 to :data:`MAX_SQUARES`.
        The default 9x7 board of 10 mm squares is 90 x 70 mm: it fills most
        of the finger camera's view at the 60-200 mm where the camera is
        focused on the marker and the objects (focus changes the focal
        length, so the board is held where the camera is used).
    square_m : float
        Side of a chessboard square (m).
    marker_m : float
        Side of an ArUco marker's black square (m), smaller than ``square_m``.
    dictionary : str
        OpenCV dictionary name without ``DICT_`` (ids 0, 1, ... are used).
        The default differs from the finger marker's ``4X4_50``, so that
        neither is ever taken for the other.
    """

    squares_x: int = 9
    squares_y: int = 7
    square_m: float = 0.010
    marker_m: float = 0.007
    dictionary: str = "5X5_100"

    def __post_init__(self) -> None:
        for name in ("squares_x", "squares_y"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) \
                    or not 3 <= value <= MAX_SQUARES:
                raise InputError(f"a board needs 3 to {MAX_SQUARES} squares along each side, "
                                 f"got {self.squares_x}x{self.squares_y}")
        if not (math.isfinite(self.square_m) and 0.001 <= self.square_m <= 1.0):
            raise InputError(f"board square must be 1 to 1000 mm, got {self.square_m * 1e3:g} mm")
        if not (math.isfinite(self.marker_m) and 0.2 * self.square_m <= self.marker_m
                < 0.95 * self.square_m):
            raise InputError(f"board marker must be 20-95 % of the square "
                             f"({self.square_m * 1e3:g} mm), got {self.marker_m * 1e3:g} mm")
        if self.dictionary not in ARUCO_DICTIONARIES:
            raise InputError(f"unknown ArUco dictionary {self.dictionary!r} "
                             "(e.g. 4X4_50, 5X5_100)")
        available = int(self.aruco_dictionary.bytesList.shape[0])
        if self.n_markers > available:
            raise InputError(f"a {self.squares_x}x{self.squares_y} board needs {self.n_markers} "
                             f"markers; dictionary {self.dictionary} has {available}")

    @property
    def aruco_dictionary(self) -> cv2.aruco.Dictionary:
        """The OpenCV dictionary object."""
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, "DICT_" + self.dictionary))

    @property
    def n_markers(self) -> int:
        """Markers on the board: one in every white square."""
        return (self.squares_x * self.squares_y) // 2

    @property
    def n_corners(self) -> int:
        """Inner chessboard corners (the points calibration uses)."""
        return (self.squares_x - 1) * (self.squares_y - 1)

    @property
    def size_m(self) -> tuple[float, float]:
        """Width and height of the board's outer squares (m)."""
        return self.squares_x * self.square_m, self.squares_y * self.square_m

    @functools.cached_property
    def cv_board(self) -> cv2.aruco.CharucoBoard:
        """OpenCV's board (ids 0 to ``n_markers - 1``)."""
        return cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square_m,
                                      self.marker_m, self.aruco_dictionary)

    @property
    def corners_m(self) -> FloatArray:
        """The inner corners in the board frame, shape ``(n_corners, 3)``, in the ids'
        order (row by row from the top left)."""
        return np.asarray(self.cv_board.getChessboardCorners(), dtype=np.float64).reshape(-1, 3)

    def black_rectangles(self) -> FloatArray:
        """The board's black as axis-aligned rectangles ``(x0, y0, x1, y1)`` (m, board frame).

        The black chessboard squares, then each marker's black modules in
        horizontal runs.  They do not overlap; together they are exactly the
        image :meth:`cv2.aruco.CharucoBoard.generateImage` draws.

        Returns
        -------
        ndarray, shape (N, 4)
        """
        board = self.cv_board
        corners = [np.asarray(c, dtype=np.float64).reshape(4, 3) for c in board.getObjPoints()]
        ids = np.asarray(board.getIds()).ravel()
        s = self.square_m
        with_marker = {(int(c[:, 1].mean() // s), int(c[:, 0].mean() // s)) for c in corners}
        rects = [[col * s, row * s, (col + 1) * s, (row + 1) * s]
                 for row in range(self.squares_y) for col in range(self.squares_x)
                 if (row, col) not in with_marker]
        for marker_id, quad in zip(ids.tolist(), corners, strict=True):
            # The marker's first corner is its top left in the board frame.
            rects.extend(marker_rectangles(self.aruco_dictionary, int(marker_id),
                                           (float(quad[0, 0]), float(quad[0, 1])),
                                           self.marker_m).tolist())
        return np.asarray(rects, dtype=np.float64)

    def describe(self) -> str:
        """``9x7 squares of 10 mm, 7 mm markers, DICT_5X5_100 ids 0-30``."""
        return (f"{self.squares_x}x{self.squares_y} squares of {self.square_m * 1e3:g} mm, "
                f"{self.marker_m * 1e3:g} mm markers, DICT_{self.dictionary} ids "
                f"0-{self.n_markers - 1}")
