"""The ChArUco board: its black rectangles are OpenCV's board, pixel for pixel."""

from __future__ import annotations

import numpy as np
import pytest

from relaxgrip.board import CharucoBoard, marker_rectangles, parse_squares
from relaxgrip.errors import InputError


def _raster(rects_m: np.ndarray, shape: tuple[int, int], px_per_m: float) -> np.ndarray:
    img = np.full(shape, 255, np.uint8)
    for x0, y0, x1, y1 in np.rint(rects_m * px_per_m).astype(int):
        img[y0:y1, x0:x1] = 0
    return img


@pytest.mark.parametrize(("board", "px_per_m"), [
    (CharucoBoard(), 2e4),
    (CharucoBoard(7, 5, 0.035, 0.028, "4X4_50"), 6e3),
    (CharucoBoard(6, 8, 0.014, 0.007, "6X6_250"), 8e3),  # more rows than columns, even rows
])
def test_black_rectangles_draw_opencvs_board(board: CharucoBoard, px_per_m: float) -> None:
    # At these scales squares, modules and the markers' margins are whole pixels: every
    # rectangle's edge falls on a pixel's, so the raster is exact.
    w, h = (round(v * px_per_m) for v in board.size_m)
    expected = board.cv_board.generateImage((w, h), marginSize=0, borderBits=1)
    drawn = _raster(board.black_rectangles(), (h, w), px_per_m)
    assert np.array_equal(drawn, expected)


def test_rectangles_do_not_overlap_and_corners_are_inner() -> None:
    board = CharucoBoard()
    rects = board.black_rectangles()
    area = float(((rects[:, 2] - rects[:, 0]) * (rects[:, 3] - rects[:, 1])).sum())
    drawn = _raster(rects, (1400, 1800), 2e4)
    assert area * 2e4**2 == pytest.approx(float((drawn == 0).sum()), rel=1e-9)
    corners = board.corners_m
    assert corners.shape == (board.n_corners, 3) == (48, 3)
    assert corners[:, 0].min() == pytest.approx(board.square_m)
    assert corners[:, 1].max() == pytest.approx(board.size_m[1] - board.square_m)


def test_marker_rectangles_are_the_marker_image() -> None:
    board = CharucoBoard()
    import cv2

    dictionary = board.aruco_dictionary
    rects = marker_rectangles(dictionary, 3, (0.0, 0.0), 7.0)  # one unit a module
    drawn = _raster(rects, (7, 7), 1.0)
    assert np.array_equal(drawn, cv2.aruco.generateImageMarker(dictionary, 3, 7, borderBits=1))


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"squares_x": 2}, "3 to 40 squares"),
    ({"squares_y": 41}, "3 to 40 squares"),
    ({"marker_m": 0.0099}, "20-95 % of the square"),
    ({"square_m": 0.0}, "board square must be 1 to 1000 mm"),
    ({"dictionary": "5X5"}, "unknown ArUco dictionary"),
    ({"squares_x": 20, "squares_y": 20, "dictionary": "4X4_50"}, "needs 200 markers"),
])
def test_bad_boards_are_refused(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(InputError, match=message):
        CharucoBoard(**kwargs)  # type: ignore[arg-type]


def test_parse_squares() -> None:
    assert parse_squares("9x7") == (9, 7)
    assert parse_squares(" 5 X 4 ") == (5, 4)
    for bad in ("9", "9x", "x7", "9x7x2", "ninexseven"):
        with pytest.raises(InputError, match="COLUMNSxROWS"):
            parse_squares(bad)
