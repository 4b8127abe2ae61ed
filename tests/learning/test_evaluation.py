"""The repeatability figures: the spread of the true force at the paper's 100 s and at the end."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from relaxgrip.learning.evaluation import (
    PAPER_SEQUENCE_S,
    CurveScore,
    Evaluation,
    spread_text,
)


def _curve(seq: int, end_s: float, at_100s_n: float, end_n: float) -> CurveScore:
    t = np.arange(0.0, end_s + 0.5, 1.0)  # 1 s steps: 100 s is a sample
    # Linear from 5 N to its value at 100 s, then on to the end.
    truth = np.interp(t, [0.0, PAPER_SEQUENCE_S, max(end_s, PAPER_SEQUENCE_S + 1.0)],
                      [5.0, at_100s_n, end_n])
    return CurveScore(sequence=seq, temp_set_c=40.0, f0_n=5.0, t_s=t, truth_n=truth,
                      predicted_n=truth, nrmse=0.0, auc_rel=0.0, corr=1.0, amp_n=1.0,
                      nrmse_icfn=0.0)


def _evaluation(groups: dict[str, list[CurveScore]]) -> Evaluation:
    empty = np.zeros(0)
    return Evaluation("test", empty, empty, [c for g in groups.values() for c in g], groups)


def test_the_spread_is_read_at_100_s_and_at_the_end() -> None:
    group = [_curve(0, 280.0, 4.7, 4.5), _curve(1, 280.0, 4.8, 4.3)]
    stats = _evaluation({"40": group}).repeatability_summary()["40"]
    assert stats["gt_std_100s_n"] == pytest.approx(np.std([4.7, 4.8], ddof=1))
    assert stats["gt_end_std_n"] == pytest.approx(np.std([4.5, 4.3], ddof=1))
    assert spread_text(stats) == "GT std 0.071 N at 100 s, end std 0.141 N"


def test_holds_shorter_than_the_papers_have_no_spread_at_100_s() -> None:
    group = [_curve(0, 60.0, 4.7, 4.5), _curve(1, 60.0, 4.8, 4.3)]
    stats = _evaluation({"40": group}).repeatability_summary()["40"]
    assert stats["gt_std_100s_n"] is None
    assert stats["gt_end_std_n"] == pytest.approx(np.std([g.truth_n[-1] for g in group], ddof=1))
    assert spread_text(stats).startswith("GT end std ")


def test_a_hold_with_a_flat_force_is_one_line_not_a_traceback(tiny: Path) -> None:
    """A curve of one value (a damaged table, a sensor stuck) has no NRMSE: evaluate names
    the hold in one line instead of raising a bare ValueError."""
    from dataclasses import replace

    from relaxgrip.errors import InputError
    from relaxgrip.learning.datastore import load_dataset
    from relaxgrip.learning.evaluation import evaluate
    from relaxgrip.learning.training import load_default_models

    data = load_dataset(tiny)
    curves = data.curves.copy()
    curves.loc[curves["sequence"] == 2, "force_n"] = 4.0
    with pytest.raises(InputError, match=r"RCFN sequence 2 cannot be scored: f_gt is constant"):
        evaluate(replace(data, curves=curves), load_default_models(), "test")
