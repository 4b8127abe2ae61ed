"""Offline replay: perception and force estimation re-run on a recording's frames and encoder.

The replay builds a fresh :class:`~relaxgrip.perception.pipeline.Perception`
on the recorded rig and the recorded estimator on the given models, and feeds
them, period by period, the recorded RGB and infrared frames and the encoder,
in the controller's order: perceive, estimate; then, where the recording says
the controller did so in that period, start the hold (the recorded
``hold_onset`` event, Eq. 8's onset) or zero the marker again (the
``marker_rezero`` event).  It does not re-run the controller's decisions: it
checks the estimation the recording's controller acted on.

With the same models and code and lossless (PNG) frames the replayed estimate
equals the recorded one; JPEG frames move the marker corners by a fraction of
a pixel, which shows as a small difference (measured in the tests).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.control.controller import onset_contact_m
from relaxgrip.control.estimators import (
    EstimatorKind,
    ForceEstimate,
    ForceEstimator,
    bundle_estimator,
    estimator_provenance,
)
from relaxgrip.errors import InputError
from relaxgrip.learning.observer import ObserverModel
from relaxgrip.learning.store import ModelBundle
from relaxgrip.perception.pipeline import Percept, Perception
from relaxgrip.recording.provenance import model_differences
from relaxgrip.recording.reader import (
    Period,
    iter_periods,
    malformed_fields,
    read_replayable_session,
    read_session,
    rig_from_dict,
)

FloatArray = NDArray[np.float64]

__all__ = ["ReplayResult", "replay", "replay_periods"]


def replay_periods(path: Path, models: ModelBundle, tolerant: bool = False,
                   estimator: str | None = None, observer: ObserverModel | None = None
                   ) -> Iterator[tuple[Period, Percept, ForceEstimate]]:
    """Each period of a recording with the replayed percept and estimate.

    Parameters
    ----------
    path : Path
        The recording.
    models : ModelBundle
        ICFN and RCFN for the estimator.
    tolerant : bool
        Read a killed recording up to its last complete chunk.
    estimator : str, optional
        Estimator to replay (default: the recorded one).
    observer : ObserverModel, optional
        The ``observer`` estimator's parameters (default: the shipped ones).

    Raises
    ------
    InputError
        Not a readable relaxgrip recording, no frames, an unknown estimator.
    """
    session = read_replayable_session(path, tolerant)
    name = estimator or str(session.get("estimator"))
    if name not in {k.value for k in EstimatorKind}:
        raise InputError(f"{path}: cannot replay estimator {name!r} "
                         "(fixed, icfn, relax or observer)")
    perception = Perception(rig_from_dict(session["rig"]))
    est = bundle_estimator(name, models, observer)
    perception.reset()
    est.reset()
    with malformed_fields(path):
        yield from _replayed(path, tolerant, perception, est)


def _replayed(path: Path, tolerant: bool, perception: Perception, est: ForceEstimator
              ) -> Iterator[tuple[Period, Percept, ForceEstimate]]:
    frames = ir_frames = 0
    holding = False
    motor_mm = math.nan

    def apply(event: dict[str, Any]) -> None:
        nonlocal holding
        kind, t = event["kind"], float(event["t_s"])
        if kind == "phase" and event["detail"] == "open":  # a new grasp: GraspController.start
            perception.reset()
            est.reset()
            holding = False
        elif kind == "contact":
            est.contact(t)
        elif kind == "hold_onset":
            est.start_hold(t, motor_mm, onset_contact_m(str(event["detail"])))
            holding = True
        elif kind == "phase" and event["detail"] == "release" and holding:
            est.end_hold(t)
            holding = False
        elif kind == "marker_rezero":
            perception.tracker.reset()

    for period in iter_periods(path, tolerant):
        # An operator's action between periods (the dashboard's Start, Release, Stop) is
        # written with the next period but came before its step, as does a grasp's start.
        before = [_before_step(e, period.t_s) for e in period.events]
        for event, first in zip(period.events, before, strict=True):
            if first:
                apply(event)
        obs = period.messages["/relaxgrip/observation"]
        motor_mm = float(obs["motor_position_mm"])
        frames += period.rgb is not None
        ir_frames += period.ir is not None
        percept = perception.update(period.rgb, period.ir, motor_mm)
        estimate = est.update(percept, motor_mm)
        yield period, percept, estimate
        for event, first in zip(period.events, before, strict=True):
            if not first:
                apply(event)
    if frames == 0:
        raise InputError(f"{path}: the recording has no RGB frames to replay")
    if ir_frames == 0:
        raise InputError(f"{path}: the recording has no infrared frames, which every estimator "
                         "reads the fingers' temperature from")


def _before_step(event: dict[str, Any], period_t_s: float) -> bool:
    """Whether ``event`` took effect before its period's perception and estimate."""
    starts_grasp = event["kind"] == "phase" and event["detail"] == "open"
    return starts_grasp or float(event["t_s"]) < period_t_s


@dataclass(frozen=True)
class ReplayResult:
    """Recorded against replayed estimation, period by period.

    Attributes
    ----------
    path : str
        The recording.
    estimator : str
        Estimator replayed.
    t_s : ndarray
        Loop time of each period (s).
    recorded_n, replayed_n : ndarray
        The estimate the controller regulated, recorded and replayed (N; nan: none).
    recorded_icfn_n, replayed_icfn_n : ndarray
        The ICFN's per-frame estimate, recorded and replayed (N).
    recorded_status, replayed_status : list of str
        Marker status of each period.
    truth_n : ndarray
        True contact force where the recording has it (N; nan otherwise).
    recorded_calibration_n, replayed_calibration_n : ndarray
        The calibrated closed-loop error taken off the estimate, recorded and
        replayed (N; nan: none, and in recordings from before it was recorded):
        a model directory calibrated since the recording shows here.
    models_differ : tuple of str
        What of the models the recording ran with the replay's are not
        (:func:`~relaxgrip.recording.provenance.model_differences`; empty for
        the same models, and for recordings that do not name theirs).
    """

    path: str
    estimator: str
    t_s: FloatArray
    recorded_n: FloatArray
    replayed_n: FloatArray
    recorded_icfn_n: FloatArray
    replayed_icfn_n: FloatArray
    recorded_status: list[str]
    replayed_status: list[str]
    truth_n: FloatArray
    recorded_calibration_n: FloatArray
    replayed_calibration_n: FloatArray
    models_differ: tuple[str, ...] = ()

    def metrics(self) -> dict[str, Any]:
        """Differences of the estimate and the ICFN, and the agreement of validity and status."""
        out: dict[str, Any] = {"periods": int(self.t_s.size)}
        for key, a, b in (("estimate", self.recorded_n, self.replayed_n),
                          ("icfn", self.recorded_icfn_n, self.replayed_icfn_n),
                          ("calibration", self.recorded_calibration_n,
                           self.replayed_calibration_n)):
            both = np.isfinite(a) & np.isfinite(b)
            diff = np.abs(a[both] - b[both])
            out[f"{key}_compared"] = int(both.sum())
            out[f"{key}_max_abs_diff_n"] = float(diff.max()) if diff.size else math.nan
            out[f"{key}_mean_abs_diff_n"] = float(diff.mean()) if diff.size else math.nan
            out[f"{key}_valid_agreement"] = (float(np.mean(np.isfinite(a) == np.isfinite(b)))
                                             if a.size else math.nan)
        same = [r == p for r, p in zip(self.recorded_status, self.replayed_status, strict=True)]
        out["marker_status_agreement"] = float(np.mean(same)) if same else math.nan
        return out

    def to_dict(self) -> dict[str, Any]:
        """The ``relaxgrip replay --json`` object."""
        return {"recording": self.path, "estimator": self.estimator,
                "models_differ": list(self.models_differ), **self.metrics()}


def _f(value: Any) -> float:
    return math.nan if value is None else float(value)


def replay(path: Path, models: ModelBundle, tolerant: bool = False,
           observer: ObserverModel | None = None) -> ReplayResult:
    """Re-run perception and estimation on a recording and compare with what it recorded.

    ``observer``: the parameters an ``observer`` recording ran with (default:
    the shipped ones).

    Raises
    ------
    InputError
        As :func:`replay_periods`.
    """
    rows: list[tuple[float, ...]] = []
    rec_status: list[str] = []
    rep_status: list[str] = []
    with malformed_fields(path):
        for period, percept, estimate in replay_periods(path, models, tolerant,
                                                        observer=observer):
            rec = period.messages["/relaxgrip/estimate"]
            truth = period.get("/relaxgrip/truth")
            perception = period.get("/relaxgrip/perception")
            rows.append((period.t_s, _f(rec.get("force_n")), estimate.force_n,
                         _f(rec.get("f_icfn_n")), estimate.f_icfn_n,
                         math.nan if truth is None else float(truth["contact_force_n"]),
                         _f(rec.get("calibration_n")), estimate.calibration_n))
            rec_status.append("" if perception is None else str(perception["marker_status"]))
            rep_status.append(percept.marker.status.value)
    session = read_session(path, tolerant)
    name = str(session.get("estimator"))
    differ = model_differences(session.get("models"),
                               estimator_provenance(name, models, observer))
    cols = np.array(rows, dtype=np.float64).reshape(-1, 8)
    return ReplayResult(str(path), name, cols[:, 0], cols[:, 1], cols[:, 2], cols[:, 3],
                        cols[:, 4], rec_status, rep_status, cols[:, 5], cols[:, 6], cols[:, 7],
                        tuple(differ))
