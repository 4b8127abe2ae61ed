"""Which models a recording ran with, and which to replay or calibrate it with.

A recording's session names its estimator's models (``models``: the
directory they were loaded from, the sha256 of each model file, a digest of
the calibration taken off the estimate, and for the ``observer`` its
directory, file sha256 and band scales; :meth:`ModelBundle.provenance`).
Replaying a recording, or calibrating on it, with other models than it ran
with measures those models on frames another loop made: legitimate when it
is meant (a lab's new models on its old recordings), a silent error when the
user only forgot ``--models``.  So:

* without ``--models`` (``--observer``) the recordings' own models are used:
  the shipped ones, or the directory they were loaded from if it still holds
  them; anything else is an error naming that directory
  (:func:`recorded_models`, :func:`recorded_observer`);
* with them, every difference is said (:func:`differences_note`).

Recordings made before sessions named their models name none: the shipped
models are used for them, as before.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

from relaxgrip.errors import InputError
from relaxgrip.fileio import one_line
from relaxgrip.learning.observer import (
    ObserverFileError,
    ObserverModel,
    default_observer_dir,
    load_observer,
)
from relaxgrip.learning.store import ModelBundle, ModelFileError, load_models, model_checksums
from relaxgrip.learning.training import default_models_dir
from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
from relaxgrip.recording.reader import read_session

__all__ = ["differences_note", "model_differences", "recorded_models", "recorded_observer"]

_T = TypeVar("_T")


def _named(paths: Sequence[Path], part: str | None) -> dict[str, tuple[dict[str, Any], Path]]:
    """The models (``part`` None) or observers the recordings name, by checksum, with the
    first recording naming each."""
    named: dict[str, tuple[dict[str, Any], Path]] = {}
    for path in paths:
        models = read_session(Path(path)).get("models")
        if not isinstance(models, dict):
            continue
        entry = models if part is None else models.get(part)
        if not isinstance(entry, dict):
            continue
        key = str(entry.get("sha256"))
        named.setdefault(key, (entry, Path(path)))
    return named


def _one(named: dict[str, tuple[dict[str, Any], Path]], what: str, flag: str
         ) -> tuple[dict[str, Any], Path] | None:
    if len(named) > 1:
        (_, a), (_, b) = list(named.values())[:2]
        raise InputError(f"{a}, {b}: the recordings ran with different {what}: "
                         f"give the ones to use with {flag}")
    return next(iter(named.values()), None)


def _first_holding(entry: Mapping[str, Any], shipped: Path, load: Callable[[Path], _T],
                   error: type[Exception], holds: Callable[[_T], bool]
                   ) -> tuple[_T, str] | tuple[None, str]:
    """What ``load`` reads from the shipped directory, or else from the one a recording names
    (``entry["directory"]``), if it ``holds`` what the recording ran with; if neither does,
    None and what became of the one named: "" (gone), "it holds others now" or why it does
    not load (a file damaged in a copy)."""
    why = ""  # of the directory looked in last: the named one
    for directory in (shipped, entry.get("directory")):
        why = ""
        if not directory or not Path(directory).is_dir():
            continue
        try:
            loaded = load(Path(directory))
        except error as exc:
            why = one_line(exc)
            continue
        if holds(loaded):
            return loaded, ""
        why = "it holds others now"
    return None, why


def recorded_models(paths: Sequence[Path]) -> ModelBundle | None:
    """The models the recordings ran with, loaded; None when they name none.

    Raises
    ------
    InputError
        The recordings name different models, or models that are neither the
        shipped ones nor still in the directory they were loaded from.
    """
    found = _one(_named(paths, None), "models", "--models")
    if found is None:
        return None
    entry, path = found
    wanted = entry.get("sha256")
    bundle, why = _first_holding(
        entry, default_models_dir(),
        lambda d: load_models(d, icfn_feature_schema=ICFN_SCHEMA, rcfn_feature_schema=RCFN_SCHEMA),
        ModelFileError, lambda b: model_checksums(b.manifest) == wanted)
    if bundle is not None:
        return bundle
    raise InputError(
        f"{path}: it ran with the models in {entry.get('directory')} "
        f"(icfn sha256 {str((wanted or {}).get('icfn', '?'))[:12]}…), which are not there now"
        f"{f' ({why})' if why else ''}: give a copy of them with --models")


def recorded_observer(paths: Sequence[Path]) -> ObserverModel | None:
    """The observer the recordings ran with, loaded; None when they name none.

    Raises
    ------
    InputError
        As :func:`recorded_models`, for the observer.
    """
    found = _one(_named(paths, "observer"), "observers", "--observer")
    if found is None:
        return None
    entry, path = found
    observer, why = _first_holding(
        entry, default_observer_dir(), load_observer, ObserverFileError,
        lambda o: o.source is not None and o.source[1] == entry.get("sha256"))
    if observer is not None:
        return observer
    raise InputError(
        f"{path}: it ran with the observer in {entry.get('directory')} "
        f"(sha256 {str(entry.get('sha256'))[:12]}…), which is not there now"
        f"{f' ({why})' if why else ''}: give a copy of it with --observer")


def model_differences(recorded: Mapping[str, Any] | None, used: Mapping[str, Any]) -> list[str]:
    """What of a recording's models (its session's ``models``) ``used`` does not have.

    Model files by their section (``icfn``, ``rcfn``, ``icfn_unrelaxed``,
    ``history``), then ``calibration`` (the closed-loop error taken off the
    estimate), ``observer`` (its file) and ``observer band`` (its scales).
    Nothing for a recording that names no models.
    """
    if not isinstance(recorded, Mapping):
        return []
    out: list[str] = []
    files, now = recorded.get("sha256") or {}, used.get("sha256") or {}
    out += [k for k in sorted(set(files) | set(now)) if files.get(k) != now.get(k)]
    if recorded.get("hold_bias_sha256") != used.get("hold_bias_sha256"):
        out.append("calibration")
    observer, observer_now = recorded.get("observer"), used.get("observer")
    if isinstance(observer, Mapping) and isinstance(observer_now, Mapping):
        if observer.get("sha256") != observer_now.get("sha256"):
            out.append("observer")
        elif any(observer.get(k, default) != observer_now.get(k, default)
                 for k, default in (("band_scale", None), ("drift_scale", None),
                                    # recorded before the floor and the temperature
                                    # factors: none
                                    ("band_floor_n", 0.0), ("band_temps_c", []),
                                    ("band_temp_factors", []))):
            out.append("observer band")
    return out


def differences_note(paths: Sequence[Path], used: Mapping[str, Any],
                     ignore: Sequence[str] = ()) -> str | None:
    """One line saying which recordings ran with other models than ``used`` (an
    estimator's :attr:`provenance`), and in what; None when none did."""
    differing: list[tuple[Path, list[str]]] = []
    for path in paths:
        diff = [d for d in model_differences(read_session(Path(path)).get("models"), used)
                if d not in ignore]
        if diff:
            differing.append((Path(path), diff))
    if not differing:
        return None
    first, parts = differing[0]
    more = f" and {len(differing) - 1} more" if len(differing) > 1 else ""
    return (f"{first}{more} ran with other models than these ({', '.join(parts)} differ): "
            "the figures are these models' on frames the recorded ones acted on")
