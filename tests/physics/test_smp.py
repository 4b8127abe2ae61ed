"""SMP modulus, shift factor and relaxing share."""

import numpy as np
import pytest

from relaxgrip.physics.smp import (
    SMPParams,
    glassy_fraction,
    relaxation_fraction,
    shift_factor,
    storage_modulus_pa,
)

P = SMPParams()


def test_modulus_limits_and_steepest_at_tg():
    t = np.linspace(0.0, 100.0, 10001)
    e = storage_modulus_pa(t, P)
    assert e[0] == pytest.approx(P.e_glassy_pa, rel=1e-4)
    assert e[-1] == pytest.approx(P.e_rubbery_pa, rel=1e-2)
    assert np.all(np.diff(e) < 0)
    steepest = t[np.argmin(np.diff(e))]
    assert steepest == pytest.approx(P.tg_c, abs=0.02)
    assert glassy_fraction(P.tg_c, P) == pytest.approx(0.5)


def test_shift_factor_wlf_above_arrhenius_below_continuous_at_tg():
    assert shift_factor(P.tg_c, P) == pytest.approx(1.0)
    dt = 12.0
    wlf = 10 ** (-P.wlf_c1 * dt / (P.wlf_c2_k + dt))
    assert shift_factor(P.tg_c + dt, P) == pytest.approx(wlf)
    ea = P.activation_energy_j_per_mol
    t_k, tg_k = P.tg_c - dt + 273.15, P.tg_c + 273.15
    expected = np.exp(ea / 8.314462618 * (1 / t_k - 1 / tg_k))
    assert shift_factor(P.tg_c - dt, P) == pytest.approx(expected)
    # value and slope of ln a_T continuous at Tg
    eps = 1e-4
    lo, mid, hi = np.log(shift_factor([P.tg_c - eps, P.tg_c, P.tg_c + eps], P))
    assert mid == pytest.approx(0.0, abs=1e-12)
    assert (mid - lo) / eps == pytest.approx((hi - mid) / eps, rel=1e-3)
    t = np.linspace(10, 90, 400)
    assert np.all(np.diff(shift_factor(t, P)) < 0)


def test_shift_factor_rejects_below_absolute_zero():
    with pytest.raises(ValueError, match="absolute zero"):
        shift_factor(-300.0, P)


def test_relaxation_fraction_rises_with_temperature():
    g = relaxation_fraction(np.array([20.0, 40.0, 50.0, 60.0, 90.0]), P)
    assert np.all(np.diff(g) > 0)
    assert g[0] == pytest.approx(P.relax_fraction_glassy, abs=0.01)
    assert g[-1] == pytest.approx(P.relax_fraction_rubbery, abs=0.01)


def test_params_validate():
    with pytest.raises(ValueError, match="e_glassy_pa > e_rubbery_pa"):
        SMPParams(e_glassy_pa=1.0, e_rubbery_pa=2.0)
    with pytest.raises(ValueError, match="relax_fraction_glassy <="):
        SMPParams(relax_fraction_glassy=0.5, relax_fraction_rubbery=0.4)
