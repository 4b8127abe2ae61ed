"""Cantilever beam against Euler–Bernoulli closed forms, and the finger's calibration."""

from dataclasses import replace

import numpy as np
import pytest

from relaxgrip.physics.beam import (
    FingerParams,
    beam_grid,
    bending_stiffness_n_m2,
    contact_compliance_m_per_n,
    contact_deflection_m,
    deflection_area_m2,
    deflection_profile_m,
    deflection_share,
    local_stiffness_n_per_m,
    unit_profile_m_per_n,
)

# A uniform, temperature-independent, linear beam: the textbook cantilever.
UNIFORM = FingerParams(
    n_grid=2001, skeleton_taper=0.0, skeleton_temp_coeff_per_k=0.0, smp_ratio_base=0.0,
    smp_ratio_tip=0.0, stiffening=0.0, ei_skeleton_base_n_m2=0.2,
)


@pytest.mark.parametrize("a", [0.05, 0.08, 0.11])
def test_point_load_profile_matches_closed_form(a):
    x = beam_grid(UNIFORM)
    z, slope = unit_profile_m_per_n(a, 25.0, UNIFORM)
    ei = 0.2
    inside = x <= a
    exact = np.where(inside, x**2 * (3 * a - x) / (6 * ei), a**2 * (3 * x - a) / (6 * ei))
    np.testing.assert_allclose(z, exact, rtol=2e-5, atol=1e-12)
    exact_slope = np.where(inside, x * (2 * a - x) / (2 * ei), a**2 / (2 * ei))
    np.testing.assert_allclose(slope, exact_slope, rtol=2e-5, atol=1e-12)
    assert contact_compliance_m_per_n(a, 25.0, UNIFORM) == pytest.approx(a**3 / (3 * ei), rel=1e-5)


def test_area_closed_form():
    a, length, ei, f = 0.08, UNIFORM.length_m, 0.2, 5.0
    exact = f / ei * (a**4 / 8 + a**3 / 3 * (length - a) + a**2 / 2 * (length - a) ** 2 / 2)
    assert deflection_area_m2(f, 25.0, UNIFORM, a) == pytest.approx(exact, rel=1e-5)


def test_geometric_stiffening_solves_the_cubic():
    finger = FingerParams()
    c = 1e-3
    f = np.array([-3.0, 0.0, 2.0, 8.0])
    z = contact_deflection_m(f, c, finger)
    back = z / c * (1 + finger.stiffening * (z / finger.length_m) ** 2)
    np.testing.assert_allclose(back, f, atol=1e-12)
    assert np.all(np.abs(z) <= np.abs(f) * c + 1e-15)


def test_geometric_stiffening_keeps_precision_from_tiny_to_huge_loads():
    finger = FingerParams()
    c = 1e-3
    f = np.array([1e-12, 1e-9, 1e-6, 1e-3, 1.0, 1e3, 1e6])
    z = contact_deflection_m(f, c, finger)
    p = finger.length_m**2 / finger.stiffening
    # The cubic's residual, relative to its constant term, at rounding level throughout.
    np.testing.assert_allclose((z**3 + p * z) / (p * c * f), 1.0, rtol=1e-14)
    # Tiny loads: linear to full precision (Cardano's form was 8e-4 off at 1e-12 N).
    np.testing.assert_allclose(z[:3] / (c * f[:3]), 1.0, rtol=1e-14)
    np.testing.assert_array_equal(contact_deflection_m(-f, c, finger), -z)


def test_temperature_field_and_monotonic_softening():
    finger = FingerParams()
    t = np.linspace(20, 70, 26)
    for load in (2.0, 4.0, 6.0, 8.0):
        z80 = [np.interp(0.08, beam_grid(finger), deflection_profile_m(load, 0.08, tt, finger))
               for tt in t]
        assert np.all(np.diff(z80) > 0), "deformation must rise with temperature at every load"
    # a hot base softens more than a hot tip (bending moment is largest at the base)
    x = beam_grid(finger)
    hot_base = np.where(x < 0.04, 60.0, 25.0)
    hot_tip = np.where(x > 0.07, 60.0, 25.0)
    assert contact_compliance_m_per_n(0.08, hot_base, finger) > contact_compliance_m_per_n(
        0.08, hot_tip, finger)
    assert bending_stiffness_n_m2(25.0, finger).shape == x.shape


def test_local_stiffness_rises_towards_the_base():
    finger = FingerParams()
    k = [local_stiffness_n_per_m(8.0, 25.0, finger, contact_m=a, at_m=a) for a in (0.05, 0.08, 0.1)]
    assert k[0] > k[1] > k[2]


def test_params_validate():
    with pytest.raises(ValueError, match="length_m > 0"):
        FingerParams(length_m=0.0)
    with pytest.raises(ValueError, match="outside"):
        unit_profile_m_per_n(0.2, 25.0, replace(UNIFORM, length_m=0.11))


def test_the_deflection_share_is_the_profile_over_its_value_at_the_contact() -> None:
    finger = FingerParams()
    x = beam_grid(finger)
    profile = deflection_profile_m(5.0, 0.08, 40.0, finger)
    share = deflection_share(x, 0.08, 40.0, finger)
    np.testing.assert_allclose(share, profile / np.interp(0.08, x, profile), rtol=1e-12)
    assert float(deflection_share(0.08, 0.08, 40.0, finger)) == 1.0
