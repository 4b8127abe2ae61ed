"""The hold beyond Eq. 10's assumptions: a temperature ramp, a new target, a push.

Eq. 10 assumes one step of displacement at one temperature.  Each scenario
here breaks that while the gripper holds (the paper's own integrated demo
heats the fingers mid-grasp), and :func:`compare_scenarios` runs ``relax``
and ``observer`` through each on one seed: how much Eq. 10 degrades, how
much the online viscoelastic observer keeps, and whether its band covers
the truth.  The profiles are stated for a 280 s hold and scaled in time with
the hold's length.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import (
    PAPER_DURATION_S,
    HoldResult,
    map_holds,
    run_hold,
)
from relaxgrip.experiments.profiles import (
    Profile,
    parse_disturbance,
    parse_target_profile,
    parse_temp_profile,
)
from relaxgrip.learning.observer import ObserverModel
from relaxgrip.learning.store import ModelBundle
from relaxgrip.twin import TwinConfig

__all__ = ["SCENARIOS", "Scenario", "ScenarioComparison", "check_scenarios",
           "compare_scenarios", "scenario_hold", "scenario_holds"]


@dataclass(frozen=True)
class Scenario:
    """A hold's profiles, in the ``relaxgrip hold`` grammar, for a 280 s hold.

    Attributes
    ----------
    label : str
        What it is, for reports (:meth:`describe` adds what happens when).
    temp_profile, target_profile, disturbance : str or None
        ``--temp-profile``, ``--target-profile`` and ``--disturbance``.
    target_n : float
        ``--target-n``: the target the hold closes to (N).
    temp_c : float
        ``--temp-c``: the finger temperature it holds at before a profile acts (°C).
    """

    label: str
    temp_profile: str | None = None
    target_profile: str | None = None
    disturbance: str | None = None
    target_n: float = 5.0
    temp_c: float = 40.0

    def profiles(self, duration_s: float) -> dict[str, Profile | None]:
        """The parsed profiles, their times scaled from 280 s to ``duration_s``."""
        factor = duration_s / PAPER_DURATION_S

        def scaled(text: str | None, parse: Any) -> Profile | None:
            if text is None:
                return None
            p: Profile = parse(text)
            if factor == 1.0:
                return p
            return replace(p, start_s=p.start_s * factor, over_s=p.over_s * factor,
                           until_s=p.until_s * factor)

        return {"temp_profile": scaled(self.temp_profile, parse_temp_profile),
                "target_profile": scaled(self.target_profile, parse_target_profile),
                "disturbance": scaled(self.disturbance, parse_disturbance)}

    def describe(self, duration_s: float = PAPER_DURATION_S) -> str:
        """What happens, with the times of a ``duration_s`` hold."""
        p = self.profiles(duration_s)
        parts = []
        if (t := p["temp_profile"]) is not None:
            start = "" if math.isnan(t.before) else f"{t.before:g} → "
            parts.append(f"{start}{t.after:g} °C "
                         + (f"over {t.over_s:g} s from {t.start_s:g} s" if t.over_s > 0
                            else f"at {t.start_s:g} s"))
        if (g := p["target_profile"]) is not None:
            parts.append(f"{self.target_n:g} → {g.after:g} N at {g.start_s:g} s"
                         if g.over_s <= 0 else
                         f"{g.before:g} → {g.after:g} N over {g.over_s:g} s from "
                         f"{g.start_s:g} s")
        if (d := p["disturbance"]) is not None:
            parts.append(f"{d.after:g} N from {d.start_s:g} s")
        return f"{self.label}: {', '.join(parts)}" if parts else self.label

    def to_dict(self) -> dict[str, str | float | None]:
        return {"label": self.label, "temp_profile": self.temp_profile,
                "target_profile": self.target_profile, "disturbance": self.disturbance,
                "target_n": self.target_n, "temp_c": self.temp_c}


#: The scenarios, by name; ``standard`` is the paper's hold.
SCENARIOS: dict[str, Scenario] = {
    "standard": Scenario("standard hold, 5 N at 40 °C"),
    "ramp": Scenario("stiffness switch", temp_profile="ramp:40:55:150:30"),
    "step": Scenario("new target", target_profile="step:3:150"),
    "push": Scenario("push on the object", disturbance="push:2:200"),
    # The standard hold at the ends of the targets: the band's error is partly
    # absolute, and its calibration needs holds at more than one force.
    "light": Scenario("light hold, 1 N at 40 °C", target_n=1.0),
    "firm": Scenario("firm hold, 8 N at 40 °C", target_n=8.0),
    # And at the hot end of the temperatures, where the relaxing share the
    # error follows scatters more than at 40 °C.
    "hot": Scenario("hot hold, 5 N at 55 °C", temp_c=55.0),
    # And at the glass transition, where the stiffness and the share's scatter change
    # fastest: interpolated from 40 and 55 °C alone the band covered seeds 4000-4011 at
    # 48 °C 89.3 % of the time (50 °C: 99.8 %).
    "warm": Scenario("warm hold, 5 N at 48 °C", temp_c=48.0),
}


def check_scenarios(names: Sequence[str]) -> list[str]:
    """The names, checked against :data:`SCENARIOS`.

    Raises
    ------
    InputError
        None given, or an unknown one.
    """
    unknown = [s for s in names if s not in SCENARIOS]
    if unknown or not names:
        raise InputError(f"unknown scenario {unknown[0] if unknown else '(none)'}; known: "
                         f"{', '.join(SCENARIOS)}")
    return list(names)


def scenario_hold(estimator: str, name: str, seed: int = 0,
                  duration_s: float = PAPER_DURATION_S, models: ModelBundle | None = None,
                  observer: ObserverModel | None = None,
                  config: TwinConfig | None = None) -> HoldResult:
    """One estimator's closed-loop hold through a scenario (its target and temperature before
    it acts), on the twin ``config`` (our gripper by default)."""
    scenario = SCENARIOS[check_scenarios([name])[0]]
    p = scenario.profiles(duration_s)
    return run_hold(estimator, target_n=scenario.target_n, duration_s=duration_s,
                    temp_c=scenario.temp_c, seed=seed, models=models, config=config,
                    observer=observer, temp_profile=p["temp_profile"],
                    target_profile=p["target_profile"], disturbance=p["disturbance"])


@dataclass(frozen=True)
class ScenarioComparison:
    """``relax`` and ``observer`` through each scenario on one seed.

    Attributes
    ----------
    seed : int
    duration_s : float
    holds : dict of str to dict of str to HoldResult
        Scenario name -> estimator -> hold.
    """

    seed: int
    duration_s: float
    holds: dict[str, dict[str, HoldResult]]

    def mae_n(self, scenario: str, estimator: str) -> float:
        return float(self.holds[scenario][estimator].metrics()["mae_n"])

    def degradation(self, scenario: str) -> float:
        """``relax``'s MAE over the observer's (nan without both)."""
        runs = self.holds[scenario]
        if not {"relax", "observer"} <= runs.keys():
            return math.nan
        return self.mae_n(scenario, "relax") / self.mae_n(scenario, "observer")

    def to_dict(self) -> dict[str, Any]:
        return {
            "seed": self.seed, "duration_s": self.duration_s,
            "scenarios": {name: {**SCENARIOS[name].to_dict(),
                                 "relax_over_observer": self.degradation(name),
                                 "holds": {est: hold.metrics() for est, hold in runs.items()}}
                          for name, runs in self.holds.items()},
        }


#: One hold to run: estimator, scenario name, seed.
Run = tuple[str, str, int]


def _one(args: tuple[Run, float, ModelBundle | None, ObserverModel | None, TwinConfig | None]
         ) -> HoldResult:
    (estimator, name, seed), duration_s, models, observer, config = args
    return scenario_hold(estimator, name, seed, duration_s, models, observer, config)


def scenario_holds(runs: Sequence[Run], duration_s: float = PAPER_DURATION_S,
                   models: ModelBundle | None = None, observer: ObserverModel | None = None,
                   n_jobs: int = 1, config: TwinConfig | None = None) -> list[HoldResult]:
    """Each run's :func:`scenario_hold`, in order, ``n_jobs`` at once."""
    return map_holds(_one, [(run, duration_s, models, observer, config) for run in runs],
                     n_jobs)


def compare_scenarios(names: Sequence[str] = ("ramp", "step", "push"), seed: int = 0,
                      duration_s: float = PAPER_DURATION_S,
                      estimators: Sequence[str] = ("relax", "observer"),
                      models: ModelBundle | None = None, observer: ObserverModel | None = None,
                      n_jobs: int = 1, config: TwinConfig | None = None) -> ScenarioComparison:
    """Run every estimator through every scenario on ``seed`` (``n_jobs`` holds at once), on
    the twin ``config`` (our gripper by default)."""
    runs = [(est, name, seed) for name in check_scenarios(names) for est in estimators]
    holds = scenario_holds(runs, duration_s, models, observer, n_jobs, config)
    out: dict[str, dict[str, HoldResult]] = {}
    for (est, name, _), hold in zip(runs, holds, strict=True):
        out.setdefault(name, {})[est] = hold
    return ScenarioComparison(seed, duration_s, out)
