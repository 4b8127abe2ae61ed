"""Training datasets from recordings (``relaxgrip dataset from-recordings``).

A recording becomes training data when it has a force ground truth: the
twin's ``/relaxgrip/truth`` channel or a reference force sensor's
``/relaxgrip/force_ref`` channel.  Its frames are perceived again, exactly as
:mod:`relaxgrip.recording.replay` does (the recorded marker zeroing applied),
so the features are the ones this code computes, in the schemas
:func:`relaxgrip.learning.datastore.load_dataset` checks.

What a recording must contain:

* the session message, RGB and infrared frames, observations (encoder), the
  phase (all of them are always recorded);
* a force ground truth (truth or force_ref) at least in the periods used:
  the twin's truth of the period, else the force reference's readings
  interpolated at the period's time on their own timestamps
  (:class:`ReferenceForce`; a load cell reads at 10-80 Hz, the loop runs at
  30 Hz, and a reading comes with the Status after it);
* for an RCFN sequence: a ``hold_onset`` event, and a hold at a fixed
  aperture (the encoder within :data:`FIXED_APERTURE_TOL_MM` of its onset
  value throughout: the ``fixed`` estimator) lasting at least
  :data:`MIN_HOLD_S`.  The RCFN is trained on relaxation at a fixed aperture;
  a hold the controller regulated is not one, and gives ICFN samples only.

Tables (same columns as :mod:`relaxgrip.learning.datasets`):

* ``icfn``: one row every ``icfn_every_s`` of loop time with ICFN features,
  label the true force of that period; ``episode`` is the recording's index.
* ``rcfn_sequences`` / ``rcfn_features`` / ``rcfn_curves``: one sequence per
  qualifying hold: the true force from the onset to the end of the Hold phase
  at ``curve_rate_hz``; RCFN features at ``feature_rate_hz`` (the marker pose
  of every frame before the onset feeds the loading history, as in the
  controller); labels ``K``, ``tau`` of the reduced model fitted to the curve
  anchored at the onset force, ``kappa = K / F0``.

Splits are by recording (all rows of a recording in one split): a seeded
shuffle, at least one recording in train and, from two recordings on, one in
val.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from relaxgrip import __version__
from relaxgrip.errors import InputError
from relaxgrip.learning.datasets import _ICFN_COLUMNS
from relaxgrip.learning.datastore import (
    DATASET_FORMAT,
    DATASET_VERSION,
    check_dataset_out,
    split_counts,
    training_gaps,
    write_dataset,
)
from relaxgrip.learning.store import ModelBundle
from relaxgrip.perception.features import (
    ICFN_SCHEMA,
    RCFN_SCHEMA,
    RcfnFeatures,
    finger_temperature_c,
    marker_pose,
)
from relaxgrip.physics.fitting import fit_reduced
from relaxgrip.recording.reader import malformed_fields, read_replayable_session, read_session
from relaxgrip.recording.replay import replay_periods
from relaxgrip.validate import check_positive

__all__ = ["FIXED_APERTURE_TOL_MM", "MIN_HOLD_S", "dataset_from_recordings", "recording_files",
           "truth_force_n"]

#: A hold counts as fixed-aperture if the encoder stays this close to its onset value (mm).
FIXED_APERTURE_TOL_MM = 0.01
#: Shortest hold that gives an RCFN sequence (s).
MIN_HOLD_S = 5.0

_SEQ_COLUMNS = (
    "sequence", "condition", "split", "object", "temp_set_c", "contact_set_m", "force_set_n",
    "repeat", "f0_n", "f_end_n", "amp_n", "k_n", "tau_s", "kappa", "fit_nrmse", "truth_temp_c",
    "truth_contact_m", *(f"onset_{name}" for name in ICFN_SCHEMA.names),
)


def recording_files(paths: Sequence[Path | str]) -> list[Path]:
    """The recordings ``paths`` name, each once: a directory stands for the ``*.mcap`` in it.

    Raises
    ------
    InputError
        No recordings, or a directory without any.
    """
    files: list[Path] = []
    seen: set[Path] = set()
    for p in map(Path, paths):
        found = sorted(p.glob("*.mcap")) if p.is_dir() else [p]
        if p.is_dir() and not found:
            raise InputError(f"{p}: no .mcap recordings in this directory")
        for f in found:
            if f.resolve() not in seen:
                seen.add(f.resolve())
                files.append(f)
    if not files:
        raise InputError("no recordings given")
    return files


#: Longest gap between two force-reference readings that a period's label is interpolated
#: across (s); a period in a longer gap, or outside the readings, has no label.
MAX_REF_GAP_S = 0.5


class ReferenceForce:
    """The force reference of a recording (``/relaxgrip/force_ref``) on its own timestamps.

    Parameters
    ----------
    path : Path
        The recording.

    Attributes
    ----------
    t_s, force_n : ndarray
        Every reading, in time order (s, N).
    """

    def __init__(self, path: Path) -> None:
        from relaxgrip.recording.reader import iter_messages

        t: list[float] = []
        f: list[float] = []
        for topic, _, message in iter_messages(path):
            if topic == "/relaxgrip/force_ref":
                t.extend(float(v) for v in message["t_s"])
                f.extend(float(v) for v in message["force_n"])
        order = np.argsort(np.asarray(t, dtype=np.float64), kind="stable")
        self.t_s = np.asarray(t, dtype=np.float64)[order]
        self.force_n = np.asarray(f, dtype=np.float64)[order]

    def at(self, t_s: float) -> float:
        """The reference at ``t_s`` (linear between the readings around it; nan without)."""
        t = self.t_s
        if not t.size or not t[0] <= t_s <= t[-1]:
            return math.nan
        k = int(np.searchsorted(t, t_s, side="right"))
        if k >= t.size:
            return float(self.force_n[-1])
        if t[k] - t[k - 1] > MAX_REF_GAP_S:
            return math.nan
        return float(np.interp(t_s, t[k - 1:k + 1], self.force_n[k - 1:k + 1]))


def truth_force_n(period_messages: dict[str, dict[str, Any]]) -> float:
    """True force of a period: the twin's truth, else the force sensor's last reading."""
    truth = period_messages.get("/relaxgrip/truth")
    if truth is not None:
        return float(truth["contact_force_n"])
    ref = period_messages.get("/relaxgrip/force_ref")
    if ref is not None and ref["force_n"]:
        return float(ref["force_n"][-1])
    return math.nan


def _splits(n: int, seed: int, shares: tuple[float, float, float]) -> list[str]:
    """Split of each of ``n`` recordings: shuffled, train and val never empty when possible."""
    order = np.random.default_rng([seed, 303]).permutation(n)
    n_val = max(1 if n >= 2 else 0, round(shares[1] * n))
    n_test = round(shares[2] * n) if n - n_val - round(shares[2] * n) >= 1 else 0
    n_train = n - n_val - n_test
    labels = ["train"] * n_train + ["val"] * n_val + ["test"] * n_test
    out = [""] * n
    for rank, index in enumerate(order):
        out[int(index)] = labels[rank]
    return out


def _one(index: int, path: Path, split: str, models: ModelBundle, icfn_every_s: float,
         curve_rate_hz: float, feature_rate_hz: float) -> tuple[dict[str, list[Any]],
                                                                dict[str, Any] | None,
                                                                dict[str, list[Any]],
                                                                dict[str, list[Any]], str]:
    """ICFN rows, RCFN sequence (or None), its features and curve, and a note."""
    session = read_session(path)
    plan = session.get("plan") or {}
    temp_set = plan.get("temp_c")
    rig_finger = int(session["rig"].get("marker_finger", 0))
    rows: dict[str, list[Any]] = {name: [] for name in _ICFN_COLUMNS}
    feats: dict[str, list[Any]] = {"sequence": [], "t_s": []}
    feats.update({name: [] for name in RCFN_SCHEMA.names})
    curve: dict[str, list[Any]] = {"sequence": [], "t_s": [], "force_n": []}
    builder = RcfnFeatures()
    next_icfn = -math.inf
    truths = 0
    onset: dict[str, Any] | None = None
    hold_end = False
    next_curve = next_feature = 0.0
    motor_spread = 0.0
    hold_t: list[float] = []
    hold_f: list[float] = []
    reference = ReferenceForce(path)
    for period, percept, _ in replay_periods(path, models, estimator="icfn"):
        obs = period.messages["/relaxgrip/observation"]
        motor = float(obs["motor_position_mm"])
        truth_msg = period.messages.get("/relaxgrip/truth")
        force = (float(truth_msg["contact_force_n"]) if truth_msg is not None
                 else reference.at(period.t_s))
        truth = period.get("/relaxgrip/truth")
        phase = period.messages["/relaxgrip/phase"]["phase"]
        t = period.t_s
        if math.isfinite(force):
            truths += 1
        pose = marker_pose(percept.marker)
        if percept.features is not None and math.isfinite(force) and t >= next_icfn:
            next_icfn = t + icfn_every_s
            command = period.get("/relaxgrip/command") or {}
            meta = {
                "episode": index, "split": split,
                "object": (truth or {}).get("object_name") or "unknown",
                "temp_set_c": math.nan if temp_set is None else float(temp_set),
                "contact_set_m": math.nan if truth is None else truth["contact_position_m"],
                "speed_mm_s": float(command.get("motor_velocity_mm_s", math.nan)), "t_s": t,
                "force_n": force,
                "truth_temp_c": (float(np.mean(truth["finger_temp_c"])) if truth is not None
                                 else math.nan),
                "truth_deflection_m": (truth["marker_deflection_m"][rig_finger]
                                       if truth is not None else math.nan),
                "truth_contact_m": math.nan if truth is None else truth["contact_position_m"],
                "ir_age_s": percept.ir_age_s,
            }
            for key, value in meta.items():
                rows[key].append(value)
            for name, value in zip(ICFN_SCHEMA.names, percept.features.tolist(), strict=True):
                rows[name].append(value)
        if onset is None:
            if pose is not None:
                builder.observe(t, pose, motor)
            started = [e for e in period.events if e["kind"] == "hold_onset"]
            if started and pose is not None and percept.features is not None \
                    and math.isfinite(force):
                onset = {"t_s": float(started[0]["t_s"]), "motor": motor, "f0": force,
                         "features": percept.features, "truth": truth}
                builder.start(onset["t_s"], pose, motor)
                hold_t, hold_f = [0.0], [force]
                next_curve = 1.0 / curve_rate_hz
                next_feature = 0.0
            continue
        if hold_end:
            continue
        if phase != "hold" or not math.isfinite(force):
            hold_end = True
            continue
        since = t - onset["t_s"]
        motor_spread = max(motor_spread, abs(motor - onset["motor"]))
        if since >= next_curve - 1e-9:
            hold_t.append(since)
            hold_f.append(force)
            next_curve += 1.0 / curve_rate_hz
        if since >= next_feature - 1e-9:
            next_feature += 1.0 / feature_rate_hz
            if pose is not None and percept.thermal is not None:
                builder.observe(t, pose, onset["motor"])
                x = builder.build(finger_temperature_c(percept.thermal))
                if x is not None:
                    feats["sequence"].append(index)
                    feats["t_s"].append(since)
                    for name, value in zip(RCFN_SCHEMA.names, x.tolist(), strict=True):
                        feats[name].append(value)
    if truths == 0:
        raise InputError(f"{path}: no force ground truth (neither /relaxgrip/truth nor "
                         "/relaxgrip/force_ref): it cannot label a dataset")
    note = "ICFN only: "
    if onset is None:
        return rows, None, _empty(feats), _empty(curve), note + "no hold onset"
    if motor_spread > FIXED_APERTURE_TOL_MM:
        return rows, None, _empty(feats), _empty(curve), \
            note + f"the hold was regulated (encoder moved {motor_spread:.3f} mm)"
    if hold_t[-1] < MIN_HOLD_S or not feats["sequence"]:
        return rows, None, _empty(feats), _empty(curve), \
            note + f"hold of {hold_t[-1]:.1f} s (< {MIN_HOLD_S:g} s) or without RCFN features"
    t_arr, f_arr = np.asarray(hold_t), np.asarray(hold_f)
    f0 = float(onset["f0"])
    fit = fit_reduced(t_arr, f_arr, f_inst_n=f0)
    span = float(f_arr.max() - f_arr.min())
    on_truth = onset["truth"] or {}
    sequence = {
        "sequence": index, "condition": index, "split": split,
        "object": on_truth.get("object_name") or "unknown",
        "temp_set_c": math.nan if temp_set is None else float(temp_set),
        "contact_set_m": on_truth.get("contact_position_m", math.nan),
        "force_set_n": float(plan.get("target_n", math.nan)), "repeat": 0,
        "f0_n": f0, "f_end_n": float(f_arr[-1]), "amp_n": f0 - float(f_arr[-1]),
        "k_n": fit.k_n, "tau_s": fit.tau_s, "kappa": fit.k_n / f0,
        "fit_nrmse": (float(np.sqrt(np.mean((fit.predict(t_arr) - f_arr) ** 2))) / span
                      if span > 0 else 0.0),
        "truth_temp_c": (float(np.mean(on_truth["finger_temp_c"])) if on_truth
                         else math.nan),
        "truth_contact_m": on_truth.get("contact_position_m", math.nan),
        **{f"onset_{name}": value for name, value in
           zip(ICFN_SCHEMA.names, onset["features"].tolist(), strict=True)},
    }
    curve = {"sequence": [index] * len(hold_t), "t_s": hold_t, "force_n": hold_f}
    return rows, sequence, feats, curve, f"ICFN and RCFN ({hold_t[-1]:.1f} s hold)"


def _empty(table: dict[str, list[Any]]) -> dict[str, list[Any]]:
    return {key: [] for key in table}


def dataset_from_recordings(
    paths: Sequence[Path],
    out_dir: Path,
    models: ModelBundle,
    seed: int = 0,
    icfn_every_s: float = 0.5,
    curve_rate_hz: float = 10.0,
    feature_rate_hz: float = 0.5,
    split: tuple[float, float, float] = (0.70, 0.15, 0.15),
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Turn recordings with a force ground truth into a dataset ``relaxgrip train`` reads.

    Parameters
    ----------
    paths : sequence of Path
        Recordings (``.mcap`` files; a directory stands for the ``*.mcap`` in it).
    out_dir : Path
        Dataset directory to write (a previous relaxgrip dataset is replaced).
    models : ModelBundle
        Models of the replayed estimator (the features do not depend on them).
    seed : int
        Seed of the split by recording.
    icfn_every_s : float
        Loop time between ICFN samples of a recording (s).
    curve_rate_hz, feature_rate_hz : float
        Rates of the kept hold curve and of the RCFN features (Hz).
    split : tuple of float
        Train / validation / test shares (by recording).
    progress : callable, optional
        ``progress(done, total)`` after each recording.

    Returns
    -------
    dict
        The dataset's manifest (``notes`` says what each recording gave).

    Raises
    ------
    InputError
        No recordings, an unreadable one, one without frames or ground truth,
        or no ICFN sample at all.
    """
    files = recording_files(paths)  # one recording named twice would sit in two splits
    out = Path(out_dir).resolve()
    for f in files:
        if f.resolve() == out or out in f.resolve().parents:
            raise InputError(f"--out {out_dir} holds the recording {f}: writing the dataset "
                             "there would replace it; choose another --out")
    check_positive(icfn_every_s, "--icfn-every-s")  # inf: no sample after t = 0
    if not (curve_rate_hz > 0 and feature_rate_hz > 0):
        raise InputError("sampling intervals and rates must be > 0")
    if abs(sum(split) - 1.0) > 1e-9 or min(split) < 0:
        raise InputError(f"split shares must be >= 0 and sum to 1, got {split}")
    check_dataset_out(out_dir)
    for f in files:  # every file checked before any work
        read_replayable_session(f)
    start = time.perf_counter()
    icfn: list[dict[str, list[Any]]] = []
    seqs: list[dict[str, Any]] = []
    feats: list[dict[str, list[Any]]] = []
    curves: list[dict[str, list[Any]]] = []
    found_notes: list[str] = []
    versions: set[str] = set()
    for i, f in enumerate(files):
        with malformed_fields(f):
            rows, seq, feat, curve, note = _one(i, f, "", models, icfn_every_s,
                                                curve_rate_hz, feature_rate_hz)
        versions.add(str(read_session(f)["backend"].get("version")))
        icfn.append(rows)
        if seq is not None:
            seqs.append(seq)
            feats.append(feat)
            curves.append(curve)
        found_notes.append(note)
        if progress is not None:
            progress(i + 1, len(files))
    # Split by recording, those that give an RCFN sequence apart from the others, so
    # that train and val each get some of both whenever there are enough.
    splits = [""] * len(files)
    with_sequence = {int(seq["sequence"]) for seq in seqs}
    for group in (sorted(with_sequence),
                  [i for i in range(len(files)) if i not in with_sequence]):
        for i, label in zip(group, _splits(len(group), seed, split), strict=True):
            splits[i] = label
    for rows in icfn:
        rows["split"] = [splits[e] for e in rows["episode"]]
    for seq in seqs:
        seq["split"] = splits[seq["sequence"]]
    notes = {str(f): f"{splits[i]}: {found_notes[i]}" for i, f in enumerate(files)}
    tables = {
        "icfn": _frame(icfn, _ICFN_COLUMNS),
        "rcfn_sequences": _frame([{k: [v] for k, v in s.items()} for s in seqs], _SEQ_COLUMNS),
        "rcfn_features": _frame(feats, ("sequence", "t_s", *RCFN_SCHEMA.names)),
        "rcfn_curves": _frame(curves, ("sequence", "t_s", "force_n")),
    }
    if tables["icfn"].empty:
        raise InputError("no ICFN sample in the recordings (no frame with features and truth)")
    counts_split = split_counts(tables)
    warnings = training_gaps(counts_split, {
        "icfn": "recordings with frames and a force truth in both",
        "rcfn_sequences": f"fixed-aperture holds of {MIN_HOLD_S:g} s or more in both"})
    manifest = {
        "format": DATASET_FORMAT,
        "format_version": DATASET_VERSION,
        "relaxgrip_version": __version__,
        "twin_version": ", ".join(sorted(versions)),
        "icfn_schema": ICFN_SCHEMA.to_dict(),
        "rcfn_schema": RCFN_SCHEMA.to_dict(),
        "spec": {"source": "recordings", "recordings": [str(f) for f in files], "seed": seed,
                 "icfn_every_s": icfn_every_s, "curve_rate_hz": curve_rate_hz,
                 "feature_rate_hz": feature_rate_hz, "split": list(split)},
        "counts": {"icfn_samples": len(tables["icfn"]), "icfn_dropped": 0,
                   "rcfn_sequences": len(tables["rcfn_sequences"]), "rcfn_dropped":
                   len(files) - len(seqs), "splits": counts_split},
        "noise": {"source": "the backends that recorded them (see each recording's session)"},
        "notes": notes,
        "warnings": warnings,
        "build": {"seconds": time.perf_counter() - start},
    }
    write_dataset(out_dir, tables, manifest)
    return manifest


def _frame(parts: list[dict[str, list[Any]]], columns: Sequence[str]) -> pd.DataFrame:
    frames = [pd.DataFrame(p) for p in parts if any(len(v) for v in p.values())]
    if not frames:
        return pd.DataFrame({c: pd.Series(dtype="float64") for c in columns})
    return pd.concat(frames, ignore_index=True)[list(columns)]
