"""``run_hold``: a hold lasts its periods exactly, and a ramp starts where the hold is."""

from __future__ import annotations

import math

import numpy as np
import pytest

from relaxgrip.control import EventKind, GraspPhase
from relaxgrip.errors import InputError
from relaxgrip.experiments import controlled_hold
from relaxgrip.experiments.controlled_hold import run_hold
from relaxgrip.experiments.profiles import parse_target_profile, parse_temp_profile

#: The loop's rate (Hz): a hold of d seconds is 30 d periods.
RATE_HZ = 30.0


# Seeds 0 and 7 settled their motor for seven periods before the onset and held 599 of a
# 20 s hold's 600; seed 5 settled for six and held 600.
@pytest.mark.parametrize("seed", [0, 5, 7])
@pytest.mark.parametrize("duration_s", [14.0, 20.0])
def test_a_hold_lasts_exactly_its_periods_from_the_onset(seed: int, duration_s: float) -> None:
    hold = run_hold("relax", duration_s=duration_s, seed=seed)
    periods = round(duration_s * RATE_HZ)
    assert hold.t_s.size == periods + 1  # the onset and one sample per period after it
    assert hold.t_s[0] == 0.0
    assert hold.t_s[-1] == pytest.approx(duration_s, abs=1e-9)
    np.testing.assert_allclose(np.diff(hold.t_s), 1.0 / RATE_HZ, atol=1e-9)
    # The run ends with the hold's last period, the onset where the controller logged it.
    onset = [e.t_s for e in hold.loop.log.events if e.kind is EventKind.HOLD_ONSET]
    assert hold.loop.hold_onset_s() == pytest.approx(onset[0], abs=1e-9)
    assert hold.loop["t_s"][-1] == pytest.approx(onset[0] + duration_s, abs=1e-9)
    # The hold ends there (the controller releases, and the run ends done).
    assert hold.loop.phase_at(-2) is GraspPhase.HOLD
    assert hold.loop.phase_at(-1) is GraspPhase.DONE
    assert hold.metrics()["mae_n"] < 0.2


def test_a_budgeted_hold_with_a_profile_lasts_its_periods_too() -> None:
    hold = run_hold("relax", duration_s=14.0, seed=0, budget=True,
                    target_profile=parse_target_profile("step:4:7"))
    assert hold.t_s.size == 14 * 30 + 1
    assert hold.fixed_aperture_n is not None
    assert hold.fixed_aperture_n.size == hold.t_s.size
    assert hold.target_t_n[0] == 5.0
    assert hold.target_t_n[-1] == 4.0


@pytest.mark.parametrize(("target_n", "temp_c", "temps", "targets", "message"), [
    (5.0, 40.0, None, "ramp:4:3:5:2",
     "--target-profile ramps from 4 N but the hold's target is 5 N (--target-n)"),
    (3.0, 40.0, None, "ramp:5:3:5:2",
     "--target-profile ramps from 5 N but the hold's target is 3 N (--target-n)"),
    (5.0, 40.0, "ramp:45:55:5:3", None,
     "--temp-profile ramps from 45 °C but the hold's temperature is 40 °C (--temp-c)"),
    (5.0, 48.0, "ramp:40:55:5:3", "ramp:5:3:5:2",
     "--temp-profile ramps from 40 °C but the hold's temperature is 48 °C (--temp-c)"),
])
def test_a_ramp_from_another_value_than_the_holds_is_refused(
        monkeypatch: pytest.MonkeyPatch, target_n: float, temp_c: float, temps: str | None,
        targets: str | None, message: str) -> None:
    temp_profile = None if temps is None else parse_temp_profile(temps)
    target_profile = None if targets is None else parse_target_profile(targets)

    def no_backend(*args: object) -> None:
        raise AssertionError("a backend was made for a hold that had to be refused")

    monkeypatch.setattr(controlled_hold, "_make_backend", no_backend)
    with pytest.raises(InputError) as refused:
        run_hold("relax", target_n, 14.0, temp_c, temp_profile=temp_profile,
                 target_profile=target_profile)
    assert str(refused.value) == f"{message}: the ramp must start from it"


def test_ramps_from_the_holds_values_and_steps_are_accepted() -> None:
    check = controlled_hold.check_ramp_starts
    # The scenarios' and the docs' ramps, on the hold they are given with.
    check(5.0, 40.0, parse_temp_profile("ramp:40:55:150:30"),
          parse_target_profile("ramp:5:3:300:10"))
    check(3.0, 48.0, parse_temp_profile("step:55:10"), parse_target_profile("step:4:10"))
    check(5.0, 40.0)


def test_a_ramp_from_the_holds_values_moves_nothing_at_the_onset() -> None:
    hold = run_hold("relax", target_n=4.0, duration_s=14.0, temp_c=42.0, seed=1,
                    temp_profile=parse_temp_profile("ramp:42:46:7:3"),
                    target_profile=parse_target_profile("ramp:4:3:7:3"))
    target = hold.target_t_n
    assert np.all(target[hold.t_s < 7.0] == 4.0)
    assert target[-1] == 3.0
    setpoint = hold.series("setpoint_c")
    assert np.all(setpoint[hold.t_s < 7.0] == 42.0)
    assert setpoint[-1] == 46.0
    # The target before the onset was the hold's too: nothing jumps at it.
    before = hold.loop["setpoint_c"][~np.isfinite(hold.loop["hold_s"])]
    assert math.isclose(before[np.isfinite(before)][-1], 42.0)
    assert abs(hold.truth_n[hold.t_s < 7.0] - 4.0).max() < 0.3


def test_the_other_finger_read_in_the_infrared_frame_takes_the_chain_over(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """By default (the object located, ``ChainParams.ir_weight`` 1) the estimate from 5 s
    of the hold on is the chain's reading with finger 1 read in the infrared frames;
    before, and with weight 0, it is the one-marker chain's."""
    from functools import partial

    from relaxgrip.control import chain

    read = run_hold("relax", duration_s=12.0, seed=4)
    monkeypatch.setattr(chain, "ChainParams", partial(chain.ChainParams, ir_weight=0.0))
    shipped = run_hold("relax", duration_s=12.0, seed=4)
    onset = read.loop.hold_onset_s()
    assert onset is not None
    hold_s = read.loop["t_s"] - onset
    before = (hold_s >= 0.0) & (hold_s < 4.0)
    after = hold_s >= 6.0
    np.testing.assert_array_equal(read.loop["estimate_n"][before],
                                  shipped.loop["estimate_n"][before])
    assert not np.array_equal(read.loop["estimate_n"][after], shipped.loop["estimate_n"][after])
    # At weight 1 the estimate is the reading: what the chain added is all of the change.
    chain_n = read.loop["chain_n"][after]
    assert np.all(np.isfinite(chain_n))
    assert abs(float(np.mean(read.loop["estimate_n"][after])) - 5.0) < 0.05
