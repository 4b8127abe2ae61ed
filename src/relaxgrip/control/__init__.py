"""Control: PID, force estimators, the temperature loop, grasp phases and the loop runner."""

from relaxgrip.control.controller import (
    MAX_TARGET_N,
    ForceControlConfig,
    GraspController,
    GraspPlan,
    check_target_n,
    twin_limits,
)
from relaxgrip.control.estimators import (
    EstimatorKind,
    FixedEstimator,
    ForceEstimate,
    ForceEstimator,
    IcfnEstimator,
    RelaxEstimator,
    bundle_estimator,
    make_estimator,
)
from relaxgrip.control.phases import PHASES, Event, EventKind, GraspPhase, PhaseLog
from relaxgrip.control.pid import PID, PIDGains
from relaxgrip.control.runner import LoopInterrupted, LoopResult, run_loop
from relaxgrip.control.temperature import (
    MODE_SETPOINTS_C,
    StiffnessMode,
    TemperatureLoop,
    TemperatureStatus,
    ThermalLimits,
)

__all__ = [
    "MAX_TARGET_N",
    "MODE_SETPOINTS_C",
    "PHASES",
    "PID",
    "EstimatorKind",
    "Event",
    "EventKind",
    "FixedEstimator",
    "ForceControlConfig",
    "ForceEstimate",
    "ForceEstimator",
    "GraspController",
    "GraspPhase",
    "GraspPlan",
    "IcfnEstimator",
    "LoopInterrupted",
    "LoopResult",
    "PIDGains",
    "PhaseLog",
    "RelaxEstimator",
    "StiffnessMode",
    "TemperatureLoop",
    "TemperatureStatus",
    "ThermalLimits",
    "bundle_estimator",
    "check_target_n",
    "make_estimator",
    "run_loop",
    "twin_limits",
]
