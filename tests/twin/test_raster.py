"""The exact-area rasteriser against polygons clipped to each pixel."""

from __future__ import annotations

import numpy as np
import pytest

from relaxgrip.twin.raster import area_coverage


def _clip(polygon: list[tuple[float, float]], axis: int, bound: float,
          keep_below: bool) -> list[tuple[float, float]]:
    """One Sutherland-Hodgman pass: the part of ``polygon`` on one side of a line."""

    def inside(p: tuple[float, float]) -> bool:
        return p[axis] <= bound if keep_below else p[axis] >= bound

    out: list[tuple[float, float]] = []
    for i, p in enumerate(polygon):
        q = polygon[(i + 1) % len(polygon)]
        if inside(p):
            out.append(p)
        if inside(p) != inside(q):
            t = (bound - p[axis]) / (q[axis] - p[axis])
            out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
    return out


def _shoelace(polygon: list[tuple[float, float]]) -> float:
    if len(polygon) < 3:
        return 0.0
    x = np.array([p[0] for p in polygon])
    y = np.array([p[1] for p in polygon])
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _reference(polygon: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Each pixel's signed area of ``polygon`` (clockwise on screen positive), by clipping."""
    rows, cols = shape
    out = np.zeros(shape)
    poly = [(float(x), float(y)) for x, y in polygon]
    for r in range(rows):
        band = _clip(_clip(poly, 1, r - 0.5, False), 1, r + 0.5, True)
        for c in range(cols):
            cell = _clip(_clip(band, 0, c - 0.5, False), 0, c + 0.5, True)
            out[r, c] = _shoelace(cell)
    return out


def _edges(polygon: np.ndarray) -> np.ndarray:
    return np.stack([polygon, np.roll(polygon, -1, axis=0)])


def _convex(rng: np.random.Generator, centre: tuple[float, float], radius: float) -> np.ndarray:
    angles = np.sort(rng.uniform(0.0, 2.0 * np.pi, 5))
    radii = rng.uniform(0.4, 1.0, 5) * radius
    return np.column_stack([centre[0] + radii * np.cos(angles),
                            centre[1] + radii * np.sin(angles)])


@pytest.mark.parametrize("seed", range(6))
def test_random_polygons_cover_each_pixel_by_their_exact_area(seed: int) -> None:
    rng = np.random.default_rng(seed)
    shape = (9, 11)
    polygon = _convex(rng, (rng.uniform(3, 7), rng.uniform(3, 5)), rng.uniform(2, 5))
    got = area_coverage(_edges(polygon), 1.0, shape)[0]
    np.testing.assert_allclose(got, _reference(polygon, shape), atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_polygons_reaching_off_the_grid_are_clipped(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    shape = (6, 7)
    polygon = _convex(rng, (rng.uniform(-2, 9), rng.uniform(-2, 8)), rng.uniform(4, 7))
    got = area_coverage(_edges(polygon), 1.0, shape)[0]
    np.testing.assert_allclose(got, _reference(polygon, shape), atol=1e-12)


def test_orientation_weights_and_planes_add_as_stated() -> None:
    shape = (8, 8)
    outer = np.array([[0.3, 0.6], [6.2, 1.1], [5.7, 6.4], [0.9, 5.8]])  # clockwise on screen
    inner = np.array([[2.2, 2.1], [4.1, 2.5], [3.6, 4.2]])
    assert _shoelace([tuple(p) for p in outer]) > 0
    edges = np.concatenate([_edges(outer), _edges(inner), _edges(inner[::-1])], axis=1)
    weights = np.repeat([2.0, -0.5, 1.0], [4, 3, 3])
    plane = np.repeat([0, 0, 1], [4, 3, 3])
    got = area_coverage(edges, weights, shape, plane=plane, planes=2)
    np.testing.assert_allclose(
        got[0], 2.0 * _reference(outer, shape) - 0.5 * _reference(inner, shape), atol=1e-12)
    # Drawn the other way round, the inner triangle counts with minus its weight.
    np.testing.assert_allclose(got[1], -_reference(inner, shape), atol=1e-12)


def test_edges_on_pixel_boundaries_and_whole_pixels() -> None:
    square = np.array([[0.5, 0.5], [3.5, 0.5], [3.5, 2.5], [0.5, 2.5]])
    got = area_coverage(_edges(square), 1.0, (4, 5))[0]
    want = np.zeros((4, 5))
    want[1:3, 1:4] = 1.0
    np.testing.assert_allclose(got, want, atol=1e-12)
    # Vertices on the pixel centres: half and quarter pixels along the outline.
    centred = np.array([[1.0, 1.0], [3.0, 1.0], [3.0, 2.0], [1.0, 2.0]])
    got = area_coverage(_edges(centred), 1.0, (4, 5))[0]
    np.testing.assert_allclose(got, _reference(centred, (4, 5)), atol=1e-12)
    assert got.sum() == pytest.approx(2.0)


def test_a_polygon_covering_the_whole_grid_covers_every_pixel_once() -> None:
    big = np.array([[-10.0, -10.0], [20.0, -10.0], [20.0, 20.0], [-10.0, 20.0]])
    got = area_coverage(_edges(big), 1.0, (3, 4))[0]
    np.testing.assert_allclose(got, np.ones((3, 4)), atol=1e-12)


def test_nothing_to_draw() -> None:
    assert area_coverage(np.zeros((2, 0, 2)), [], (3, 4), planes=2).shape == (2, 3, 4)
    assert not area_coverage(np.zeros((2, 0, 2)), [], (3, 4)).any()
    with pytest.raises(ValueError, match="shape"):
        area_coverage(np.zeros((3, 2)), 1.0, (3, 4))
