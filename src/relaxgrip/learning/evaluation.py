"""The paper's accuracy evaluation (§V-B) of trained models on a dataset split.

* ICFN: MAE, RMSE, R², and the median absolute error per force range.
* RCFN: every held-out hold is reconstructed online as the estimator would:
  at each feature time the RCFN predicts ``(kappa, tau)`` from the features
  seen so far, and until the next one the force is
  ``F0 (1 - kappa (1 - exp(-t / tau)))`` (Eq. 10 with ``K = kappa F0``).
  ``F0`` is the true onset force, which isolates the RCFN as the paper's
  curve metrics do; the same curves started from the ICFN's estimate of the
  onset force are scored too.  NRMSE, AUC_rel, correlation and Amp per curve.
* The force ``relax`` and ``observer`` read (beyond the paper), where the
  models have an unrelaxed ICFN: its ensemble times each sample's retained
  share (:mod:`relaxgrip.learning.history`), scored like the ICFN.
* Repeatability: the 40, 50 and 60 °C groups of six holds from the same start
  force: mean and spread of the curve metrics, and the spread of the true force
  at the hold's end and at 100 s since the onset, where the paper's sequences
  end (its "GT std at t_end").
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.learning.datasets import (
    REPEAT_CONTACT_M,
    REPEAT_FORCE_N,
    REPEAT_TEMPS_C,
    REPEATS_PER_GROUP,
)
from relaxgrip.learning.datastore import Dataset
from relaxgrip.learning.history import retained_shares
from relaxgrip.learning.store import ModelBundle
from relaxgrip.metrics import (
    amplitude,
    auc_rel,
    curve_correlation,
    mae,
    median_ae_by_range,
    nrmse,
    r2,
    rmse,
)
from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA

FloatArray = NDArray[np.float64]

#: Length of the paper's relaxation sequences (s): its repeatability's "t_end".
PAPER_SEQUENCE_S = 100.0

__all__ = [
    "PAPER_SEQUENCE_S", "CurveScore", "Evaluation", "evaluate", "reconstruct_online",
    "spread_text",
]


@dataclass(frozen=True)
class CurveScore:
    """One reconstructed hold.

    Attributes
    ----------
    sequence : int
        Sequence id.
    temp_set_c, f0_n : float
        Set temperature (°C) and true onset force (N).
    t_s, truth_n, predicted_n : ndarray
        Curve times since the onset (s), true and reconstructed force (N).
    nrmse, auc_rel, corr, amp_n : float
        Paper metrics of the curve.
    nrmse_icfn : float
        NRMSE of the same reconstruction started from the ICFN's onset estimate.
    """

    sequence: int
    temp_set_c: float
    f0_n: float
    t_s: FloatArray
    truth_n: FloatArray
    predicted_n: FloatArray
    nrmse: float
    auc_rel: float
    corr: float
    amp_n: float
    nrmse_icfn: float


@dataclass(frozen=True)
class Evaluation:
    """Everything the accuracy figure and the ``--json`` output need.

    Attributes
    ----------
    split : str
        The split evaluated.
    icfn_truth_n, icfn_predicted_n : ndarray
        ICFN labels and predictions.
    curves : list of CurveScore
        Every reconstructed hold.
    repeat_groups : dict
        Temperature (``"40"``…) to the curves of its repeatability group.
    history_predicted_n : ndarray or None
        The force read from the loading history on the ICFN samples (the
        unrelaxed ICFN times the retained share); None without one.
    """

    split: str
    icfn_truth_n: FloatArray
    icfn_predicted_n: FloatArray
    curves: list[CurveScore]
    repeat_groups: dict[str, list[CurveScore]] = field(default_factory=dict)
    history_predicted_n: FloatArray | None = None

    def icfn_summary(self) -> dict[str, Any]:
        """ICFN figures."""
        return _force_scores(self.icfn_predicted_n, self.icfn_truth_n)

    def history_summary(self) -> dict[str, Any] | None:
        """The same figures for the force read from the loading history (None without it)."""
        if self.history_predicted_n is None:
            return None
        return _force_scores(self.history_predicted_n, self.icfn_truth_n)

    def rcfn_summary(self) -> dict[str, Any]:
        """RCFN figures over the held-out curves."""
        def stat(values: list[float]) -> tuple[float, float]:
            return statistics.fmean(values), statistics.median(values)

        n_mean, n_med = stat([c.nrmse for c in self.curves])
        a_mean, a_med = stat([c.auc_rel for c in self.curves])
        i_mean, i_med = stat([c.nrmse_icfn for c in self.curves])
        return {"nrmse_mean": n_mean, "nrmse_median": n_med, "auc_rel_mean": a_mean,
                "auc_rel_median": a_med, "corr_mean": statistics.fmean(c.corr for c in self.curves),
                "amp_mean_n": statistics.fmean(c.amp_n for c in self.curves),
                "nrmse_from_icfn_mean": i_mean, "nrmse_from_icfn_median": i_med,
                "sequences": len(self.curves)}

    def repeatability_summary(self) -> dict[str, dict[str, float | None]]:
        """Per group: mean ± std of NRMSE, AUC_rel and correlation; spread of the true force.

        ``gt_end_std_n`` is the spread at each hold's end; ``gt_std_100s_n``
        at :data:`PAPER_SEQUENCE_S` since the onset, the end of the paper's
        sequences (None where the holds are shorter).
        """
        def spread(values: list[float]) -> float:
            return statistics.stdev(values) if len(values) > 1 else 0.0

        def ms(values: list[float]) -> tuple[float, float]:
            return statistics.fmean(values), spread(values)

        out: dict[str, dict[str, float | None]] = {}
        for temp, group in self.repeat_groups.items():
            n = ms([c.nrmse for c in group])
            a = ms([c.auc_rel for c in group])
            r = ms([c.corr for c in group])
            ends = [float(c.truth_n[-1]) for c in group]
            long_enough = all(c.t_s[-1] >= PAPER_SEQUENCE_S for c in group)
            at_100s = [float(np.interp(PAPER_SEQUENCE_S, c.t_s, c.truth_n)) for c in group]
            out[temp] = {"nrmse_mean": n[0], "nrmse_std": n[1], "auc_rel_mean": a[0],
                         "auc_rel_std": a[1], "corr_mean": r[0], "corr_std": r[1],
                         "gt_end_std_n": spread(ends),
                         "gt_std_100s_n": spread(at_100s) if long_enough else None,
                         "sequences": len(group)}
        return out

    def to_dict(self) -> dict[str, Any]:
        """The ``relaxgrip evaluate --json`` object."""
        out = {"split": self.split, "icfn": self.icfn_summary(), "rcfn": self.rcfn_summary(),
               "repeatability": self.repeatability_summary()}
        if (history := self.history_summary()) is not None:
            out["icfn_history"] = history
        return out


def spread_text(group: dict[str, float | None]) -> str:
    """A repeatability group's spread of the true force, at 100 s and at the end, as text."""
    at_100s = group.get("gt_std_100s_n")
    end = f"end std {group['gt_end_std_n']:.3f} N"
    if at_100s is None:
        return f"GT {end}"
    return f"GT std {at_100s:.3f} N at {PAPER_SEQUENCE_S:g} s, {end}"


def _force_scores(predicted: FloatArray, truth: FloatArray) -> dict[str, Any]:
    return {"mae_n": mae(predicted, truth), "rmse_n": rmse(predicted, truth),
            "r2": r2(predicted, truth), "median_ae_n": median_ae_by_range(predicted, truth),
            "samples": int(truth.size)}


def reconstruct_online(
    t_s: FloatArray, f_inst_n: float, feature_t_s: FloatArray, kappa: FloatArray,
    tau_s: FloatArray,
) -> FloatArray:
    """Eq. 10 with the latest RCFN prediction at each time (held until the next one)."""
    idx = np.clip(np.searchsorted(feature_t_s, t_s, side="right") - 1, 0, feature_t_s.size - 1)
    out: FloatArray = f_inst_n * (1.0 - kappa[idx] * -np.expm1(-t_s / tau_s[idx]))
    return out


def evaluate(data: Dataset, models: ModelBundle, split: str = "test") -> Evaluation:
    """Score the models on one split of a dataset (``"all"``: on all of it).

    Raises
    ------
    InputError
        If the split has no ICFN samples or no RCFN sequences, or a hold whose
        true or reconstructed force is constant (no NRMSE or correlation).
    """
    x, y = data.icfn_xy(split)
    if y.size == 0:
        raise InputError(f"the dataset has no ICFN samples in split {split!r}")
    seqs = data.sequences
    if split != "all":
        seqs = seqs[seqs["split"] == split]
    if seqs.empty:
        raise InputError(f"the dataset has no RCFN sequences in split {split!r}")
    feats = data.rcfn_features.groupby("sequence")
    curves_by = data.curves.groupby("sequence")
    onset = seqs[[f"onset_{n}" for n in ICFN_SCHEMA.names]].to_numpy(np.float64)
    f_icfn = models.icfn.predict(onset)
    curves = []
    for row, f_hat in zip(seqs.itertuples(index=False), f_icfn, strict=True):
        seq_id = int(row.sequence)
        f = feats.get_group(seq_id)
        c = curves_by.get_group(seq_id)
        pred = models.rcfn.predict(f[list(RCFN_SCHEMA.names)].to_numpy(np.float64))
        t = c["t_s"].to_numpy(np.float64)
        truth = c["force_n"].to_numpy(np.float64)
        ft = f["t_s"].to_numpy(np.float64)
        kappa, tau = pred[:, 0], np.exp(pred[:, 1])
        f0 = float(row.f0_n)
        predicted = reconstruct_online(t, f0, ft, kappa, tau)
        from_icfn = reconstruct_online(t, float(f_hat), ft, kappa, tau)
        try:
            scores = (nrmse(t, predicted, truth), auc_rel(t, predicted, truth),
                      curve_correlation(predicted, truth), nrmse(t, from_icfn, truth))
        except ValueError as exc:  # a flat curve: the paper's metrics are not defined on it
            raise InputError(f"RCFN sequence {seq_id} cannot be scored: {exc}") from None
        curves.append(CurveScore(
            sequence=seq_id, temp_set_c=float(row.temp_set_c), f0_n=f0, t_s=t, truth_n=truth,
            predicted_n=predicted, nrmse=scores[0], auc_rel=scores[1], corr=scores[2],
            amp_n=amplitude(truth), nrmse_icfn=scores[3],
        ))
    by_id = {c.sequence: c for c in curves}
    groups: dict[str, list[CurveScore]] = {}
    for temp in REPEAT_TEMPS_C:
        members = seqs[(seqs["object"] == "force_ball")
                       & np.isclose(seqs["contact_set_m"], REPEAT_CONTACT_M)
                       & np.isclose(seqs["force_set_n"], REPEAT_FORCE_N)
                       & np.isclose(seqs["temp_set_c"], temp)].sort_values("repeat")
        chosen = [by_id[int(s)] for s in members["sequence"][:REPEATS_PER_GROUP]]
        if chosen:
            groups[f"{temp:g}"] = chosen
    history = None
    if models.unrelaxed is not None:
        # Splits are by episode, so each sample's history lies within its split.
        history = models.unrelaxed.predict(x) * retained_shares(data.icfn_rows(split),
                                                               models.unrelaxed.model)
    return Evaluation(split, y, models.icfn.predict(x), curves, groups, history)

