"""Series contact, friction and adhesion."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from relaxgrip.physics.contact import (
    AdhesionParams,
    adhesion_pulloff_n,
    friction_capacity_n,
    series_contact,
)


def test_series_springs():
    k1, k2, ko, delta = 1500.0, 1400.0, 700.0, 0.01
    sol = series_contact(delta, [k1, k2], [0.0, 0.0], ko)
    expected = delta / (1 / k1 + 1 / k2 + 1 / ko)
    assert sol.force_n == pytest.approx(expected)
    assert sol.finger_deflection_m[0] * k1 == pytest.approx(expected)
    assert sum(sol.finger_deflection_m) + sol.object_compression_m == pytest.approx(delta)


@settings(max_examples=100, deadline=None)
@given(
    delta=st.floats(-0.02, 0.05),
    k=st.lists(st.floats(10.0, 1e5), min_size=1, max_size=2),
    c=st.floats(-20.0, 20.0),
    ko=st.floats(1.0, 1e6),
    yield_n=st.floats(0.1, 100.0) | st.just(math.inf),
)
def test_force_never_negative_and_geometry_closes(delta, k, c, ko, yield_n):
    offsets = [c] * len(k)
    sol = series_contact(delta, k, offsets, ko, yield_n)
    assert sol.force_n >= 0.0
    assert sol.force_n <= yield_n + 1e-9
    assert sol.plastic_m >= 0.0
    for kj, cj, xj in zip(k, offsets, sol.finger_deflection_m, strict=True):
        assert kj * xj + cj == pytest.approx(sol.force_n, abs=1e-6 * max(1.0, abs(cj)))
    if sol.force_n > 0:
        closed = sum(sol.finger_deflection_m) + sol.object_compression_m + sol.plastic_m
        assert closed == pytest.approx(delta, abs=1e-9)


def test_yield_caps_force_and_sets_plastic():
    sol = series_contact(0.05, [1000.0, 1000.0], [0.0, 0.0], 1000.0, object_yield_n=5.0)
    assert sol.force_n == 5.0
    assert sol.plastic_m == pytest.approx(0.05 - 3 * 0.005)


def test_friction_tilt_and_adhesion():
    assert friction_capacity_n(10.0, 0.5) == pytest.approx(10.0)
    tilted = friction_capacity_n(10.0, 0.5, 0.2)
    assert tilted == pytest.approx(2 * 10 * (0.5 * np.cos(0.2) - np.sin(0.2)))
    assert friction_capacity_n(10.0, 0.1, 0.5) == 0.0
    p = AdhesionParams()
    assert adhesion_pulloff_n(70.0, True, p) == pytest.approx(p.max_pulloff_n, rel=1e-3)
    assert adhesion_pulloff_n(25.0, True, p) < 0.01
    assert adhesion_pulloff_n(70.0, False, p) == 0.0
