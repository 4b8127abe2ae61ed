"""Both fingers' bend read from the infrared frame: the top face's midline, row by row."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.perception.face_bend import (
    FaceBendReader,
    FaceMidline,
    clear_span_m,
    fit_contact_deflection_m,
)
from relaxgrip.physics.beam import beam_grid, unit_profile_m_per_n
from relaxgrip.twin import TwinConfig
from relaxgrip.twin.render_ir import IrObject, IrRenderer
from relaxgrip.twin.sensors import IrSensorConfig

CFG = TwinConfig()
RIG = CFG.rig
FINGER = CFG.finger
NODES = np.linspace(0.0, RIG.finger.length_m, 12)
GRID = beam_grid(FINGER)
APERTURE_M = 0.030
ROOM_C = 25.0


def _frame(contacts_m: tuple[float, float], temp_c: float = 40.0, contact_at_m: float = 0.079,
           netd_k: float = 0.0, aperture_m: float = APERTURE_M, samples: int = 1,
           objects: tuple[IrObject, ...] = ()) -> np.ndarray:
    """An infrared frame of both fingers bent by the beam model's profile for a load at
    ``contact_at_m``, with deflections ``contacts_m`` there."""
    z, _ = unit_profile_m_per_n(contact_at_m, temp_c, FINGER)
    unit = z / np.interp(contact_at_m, GRID, z)
    bend = np.stack([c * unit for c in contacts_m])
    renderer = IrRenderer(RIG, IrSensorConfig(netd_k=netd_k, max_offset_k=0.0,
                                              samples_per_px=samples), seed=0)
    temps = np.full((2, NODES.size), temp_c)
    img: np.ndarray = renderer.render(0, temps, NODES, aperture_m, list(objects), ROOM_C,
                                      (GRID, bend))
    return img


def _guess(contact_m: float, temp_c: float = 40.0, contact_at_m: float = 0.079
           ) -> tuple[float, float]:
    """The marker finger's deflection and slope at the tab for that bend: what the pipeline
    hands the reader from the marker."""
    z, slope = unit_profile_m_per_n(contact_at_m, temp_c, FINGER)
    scale = contact_m / float(np.interp(contact_at_m, GRID, z))
    tab = RIG.marker.position_m
    return scale * float(np.interp(tab, GRID, z)), scale * float(np.interp(tab, GRID, slope))


def test_unbent_faces_read_no_bend_along_the_whole_span() -> None:
    reader = FaceBendReader(RIG)
    for midline in reader.read(_frame((0.0, 0.0)), APERTURE_M):
        assert midline.along_m.size >= 25
        assert midline.along_m.min() < 0.03
        assert midline.along_m.max() > 0.10
        # The twin draws each pixel by its centre: an edge is placed to half a pixel.
        assert np.abs(midline.bend_m).max() < 0.5e-3, midline.bend_m


def test_the_contact_deflection_of_each_finger_and_its_change() -> None:
    """Each finger's deflection at the contact, and a 0.5 mm creep of one finger alone."""
    reader = FaceBendReader(RIG)
    aperture = APERTURE_M

    def read(contacts: tuple[float, float]) -> list[float]:
        faces = reader.read(_frame(contacts), aperture, _guess(contacts[0]))
        return [fit_contact_deflection_m(m, 0.079, 40.0, FINGER) for m in faces]

    before = read((4.0e-3, 3.5e-3))
    assert before == pytest.approx([4.0e-3, 3.5e-3], rel=0.06)
    after = read((4.0e-3, 4.0e-3))
    assert after[0] - before[0] == pytest.approx(0.0, abs=0.05e-3)  # finger 0 did not move
    assert after[1] - before[1] == pytest.approx(0.5e-3, rel=0.15)


def test_the_marker_s_bend_guides_the_search_to_strongly_bent_faces() -> None:
    """At 8 mm the distal rows lie beyond an unbent search; the marker's bend finds them."""
    contact = 8.0e-3
    img = _frame((contact, contact))
    guess = _guess(contact)
    reader = FaceBendReader(RIG)
    blind = reader.read(img, APERTURE_M, None)[1]
    guided = reader.read(img, APERTURE_M, guess)[1]
    assert guided.along_m.max() > 0.10
    assert guided.along_m.size > blind.along_m.size
    assert fit_contact_deflection_m(guided, 0.079, 40.0, FINGER) == pytest.approx(contact, rel=0.06)


def test_noise_leaves_the_reading_within_a_few_micrometres_of_the_noise_free_one() -> None:
    reader = FaceBendReader(RIG)
    clean = [fit_contact_deflection_m(m, 0.079, 40.0, FINGER)
             for m in reader.read(_frame((4.0e-3, 4.0e-3)), APERTURE_M, _guess(4.0e-3))]
    noisy = [fit_contact_deflection_m(m, 0.079, 40.0, FINGER)
             for m in reader.read(_frame((4.0e-3, 4.0e-3), netd_k=0.05), APERTURE_M,
                                  _guess(4.0e-3))]
    assert noisy == pytest.approx(clean, abs=0.01e-3)


def test_a_face_colder_than_the_room_is_read_too() -> None:
    reader = FaceBendReader(RIG)
    faces = reader.read(_frame((4.0e-3, 4.0e-3), temp_c=10.0), APERTURE_M,
                        _guess(4.0e-3, 10.0))
    for midline in faces:
        assert midline.along_m.size >= 25
        assert fit_contact_deflection_m(midline, 0.079, 10.0, FINGER) == pytest.approx(4.0e-3,
                                                                                     rel=0.06)


def test_a_finger_at_the_room_s_temperature_shows_no_outline() -> None:
    reader = FaceBendReader(RIG)
    for midline in reader.read(_frame((4.0e-3, 4.0e-3), temp_c=ROOM_C), APERTURE_M):
        assert midline.along_m.size == 0
        assert math.isnan(fit_contact_deflection_m(midline, 0.079, ROOM_C, FINGER))


def test_the_windows_are_cached_per_tenth_of_a_millimetre() -> None:
    reader = FaceBendReader(RIG)
    img = _frame((4.0e-3, 4.0e-3))
    first = reader.read(img, APERTURE_M)
    again = reader.read(img, APERTURE_M + 2e-5)
    assert len(reader._cache) == 2  # one window per finger
    assert np.array_equal(first[0].along_m, again[0].along_m)


def test_contact_deflection_refuses_what_it_cannot_fit() -> None:
    along = np.linspace(0.02, 0.10, 20)
    z, _ = unit_profile_m_per_n(0.08, 40.0, FINGER)
    unit = np.interp(along, GRID, z / np.interp(0.08, GRID, z))
    line = FaceMidline(along, 3e-3 * unit, np.full(along.size, 0.012))
    assert fit_contact_deflection_m(line, 0.08, 40.0, FINGER) == pytest.approx(3e-3, rel=1e-9)
    assert math.isnan(fit_contact_deflection_m(line, math.nan, 40.0, FINGER))
    assert math.isnan(fit_contact_deflection_m(line, 0.2, 40.0, FINGER))  # beyond the tip
    assert math.isnan(fit_contact_deflection_m(line, 0.08, math.nan, FINGER))
    few = FaceMidline(along[:5], line.bend_m[:5], line.width_m[:5])
    assert math.isnan(fit_contact_deflection_m(few, 0.08, 40.0, FINGER))


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"min_contrast_k": 0.0}, "least contrast"),
    ({"min_contrast_k": math.nan}, "least contrast"),
    ({"margin_m": -1e-3}, "search margin"),
    ({"along_range_m": (0.05, 0.02)}, "along the finger"),
    ({"along_range_m": (0.0, 0.2)}, "along the finger"),
])
def test_bad_settings_are_refused(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(InputError, match=message):
        FaceBendReader(RIG, **kwargs)  # type: ignore[arg-type]


def test_an_unloaded_finger_is_looked_for_unbent() -> None:
    """A rigid jaw does not bend: read with ``loaded=(0,)`` it is looked for where it is."""
    img = _frame((8.0e-3, 0.0))
    reader = FaceBendReader(RIG)
    guess = _guess(8.0e-3)
    both = reader.read(img, APERTURE_M, guess)
    marker_only = reader.read(img, APERTURE_M, guess, loaded=(0,))
    assert np.array_equal(both[0].bend_m, marker_only[0].bend_m)
    # Looked for bent by 8 mm, the unbent jaw's distal rows are missed.
    assert marker_only[1].along_m.size > both[1].along_m.size
    assert np.abs(marker_only[1].bend_m).max() < 0.5e-3


def test_a_camera_that_sees_no_face_reads_nothing() -> None:
    """Looking up at the sky, no pixel's ray meets the plane of the faces."""
    away = replace(RIG, ir=replace(RIG.ir, pitch_down_deg=-60.0))
    reader = FaceBendReader(away)
    for midline in reader.read(np.full(away.ir.intrinsics.shape, ROOM_C), APERTURE_M):
        assert midline.along_m.size == 0


@pytest.mark.parametrize(("samples", "limit_m", "slope_tol"),
                         [(1, 0.12e-3, 0.2), (4, 0.025e-3, 0.05)])
def test_drawn_by_pixel_area_the_creep_is_read_to_micrometres(samples: int, limit_m: float,
                                                             slope_tol: float) -> None:
    """Finger 1 crept in 20 µm steps: read against the truth, the reading's error from a
    line stays within ``limit_m`` (by pixel centres an edge waits for the next centre)."""
    reader = FaceBendReader(RIG)
    steps = np.arange(3.8e-3, 4.21e-3, 0.02e-3)
    read = np.array([fit_contact_deflection_m(
        reader.read(_frame((4.0e-3, c), samples=samples), APERTURE_M, _guess(4.0e-3))[1],
        0.079, 40.0, FINGER) for c in steps])
    fit = np.polyval(np.polyfit(steps, read, 1), steps)
    assert np.abs(read - fit).max() < limit_m
    assert np.polyfit(steps, read, 1)[0] == pytest.approx(1.0, abs=slope_tol)


def test_the_span_ends_where_a_held_object_hides_the_face() -> None:
    """The force ball between the fingers stands above their faces and hides the distal
    rows' inner edges: the span the face is whole on ends before them."""
    aperture = 0.044
    ball = IrObject((0.079, 0.0, 0.0), 0.030, 26.0, 0.9)
    reader = FaceBendReader(RIG)
    clear = reader.read(_frame((4.0e-3, 4.0e-3), aperture_m=aperture, samples=4), aperture,
                        _guess(4.0e-3))[1]
    held = reader.read(_frame((4.0e-3, 4.0e-3), aperture_m=aperture, samples=4,
                              objects=(ball,)), aperture, _guess(4.0e-3))[1]
    assert clear_span_m(clear) == (0.015, 0.108)
    lo, hi = clear_span_m(held)
    assert lo == 0.015
    assert 0.05 < hi < 0.08
    # Every row in the span reads the face whole.
    inside = (held.along_m >= lo) & (held.along_m <= hi)
    assert np.all(held.width_m[inside] > 0.012 - 0.3e-3)


def test_the_span_needs_rows_near_the_root_to_measure_the_face_on() -> None:
    along = np.linspace(0.05, 0.10, 12)
    narrow = FaceMidline(along, np.zeros(12), np.full(12, 0.008))
    assert clear_span_m(narrow) == (0.015, 0.108)
    one_row = FaceMidline(np.r_[0.02, along], np.zeros(13), np.r_[0.012, np.full(12, 0.0119)])
    assert clear_span_m(one_row) == (0.015, 0.108)  # 0.1 mm narrower is within tolerance
