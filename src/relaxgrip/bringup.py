"""``relaxgrip bringup RIG.toml --out DIR``: a gripper's models from its own recordings.

The steps, each recorded in ``DIR/bringup.json`` when it is done, so that a
bring-up stopped anywhere (Ctrl-C, a fault, the end of the day) resumes at
the step it was in:

1. **data takes** (:func:`~relaxgrip.experiments.bringup.plan_for_rig`):
   fixed-aperture holds over the rig's forces, temperatures and contact
   positions, recorded with the force reference (``DIR/recordings``);
2. **dataset** (``DIR/dataset``): :func:`~relaxgrip.recording.dataset.dataset_from_recordings`,
   labelled by the force reference;
3. **models** (``DIR/models``): the ICFN and RCFN trained on it, and the
   observer identified on its holds (``DIR/models/observer``);
4. **calibration takes** and **calibration**: at most twelve regulated
   ``relax`` holds, recorded, and relax's closed-loop error measured on them
   against the force reference, written into ``DIR/models``;
5. **check**: one hold with the calibrated models;
6. **report** (``DIR/report.md`` and its figures): the models on the
   held-out (test) recordings, and the check hold.

Every recording is written beside its place and renamed into it when the
take is over: an interrupted take leaves nothing and is taken again.  A
directory holds one rig's bring-up: another rig's (by its name and its
gripper's description) is refused.  On the twin (``backend="twin"``) every
take runs on the twin of the rig, with seeds from ``seed``; on a serial rig
the operator is told what to do before each take.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from relaxgrip.errors import InputError
from relaxgrip.experiments.bringup import BringupPlan, Take, plan_for_rig, record_take
from relaxgrip.fileio import json_digest, write_text_atomically
from relaxgrip.hardware.rig_file import RigFile, load_rig

__all__ = ["STATE_NAME", "Bringup", "rig_fingerprint"]

#: The state file of a bring-up directory.
STATE_NAME = "bringup.json"
#: Its format name and version.
STATE_FORMAT = "relaxgrip-bringup"
STATE_VERSION = 1

Progress = Callable[[str, int, int], None]
"""``progress(step, done, total)`` after every step."""
Prompt = Callable[[str], None]
"""Tells the operator what to do and returns when they have done it (a serial rig)."""


def rig_fingerprint(rig: RigFile) -> str:
    """What makes a rig the same gripper: its name and its gripper's description.

    The cameras' intrinsics and the zero pose are left out: they are measured
    again (``calibrate-camera``, ``zero-pose``) without the gripper changing.
    """
    parts = [rig.name, repr(rig.finger), repr(rig.marker), repr(rig.stiffness),
             repr(rig.relax), repr(rig.heat), repr(rig.motor), repr(rig.force_ref.source),
             repr(rig.force_ball), repr(rig.open_aperture_m), repr(rig.marker_finger)]
    return json_digest(parts)


@dataclass
class _State:
    data: dict[str, Any]

    @property
    def done(self) -> list[str]:
        steps: list[str] = self.data["done"]
        return steps


class Bringup:
    """One rig's bring-up in a directory (see the module).

    Parameters
    ----------
    rig_path : Path
        The rig file.
    out : Path
        The bring-up directory (made if absent; resumed if it holds this rig's).
    backend : str
        ``twin`` or ``serial:RIG.toml`` (the same rig file).
    seed : int
        The plan's seed and the twin's (design seeds 0-4999).
    takes : int
        Data takes (the plan's size).
    hold_s : float
        Length of every hold (s).
    calibration_holds : int
        Regulated holds of the calibration (at most 12).
    progress : callable, optional
        Told of every step done.
    prompt : callable, optional
        Tells the operator what to do (required on a serial rig).
    """

    def __init__(self, rig_path: Path, out: Path, backend: str = "twin", seed: int = 0,
                 takes: int = 24, hold_s: float = 100.0, calibration_holds: int = 12,
                 progress: Progress | None = None, prompt: Prompt | None = None) -> None:
        self.rig_path = Path(rig_path)
        self.rig = load_rig(self.rig_path)
        if backend != "twin":
            if not backend.startswith("serial:"):
                raise InputError(f"--backend must be twin or serial:RIG.toml, got {backend!r}")
            other = Path(backend.removeprefix("serial:"))
            if not other.exists() or other.resolve() != self.rig_path.resolve():
                raise InputError(f"--backend {backend}: a bring-up runs on the rig it brings "
                                 f"up: serial:{self.rig_path}")
            if prompt is None:
                raise InputError("a bring-up on a serial rig needs an operator to prompt")
        self.serial = backend != "twin"
        self.backend = backend
        self.out = Path(out)
        self.plan: BringupPlan = plan_for_rig(self.rig, takes, hold_s, seed, calibration_holds)
        self.seed = seed
        self.progress = progress
        self.prompt = prompt
        self.state = self._open_state()

    # -- the directory --------------------------------------------------------------
    @property
    def state_path(self) -> Path:
        """The state file."""
        return self.out / STATE_NAME

    def _settings(self) -> dict[str, Any]:
        return {"backend": "twin" if not self.serial else "serial", "seed": self.seed,
                "plan": self.plan.to_dict()}

    def _open_state(self) -> _State:
        out = self.out
        if out.exists() and not out.is_dir():
            raise InputError(f"--out {out} exists and is not a directory")
        rig = {"name": self.rig.name, "path": str(self.rig_path.resolve()),
               "fingerprint": rig_fingerprint(self.rig)}
        if out.is_dir() and any(out.iterdir()):
            try:
                data = json.loads(self.state_path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                raise InputError(f"--out {out} is not empty and holds no bring-up "
                                 f"({STATE_NAME}): choose another directory") from None
            if not isinstance(data, dict) or data.get("format") != STATE_FORMAT:
                raise InputError(f"--out {out}: {STATE_NAME} is not a relaxgrip bring-up's")
            if data.get("version") != STATE_VERSION:
                raise InputError(f"--out {out}: a bring-up of version {data.get('version')}, "
                                 f"this relaxgrip resumes version {STATE_VERSION}")
            theirs = data.get("rig", {})
            if theirs.get("fingerprint") != rig["fingerprint"]:
                raise InputError(
                    f"--out {out} is the bring-up of rig {theirs.get('name')!r} "
                    f"({theirs.get('path')}), not of {self.rig.name!r} ({self.rig_path}): "
                    "another rig's directory is not resumed; choose another --out")
            if data.get("settings") != self._settings():
                raise InputError(f"--out {out} was started with other settings (backend, "
                                 "--seed, --takes, --hold-s or --calibration-holds): resume "
                                 "it with the same ones, or choose another --out")
            return _State(data)
        out.mkdir(parents=True, exist_ok=True)
        state = _State({"format": STATE_FORMAT, "version": STATE_VERSION, "rig": rig,
                        "settings": self._settings(), "done": [], "results": {}})
        self._save(state)
        return state

    def _save(self, state: _State | None = None) -> None:
        state = state if state is not None else self.state
        write_text_atomically(self.state_path, json.dumps(state.data, indent=1) + "\n")

    def _mark(self, step: str, result: Any = None) -> None:
        self.state.done.append(step)
        if result is not None:
            self.state.data["results"][step] = result
        self._save()

    # -- the steps ----------------------------------------------------------------
    def steps(self) -> list[str]:
        """Every step of the bring-up, in order."""
        return ([f"take {t.name}" for t in self.plan.data] + ["dataset", "models"]
                + [f"take {t.name}" for t in self.plan.calibration]
                + ["calibration", "check", "report"])

    def run(self) -> dict[str, Any]:
        """Run every step not yet done; return the results.

        Raises
        ------
        InputError
            A step that cannot be done (a take that never reached its hold,
            a fault of the rig); the steps before it stay done.
        KeyboardInterrupt
            A stop signal: the step it came in is taken again on resuming.
        """
        steps = self.steps()
        total = len(steps)
        self._tell_progress(steps)
        gripper = None
        try:
            for step in steps:
                if step in self.state.done:
                    continue
                if step.startswith("take "):
                    take = self._take_named(step.removeprefix("take "))
                    if self.serial and gripper is None:
                        gripper = self._open_gripper()
                    self._record(take, gripper)
                    self._mark(step)
                else:
                    result = getattr(self, f"_step_{step}")()
                    self._mark(step, result)
                if self.progress is not None:
                    self.progress(step, len(self.state.done), total)
        finally:
            if gripper is not None:
                gripper.close()
        results: dict[str, Any] = self.state.data["results"]
        return results

    def _tell_progress(self, steps: list[str]) -> None:
        if self.progress is not None:
            self.progress("resumed" if self.state.done else "started",
                          len(self.state.done), len(steps))

    def _take_named(self, name: str) -> Take:
        for take in (*self.plan.data, *self.plan.calibration):
            if take.name == name:
                return take
        raise AssertionError(name)

    @property
    def recordings(self) -> Path:
        """Where the takes are recorded."""
        return self.out / "recordings"

    @property
    def models_dir(self) -> Path:
        """The model directory the bring-up writes (``--models``)."""
        return self.out / "models"

    def _open_gripper(self) -> Any:
        from relaxgrip.clock import WallClock
        from relaxgrip.hardware.gripper import open_rig_gripper
        from relaxgrip.perception.marker import warm_up

        warm_up()
        clock = WallClock()
        return open_rig_gripper(self.rig, clock), clock

    def _record(self, take: Take, gripper: Any) -> None:
        from relaxgrip.learning.observer import load_observer
        from relaxgrip.learning.store import load_models
        from relaxgrip.learning.training import load_default_models
        from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA

        self.recordings.mkdir(exist_ok=True)
        final = self.recordings / take.name
        part = self.recordings / f".{take.name}.part"
        if take.kind == "data":
            models, observer = load_default_models(), None
        else:
            models = load_models(self.models_dir, icfn_feature_schema=ICFN_SCHEMA,
                                 rcfn_feature_schema=RCFN_SCHEMA)
            observer = load_observer(self.models_dir / "observer")
        try:
            if not self.serial:
                from relaxgrip.hardware.rig_twin import twin_config_for_rig

                record_take(take, self.plan.hold_s, part, models,
                            config=twin_config_for_rig(self.rig), observer=observer)
            else:
                assert self.prompt is not None
                device, clock = gripper
                self.prompt(take.instruction())
                device.reset()
                device.tare_force_ref()
                record_take(take, self.plan.hold_s, part, models, rig=self.rig,
                            gripper=device, clock=clock, observer=observer)
            part.replace(final)
        finally:
            part.unlink(missing_ok=True)

    def _files(self, kind: str) -> list[Path]:
        takes = self.plan.data if kind == "data" else self.plan.calibration
        return [self.recordings / t.name for t in takes]

    def _step_dataset(self) -> dict[str, Any]:
        from relaxgrip.learning.training import load_default_models
        from relaxgrip.recording.dataset import dataset_from_recordings

        data = self.out / "dataset"
        manifest = dataset_from_recordings(self._files("data"), data, load_default_models(),
                                           seed=self.seed)
        counts: dict[str, Any] = manifest["counts"]
        return {"counts": counts, "notes": manifest["notes"]}

    def _step_models(self) -> dict[str, Any]:
        from relaxgrip.learning.datastore import load_dataset
        from relaxgrip.learning.observer import fit_observer, load_default_observer
        from relaxgrip.learning.training import train_models

        start = time.perf_counter()
        staging = self.out / ".models.part"
        shutil.rmtree(staging, ignore_errors=True)
        dataset = load_dataset(self.out / "dataset")
        trained = train_models(dataset, random_state=self.seed, history=load_default_observer())
        trained.save(staging)
        # Holds of 20-60 s do not separate three relaxation times.
        terms = 3 if self.plan.hold_s >= 80.0 else 2
        observer = fit_observer(self.out / "dataset", staging / "observer",
                                models_dir=staging, n_terms=terms)
        shutil.rmtree(self.models_dir, ignore_errors=True)
        staging.replace(self.models_dir)
        record = trained.training
        return {"seconds": time.perf_counter() - start,
                "icfn_val_mae_n": min(r["val_mae_n"] for r in trained.icfn_candidates),
                "observer_terms": observer.n_terms, "observer_sequences": observer.n_sequences_,
                "training_keys": sorted(record)}

    def _step_calibration(self) -> dict[str, Any]:
        from relaxgrip.experiments.recorded_calibration import calibration_from_recordings
        from relaxgrip.learning.store import load_models, set_hold_bias
        from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA

        bundle = load_models(self.models_dir, icfn_feature_schema=ICFN_SCHEMA,
                             rcfn_feature_schema=RCFN_SCHEMA)
        files = self._files("calibration")
        result = calibration_from_recordings(files, bundle)
        record = {**result.record(),
                  "commands": [f"relaxgrip bringup {self.rig_path} --out {self.out}"]}
        set_hold_bias(self.models_dir, result.bias, record, measured_on=bundle.manifest)
        summary = result.summary()
        return {"holds": len(files),
                "conditions": {k: {"est_error_mean_n": v["est_error_mean_n"],
                                   "mae_n": v["mae_n"]} for k, v in summary.items()}}

    def _step_check(self) -> dict[str, Any]:
        from dataclasses import replace

        from relaxgrip.experiments.controlled_hold import run_hold
        from relaxgrip.learning.observer import load_observer
        from relaxgrip.learning.store import load_models
        from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA

        take = self.plan.check
        bundle = load_models(self.models_dir, icfn_feature_schema=ICFN_SCHEMA,
                             rcfn_feature_schema=RCFN_SCHEMA)
        observer = load_observer(self.models_dir / "observer")
        out: dict[str, Any] = {}
        for estimator in ("relax", "observer"):
            if self.serial:
                assert self.prompt is not None
                self.prompt(f"check hold ({estimator}): " + take.instruction())
                result = run_hold(estimator, take.force_n, self.plan.hold_s, take.temp_c,
                                  models=bundle, observer=observer, backend=self.backend)
            else:
                from relaxgrip.hardware.rig_twin import twin_config_for_rig

                cfg = replace(twin_config_for_rig(self.rig),
                              contact_position_m=take.contact_mm * 1e-3)
                result = run_hold(estimator, take.force_n, self.plan.hold_s, take.temp_c,
                                  take.seed, bundle, config=cfg, observer=observer)
            d = result.to_dict()
            d.pop("events", None)
            out[estimator] = d
            from relaxgrip.plots.holding import plot_hold

            plot_hold(result, self.out / f"check-{estimator}.png")
        return out

    def _step_report(self) -> dict[str, Any]:
        from relaxgrip.learning.datastore import load_dataset
        from relaxgrip.learning.evaluation import evaluate
        from relaxgrip.learning.store import load_models
        from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
        from relaxgrip.plots.accuracy import plot_accuracy

        dataset = load_dataset(self.out / "dataset")
        bundle = load_models(self.models_dir, icfn_feature_schema=ICFN_SCHEMA,
                             rcfn_feature_schema=RCFN_SCHEMA)
        split = "test" if (dataset.icfn["split"] == "test").any() else "val"
        evaluation = evaluate(dataset, bundle, split)
        plot_accuracy(evaluation, self.out / "accuracy.png")
        scores = evaluation.to_dict()
        results = self.state.data["results"]
        write_text_atomically(self.out / "report.md", _report_text(self, split, scores, results))
        return {"split": split, "icfn": scores["icfn"], "rcfn": scores["rcfn"]}


def _report_text(b: Bringup, split: str, scores: dict[str, Any],
                 results: dict[str, Any]) -> str:
    """The bring-up's ``report.md``."""
    icfn, rcfn = scores["icfn"], scores["rcfn"]
    counts = results["dataset"]["counts"]
    plan = b.plan
    backend = "the twin of the rig" if not b.serial else "the rig itself (serial)"
    lines = [
        f"# Bring-up of {b.rig.name}",
        "",
        f"Rig file `{b.rig_path}`, on {backend}, seed {b.seed}: {len(plan.data)} data holds "
        f"and {len(plan.calibration)} calibration holds of {plan.hold_s:g} s, every one "
        "labelled by the rig's force reference (`/relaxgrip/force_ref`), never by the twin's "
        "truth.  `models/` is the model directory (`--models`), with the observer in "
        "`models/observer`.",
        "",
        "## Dataset",
        "",
        f"{counts['icfn_samples']} ICFN samples and {counts['rcfn_sequences']} RCFN sequences "
        "from the data holds (`dataset/`), split by recording.",
        "",
        f"## The models on the held-out ({split}) recordings",
        "",
        "| metric | value | paper |",
        "|---|---|---|",
        f"| ICFN MAE | {icfn['mae_n']:.3f} N | 0.651 N |",
        f"| ICFN RMSE | {icfn['rmse_n']:.3f} N | 0.886 N |",
        f"| ICFN R² | {icfn['r2']:.3f} | 0.848 |",
        f"| RCFN NRMSE mean / median | {rcfn['nrmse_mean']:.3f} / {rcfn['nrmse_median']:.3f} "
        "| 0.160 / 0.118 |",
        f"| RCFN AUC_rel mean / median | {rcfn['auc_rel_mean']:.3f} / "
        f"{rcfn['auc_rel_median']:.3f} | 0.065 / 0.049 |",
        f"| RCFN curve correlation | {rcfn['corr_mean']:.4f} | 0.990 |",
        "",
        "![accuracy](accuracy.png)",
        "",
        "## Calibration",
        "",
        f"relax's closed-loop error, estimate − force reference over the steady state, on "
        f"{results['calibration']['holds']} regulated holds (taken off relax's estimate):",
        "",
        "| condition | mean error (N) | reference − target MAE (N) |",
        "|---|---|---|",
    ]
    for name, c in results["calibration"]["conditions"].items():
        lines.append(f"| {name} | {c['est_error_mean_n']:+.3f} | {c['mae_n']:.3f} |")
    check = results["check"]
    lines += ["", f"## Check hold: {plan.check.force_n:g} N at {plan.check.temp_c:g} °C, "
              f"{plan.hold_s:g} s", "",
              "| estimator | MAE from the target (N) | mean (N) | estimate − true (N) |",
              "|---|---|---|---|"]
    for name, d in check.items():
        lines.append(f"| {name} | {d['mae_n']:.3f} | {d['mean_signed_error_n']:+.3f} | "
                     f"{d['est_error_mean_n']:+.3f} |")
    what = ("the twin's contact force" if not b.serial else "the force reference")
    lines += ["", f"The check's true force is {what}.", "",
              "![relax](check-relax.png)", "", "![observer](check-observer.png)", ""]
    return "\n".join(lines)


def minutes(seconds: float) -> str:
    """``seconds`` as ``m:ss``."""
    if not math.isfinite(seconds):
        return "–"
    return f"{int(seconds // 60)}:{int(seconds % 60):02d}"
