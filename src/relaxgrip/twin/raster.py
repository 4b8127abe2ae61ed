"""Exact pixel-area coverage of polygons, as a font rasteriser computes it.

A camera pixel integrates the light that falls on its area, so the image of
a sharp printed edge is the fraction of each pixel the ink covers.
:func:`area_coverage` computes that fraction exactly for any set of
straight-edged polygons, with no supersampling: the signed-area
accumulation of font rasterisers (FreeType's, font-rs).  Each edge is cut
where it crosses a pixel boundary; a piece inside one pixel adds, to that
pixel, its height times the share of the pixel's width to its right, and
its full height to every pixel further right along the row.  Summed over a
closed outline, that is the area of the pixel the outline encloses.

Pixel centres are at integers (OpenCV's convention): pixel ``(r, c)`` is
the square ``[c - 1/2, c + 1/2] x [r - 1/2, r + 1/2]``.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

__all__ = ["area_coverage"]


def area_coverage(
    edges: ArrayLike,
    weights: ArrayLike,
    shape: tuple[int, int],
    plane: ArrayLike | None = None,
    planes: int = 1,
) -> FloatArray:
    """The weighted area of each pixel that closed polygons cover.

    Parameters
    ----------
    edges : array_like, shape (2, N, 2)
        The polygons' directed edges: ``edges[0][i]`` to ``edges[1][i]``,
        (x, y) in pixels.  Every polygon must be closed; edges may come in
        any order.  A polygon that runs clockwise on the screen (x right, y
        down), as ``(0, 0), (1, 0), (1, 1), (0, 1)`` does, counts with its
        weight, one that runs the other way with minus its weight.
    weights : array_like, shape (N,)
        Each edge's weight: the same for every edge of one polygon.
    shape : (rows, cols)
        The grid.  Polygons may reach outside it: what lies outside is
        clipped.
    plane : array_like of int, shape (N,), optional
        The output plane each edge adds to (default all 0).
    planes : int
        Number of output planes.

    Returns
    -------
    ndarray, shape (planes, rows, cols)
        Per plane, the sum over polygons of weight times the area of each
        pixel they cover (pixels have area 1).
    """
    rows, cols = shape
    ends = np.asarray(edges, dtype=np.float64)
    if ends.ndim != 3 or ends.shape[0] != 2 or ends.shape[2] != 2:
        raise ValueError(f"edges must have shape (2, N, 2), got {ends.shape}")
    n = ends.shape[1]
    # A column for a piece on the grid's right edge and one for its spill; a row above
    # and one below the grid for the pieces outside it.
    width, height = cols + 2, rows + 2
    size = planes * height * width
    out: FloatArray = np.zeros(size)
    if n and rows > 0 and cols > 0:
        x0, y0 = ends[0, :, 0] + 0.5, ends[0, :, 1] + 0.5  # pixel (r, c) is now [c, c+1] x [r, r+1]
        dx, dy = ends[1, :, 0] - ends[0, :, 0], ends[1, :, 1] - ends[0, :, 1]
        # The area to the right of a piece going down by dy, in units of the screen:
        # minus dy, so that a clockwise outline counts positive.
        fall = -dy * np.asarray(weights, dtype=np.float64)
        base = np.zeros(n, np.intp) if plane is None else np.asarray(plane, np.intp) * height
        t_a, t_b, edge = _pieces(x0, y0, dx, dy, rows, cols)
        t_mid = 0.5 * (t_a + t_b)
        x = np.clip(x0[edge] + t_mid * dx[edge], 0.0, float(cols))
        y = np.clip(y0[edge] + t_mid * dy[edge] + 1.0, 0.0, float(rows + 1))  # row 0 above
        col = x.astype(np.intp)  # the floor, of numbers >= 0
        rise = (t_b - t_a) * fall[edge]
        right = rise * (x - col)  # its share on the next pixel's side
        index = (base[edge] + y.astype(np.intp)) * width + col
        out = (np.bincount(index, rise - right, size).astype(np.float64, copy=False)
               + np.bincount(index + 1, right, size))
    grid = out.reshape(planes * height, width)
    # Each row's running sum: OpenCV's integral image of the rows' differences.
    grid[1:] -= grid[:-1].copy()
    summed: FloatArray = np.asarray(cv2.integral(grid, sdepth=cv2.CV_64F), np.float64)[1:, 1:]
    return summed.reshape(planes, height, width)[:, 1:-1, :cols]


def _pieces(
    x0: FloatArray, y0: FloatArray, dx: FloatArray, dy: FloatArray, rows: int, cols: int
) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
    """Cut each edge ``(x0, y0) + t (dx, dy)``, pixel boundaries at integers, where it
    crosses a boundary inside the grid's span.

    Returns per piece its parameters ``t_a <= t_b`` and its edge's index, the pieces
    of one edge in order.
    """
    n = x0.shape[0]
    t_cuts = [np.zeros(n), np.ones(n)]
    owners = [np.arange(n), np.arange(n)]
    for a, d, limit in ((x0, dx, cols), (y0, dy, rows)):
        b = a + d
        lo = np.maximum(np.ceil(np.minimum(a, b)), 0.0)
        hi = np.minimum(np.floor(np.maximum(a, b)), float(limit))
        count = (hi - lo + 1.0).astype(np.intp)
        count[(count < 0) | (d == 0.0)] = 0
        total = int(count.sum())
        if total == 0:
            continue
        owner = np.repeat(np.arange(n), count)
        step = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
        # Each edge's cuts in the order it runs, so that each list is sorted already.
        first, sign = np.where(d > 0.0, lo, hi), np.sign(d)
        # Rounding may put a cut a hair outside [0, 1]: it makes a piece of no length.
        t_cuts.append((first[owner] + sign[owner] * step - a[owner]) / d[owner])
        owners.append(owner)
    t = np.concatenate(t_cuts)
    owner = np.concatenate(owners)
    # Four sorted runs (starts, ends, x cuts, y cuts): a merge for the stable sort.
    order = np.argsort(owner + 0.5 * np.clip(t, 0.0, 1.0), kind="stable")
    t, owner = t[order], owner[order]
    same = owner[1:] == owner[:-1]
    return t[:-1][same], t[1:][same], owner[:-1][same]
