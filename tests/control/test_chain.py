"""The closed chain's reading: the object's stiffness from the loading, the force from travel."""

from __future__ import annotations

import math

import numpy as np
import pytest

from relaxgrip.control.chain import ChainParams, ClosedChain, marker_share
from relaxgrip.physics.beam import FingerParams

K_OBJ = 0.7  # N/mm, the force ball's
K_FINGER = 1.3  # N/mm, each finger's contact stiffness
TEMP_C = 40.0


def _share() -> float:
    return marker_share(0.060, 0.080, TEMP_C, FingerParams())


def _started(weight: float = 0.2, k_obj: float = K_OBJ, contact_m: float = math.nan,
             **params: float) -> ClosedChain:
    """A chain started on a loading of two equal fingers and the object in series."""
    chain = ClosedChain(ChainParams(weight=weight, **params))  # type: ignore[arg-type]
    stiffness = 1.0 / (1.0 / k_obj + 2.0 / K_FINGER)  # N per mm of travel
    marker_per_mm = _share() * stiffness / K_FINGER * 1e-3  # m of marker per mm of travel
    chain.start(stiffness, marker_per_mm, TEMP_C, contact_m)
    return chain


def _hold(chain: ClosedChain, creep_mm: tuple[float, float], estimate_off_n: float = 0.0,
          lost_after_s: float = math.inf, infrared_from_s: float = math.inf
          ) -> list[tuple[float, float, float]]:
    """Hold 5 N while the fingers creep linearly and the motor closes by the creep.

    Returns (hold time, true force, blended estimate) per frame; the estimate
    blended is the truth plus ``estimate_off_n``.  From ``infrared_from_s`` on,
    an infrared frame each second reads finger 1's contact deflection.
    """
    rows = []
    for t in np.arange(0.0, 60.0, 1.0 / 30.0):
        c0, c1 = (5.0 / K_FINGER + c * t / 60.0 for c in creep_mm)
        motor = 100.0 + (c0 + c1 - 2 * 5.0 / K_FINGER)  # closes by what the fingers gave
        force = 5.0 + 0.2 * t / 60.0  # and a little more
        motor += 0.2 * t / 60.0 / K_OBJ
        deflection = None if t > lost_after_s else _share() * c0 * 1e-3
        frame = t >= infrared_from_s and round(t * 30.0) % 30 == 0
        rows.append((float(t), force, chain.blend(float(t), motor, deflection,
                                                   force + estimate_off_n,
                                                   c1 * 1e-3 if frame else None)))
    return rows


def test_the_share_is_one_at_the_contact_and_smaller_towards_the_root() -> None:
    finger = FingerParams()
    assert marker_share(0.080, 0.080, TEMP_C, finger) == pytest.approx(1.0)
    shares = [marker_share(x, 0.080, TEMP_C, finger) for x in (0.02, 0.04, 0.06)]
    assert 0.0 < shares[0] < shares[1] < shares[2] < 1.0
    # A uniform cantilever's x^2 (3a - x) / (2 a^3) is 0.633 at 60 of 80 mm; the
    # finger's stiffness falls towards the tip, so the marker bends less of it.
    assert 0.55 < shares[2] < 0.633


def test_the_object_stiffness_is_measured_from_the_loading() -> None:
    chain = _started()
    assert chain.object_stiffness_n_per_mm == pytest.approx(K_OBJ, rel=1e-9)


def test_equal_creep_reads_the_true_force_and_the_estimate_is_pulled_to_it() -> None:
    chain = _started(weight=0.25)
    rows = _hold(chain, creep_mm=(0.3, 0.3), estimate_off_n=0.08)
    for t, force, blended in rows:
        if t < 5.0:
            assert blended == pytest.approx(force + 0.08)  # before the reference: the estimate
    t, force, blended = rows[-1]
    # The chain starts from the estimate at 4-5 s (0.08 off), then follows the truth.
    assert chain.reading_n == pytest.approx(force + 0.08, abs=1e-9)
    assert blended == pytest.approx(force + 0.08, abs=1e-9)


def test_the_chain_reads_the_other_fingers_creep_as_force() -> None:
    """Finger 1 creeps 0.1 mm more than the marker's: the chain reads 0.07 N over."""
    chain = _started(weight=0.5)
    t, force, blended = _hold(chain, creep_mm=(0.3, 0.4))[-1]
    # 0.1 mm over the whole 60 s; the reference is the mean over 4-5 s.
    over = K_OBJ * 0.1 * (t - 4.5) / 60.0
    assert chain.reading_n - force == pytest.approx(over, rel=1e-3)
    assert blended - force == pytest.approx(0.5 * over, rel=1e-3)


def test_weight_zero_is_the_estimate_alone() -> None:
    chain = _started(weight=0.0)
    assert math.isnan(chain.object_stiffness_n_per_mm)
    for _, force, blended in _hold(chain, creep_mm=(0.3, 0.6), estimate_off_n=0.1):
        assert blended == force + 0.1


def test_a_rigid_object_leaves_no_travel_to_read() -> None:
    chain = _started(k_obj=1e6)
    assert math.isnan(chain.object_stiffness_n_per_mm)
    assert all(b == f for _, f, b in _hold(chain, creep_mm=(0.3, 0.6)))


def test_a_lost_marker_keeps_the_last_deflection() -> None:
    chain = _started(weight=1.0)
    rows = _hold(chain, creep_mm=(0.3, 0.3), lost_after_s=30.0)
    _, force, blended = rows[-1]
    # The fingers crept 0.15 mm more each after the marker was lost: the chain
    # takes the motor's closing for the object's.
    assert blended - force == pytest.approx(K_OBJ * 2 * 0.15, rel=2e-3)


def test_a_seen_contact_sets_the_marker_share_and_the_weight() -> None:
    params = ChainParams(weight=0.2, seen_weight=0.4)
    nominal, seen, inside = ClosedChain(params), ClosedChain(params), ClosedChain(params)
    nominal.start(0.3, 1e-4, TEMP_C)
    seen.start(0.3, 1e-4, TEMP_C, contact_m=0.083)
    inside.start(0.3, 1e-4, TEMP_C, contact_m=0.050)  # nearer the root than the marker
    assert (nominal.contact_m, nominal.weight) == (0.080, 0.2)
    assert (seen.contact_m, seen.weight) == (0.083, 0.4)
    assert (inside.contact_m, inside.weight) == (0.080, 0.2)
    # Further out, the marker bends less of the contact's deflection.
    assert seen.share == marker_share(0.060, 0.083, TEMP_C, FingerParams()) < nominal.share
    assert inside.share == nominal.share


def test_the_other_finger_read_in_the_infrared_frame_takes_its_creep() -> None:
    """Finger 1 creeps 0.1 mm more than the marker's: read in the infrared frame (the
    object seen), the chain reads the truth and takes the estimate over."""
    chain = _started(weight=0.2, contact_m=0.080, seen_weight=0.4, ir_weight=1.0)
    rows = _hold(chain, creep_mm=(0.3, 0.4), estimate_off_n=0.05, infrared_from_s=0.0)
    assert chain.weight == 1.0
    for t, force, blended in rows:
        if t < 5.0:
            assert blended == force + 0.05
    t, force, blended = rows[-1]
    # The one-marker chain would read K_OBJ * 0.1 * 55.5 / 60 = 0.065 N over (above); the
    # infrared frames, a second apart, leave at most a second of finger 1's creep.
    assert blended == chain.reading_n
    assert abs(blended - force - 0.05) < K_OBJ * 0.4 * 1.5 / 60.0


def test_with_no_infrared_reading_at_the_reference_the_chain_keeps_one_marker() -> None:
    seen = _started(weight=0.2, contact_m=0.080, seen_weight=0.4, ir_weight=1.0)
    late = _hold(seen, creep_mm=(0.3, 0.4), infrared_from_s=10.0)
    assert seen.weight == 0.4
    blind = _started(weight=0.2, contact_m=0.080, seen_weight=0.4, ir_weight=1.0)
    assert late == _hold(blind, creep_mm=(0.3, 0.4))
    # Nor is it read where the object was not seen, nor at weight 0.
    for unseen in (_started(weight=0.2, ir_weight=1.0),
                   _started(weight=0.2, contact_m=0.080, seen_weight=0.4, ir_weight=0.0)):
        rows = _hold(unseen, creep_mm=(0.3, 0.4), infrared_from_s=0.0)
        assert math.isnan(unseen._other_ref_m)
        assert rows == _hold(_started(weight=0.2, contact_m=unseen.contact_m
                                      if unseen.seen else math.nan, seen_weight=0.4),
                             creep_mm=(0.3, 0.4))


def test_no_temperature_means_no_chain() -> None:
    chain = ClosedChain()
    chain.start(0.3, 1e-4, math.nan)
    assert chain.blend(10.0, 100.0, 1e-3, 4.0) == 4.0


@pytest.mark.parametrize("kwargs", [
    {"weight": -0.1}, {"weight": 1.5}, {"weight": math.nan}, {"seen_weight": 1.5},
    {"ir_weight": -0.5},
    {"ref_s": 0.5, "ref_window_s": 1.0}, {"ref_window_s": 0.0},
    {"marker_m": 0.09}, {"marker_m": 0.0}, {"min_compliant_share": 1.0},
])
def test_bad_parameters_are_refused(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError, match=r"chain|marker|compliant"):
        ChainParams(**kwargs)  # type: ignore[arg-type]



def test_the_markers_share_follows_the_fingers_temperature() -> None:
    """Through a 40 -> 55 °C ramp the finger stiffens towards its tip relative to its root
    differently: the marker's share of the contact deflection is read at the temperature
    as read, and the marker finger's deflection with it; half a kelvin does not move it."""
    finger = FingerParams()
    chain = _started(weight=1.0, contact_m=0.080, seen_weight=1.0)
    assert chain.share == pytest.approx(marker_share(0.060, 0.080, TEMP_C, finger))
    c0 = 5.0 / K_FINGER  # mm, the contact deflection the marker shows at 40 °C
    marker_m = chain.share * c0 * 1e-3
    for t in np.arange(0.0, 6.0, 1.0 / 30.0):
        chain.blend(float(t), 100.0, marker_m, 5.0, None, TEMP_C)
    at_40 = chain.reading_n
    chain.blend(6.0, 100.0, marker_m, 5.0, None, TEMP_C + 0.4)
    assert chain.reading_n == pytest.approx(at_40, abs=1e-12)
    chain.blend(6.1, 100.0, marker_m, 5.0, None, 55.0)
    hot = marker_share(0.060, 0.080, 55.0, finger)
    assert chain.share == pytest.approx(hot)
    assert hot > marker_share(0.060, 0.080, TEMP_C, finger)
    # The marker unmoved now shows less contact deflection: both fingers gave back that
    # much (finger 1 taken equal), and the object carries it.
    given_back_mm = 2.0 * (c0 - marker_m * 1e3 / hot)
    assert chain.reading_n - at_40 == pytest.approx(
        chain.object_stiffness_n_per_mm * given_back_mm, rel=1e-9)
    # nan keeps the share of the last reading.
    chain.blend(6.2, 100.0, marker_m, 5.0, None, math.nan)
    assert chain.share == pytest.approx(hot)
