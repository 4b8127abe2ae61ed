"""``run_loop``: how many periods a run lasts when nothing ends it before its time."""

from __future__ import annotations

import pytest

from relaxgrip.clock import VirtualClock
from relaxgrip.control import GraspController, GraspPhase, GraspPlan, make_estimator, run_loop
from relaxgrip.learning.training import load_default_models
from relaxgrip.twin import GripperTwin, TwinConfig


# 8.3 s at 30 Hz is 249.00000000000003 periods in floating point, 16.1 s 483.00000000000006:
# a ceiling of the product ran them a period long.  0.1 s and 1 s as controls.
@pytest.mark.parametrize(("max_s", "periods"), [(8.3, 249), (16.1, 483), (0.1, 3), (1.0, 30)])
def test_a_run_lasts_its_whole_periods_and_not_one_more(max_s: float, periods: int) -> None:
    models = load_default_models()
    cfg = TwinConfig(initial_temp_c=40.0)
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    controller = GraspController(cfg.rig, make_estimator("relax", models.icfn, models.rcfn),
                                 heat=cfg.heat)
    plan = GraspPlan(target_n=3.0, temp_c=40.0, hold_s=15.0)
    loop = run_loop(twin, controller, clock, plan, max_s)
    twin.close()
    # Still settling before contact: the run ended by its time, not by the grasp.
    assert loop.phase_at(-1) not in (GraspPhase.DONE, GraspPhase.STOPPED)
    assert loop["t_s"].size == periods + 1  # the start and one sample per period
    assert loop["t_s"][-1] == pytest.approx(max_s, abs=1e-9)
