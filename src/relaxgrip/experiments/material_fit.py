"""The finger's material from multi-temperature measurements (``relaxgrip fit-material``).

:func:`load_measurements` reads CSV files in two conventions and converts
them to SI:

* **pyvisco's**: a row of names and a row of units; time domain
  ``t, E_relax, T, Set`` (or ``G_relax``), frequency domain
  ``f, E_stor, E_loss, T, Set`` (or ``G_stor, G_loss``); units ``s``/``ms``/``min``,
  ``Hz``/``rad/s``, ``Pa``/``kPa``/``MPa``/``GPa``, ``C``/``°C``/``K``
  (``Set`` optional, its unit ``-``).
* **the project's**: one row of names carrying their units, as everywhere in
  relaxgrip: ``time_s``, ``freq_hz`` or ``omega_rad_s``; ``temp_c`` or
  ``temp_k``; ``modulus_<u>`` (time domain) or ``storage_<u>`` and
  ``loss_<u>`` with ``<u>`` one of ``pa, kpa, mpa, gpa``; an optional ``set``;
  ``shear`` in a column name's place of ``modulus``/``storage``/``loss`` is
  not used: a shear modulus is ``g_modulus_<u>``, ``g_storage_<u>``,
  ``g_loss_<u>``.  A time-domain record of a specimen may give
  ``force_n`` and ``displacement_mm`` instead of the modulus, with the
  specimen's gauge length and cross-section (``E = (F / A) / (x / L)``).

Without a set column, a set is a run of rows within 1 K of its first row's
temperature.  Within a set, time (frequency) runs one way, either way.

:func:`fit_material` runs the fit of :mod:`relaxgrip.physics.material_fit`
and returns a :class:`MaterialFitResult`, whose :meth:`~MaterialFitResult.to_dict`
is what ``--json`` prints and whose :attr:`~MaterialFitResult.material` is the
material file ``--out`` writes.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.fileio import check_input_file, read_text_csv
from relaxgrip.physics.material import SHIFT_PARAMS, Material, log10_shift
from relaxgrip.physics.material_fit import (
    MIN_OVERLAP_POINTS,
    MeasuredSet,
    Measurements,
    PronyChoice,
    ShiftFactors,
    ShiftLawFit,
    data_scatter_log10,
    master_rms_log10,
    model_residuals_log10,
    refine,
    select_shift_law,
    select_terms,
    shift_factors,
    to_material,
)
from relaxgrip.validate import parse_number

FloatArray = NDArray[np.float64]

__all__ = ["DEFAULT_MAX_TERMS", "MaterialFitResult", "fit_material", "load_measurements"]

#: Most Prony terms the selection tries.
DEFAULT_MAX_TERMS = 24
_MAX_BYTES = 64 * 1024 * 1024
_SET_TOLERANCE_K = 1.0

_MODULUS_UNITS = {"pa": 1.0, "kpa": 1e3, "mpa": 1e6, "gpa": 1e9}
_TIME_UNITS = {"s": 1.0, "ms": 1e-3, "min": 60.0}
_FREQ_UNITS = {"hz": 2.0 * math.pi, "rad/s": 1.0, "1/s": 1.0}  # to rad/s
_TEMP_UNITS = ("c", "°c", "degc", "k")


@dataclass(frozen=True)
class _Column:
    kind: str  # x, y, y2, temp, set, force, disp
    index: int
    scale: float = 1.0
    offset: float = 0.0


def _read_rows(path: Path) -> list[tuple[int, list[str]]]:
    path = check_input_file(path, "measurement file", InputError)
    if path.stat().st_size > _MAX_BYTES:
        raise InputError(f"{path}: larger than {_MAX_BYTES // (1024 * 1024)} MB, "
                         "not a measurement CSV")
    text = read_text_csv(path, InputError)
    first = text.lstrip().split("\n", 1)[0]
    delimiter = next((d for d in (";", "\t") if "," not in first and d in first), ",")
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
    try:
        rows = [(reader.line_num, row) for row in reader if any(c.strip() for c in row)]
    except csv.Error as exc:
        raise InputError(f"{path}, line {reader.line_num}: not a valid CSV file: {exc}") from None
    if not rows:
        raise InputError(f"{path}: empty file")
    return rows


def _is_number(text: str) -> bool:
    try:
        parse_number(text.strip())
    except ValueError:
        return False
    return True


_PROJECT = re.compile(r"^(g_)?(modulus|storage|loss)_(pa|kpa|mpa|gpa)$")


def _project_columns(path: Path, header: list[str]) -> tuple[str, str, dict[str, _Column]]:
    cols: dict[str, _Column] = {}
    shear: set[bool] = set()
    for i, name in enumerate(header):
        key = name.strip().lower()
        if key in ("time_s", "freq_hz", "omega_rad_s"):
            scale = {"time_s": 1.0, "freq_hz": 2.0 * math.pi, "omega_rad_s": 1.0}[key]
            kind = "x"
        elif key in ("temp_c", "temp_k"):
            kind, scale = "temp", 1.0
            cols[kind] = _Column(kind, i, 1.0, -273.15 if key == "temp_k" else 0.0)
            continue
        elif key == "set":
            kind, scale = "set", 1.0
        elif key == "force_n":
            kind, scale = "force", 1.0
        elif key == "displacement_mm":
            kind, scale = "disp", 1e-3
        elif (m := _PROJECT.match(key)) is not None:
            shear.add(m.group(1) is not None)
            kind = {"modulus": "y", "storage": "y", "loss": "y2"}[m.group(2)]
            scale = _MODULUS_UNITS[m.group(3)]
        else:
            continue
        if kind in cols:
            raise InputError(f"{path}: the header has two {_kind_name(kind)} columns; keep one")
        cols[kind] = _Column(kind, i, scale)
    if len(shear) > 1:
        raise InputError(f"{path}: mixes tensile and shear (g_) moduli")
    domain = "time" if any(h.strip().lower() == "time_s" for h in header) else "freq"
    if domain == "freq" and "y2" not in cols:
        raise InputError(f"{path}: a frequency-domain file needs loss_<unit> besides "
                         "storage_<unit>")
    if domain == "time" and "y2" in cols:
        raise InputError(f"{path}: loss_<unit> belongs to frequency-domain data (freq_hz)")
    if "temp" not in cols:
        raise InputError(f"{path}: missing column temp_c (or temp_k)")
    if "y" not in cols and not ("force" in cols and "disp" in cols):
        want = "modulus_<unit> (or force_n and displacement_mm)" if domain == "time" \
            else "storage_<unit>"
        raise InputError(f"{path}: missing column {want}, <unit> one of pa, kpa, mpa, gpa")
    return domain, "G" if shear == {True} else "E", cols


def _kind_name(kind: str) -> str:
    """A column kind as a user reads it."""
    return {"x": "time/frequency", "y": "modulus (storage)", "y2": "loss modulus",
            "temp": "temperature", "set": "set", "force": "force", "disp": "displacement"}[kind]


_PYVISCO_X = {"t": "time", "f": "freq", "omega": "freq"}


def _pyvisco_columns(path: Path, header: list[str], units: list[str], units_line: int
                     ) -> tuple[str, str, dict[str, _Column]]:
    names = [h.strip() for h in header]
    cols: dict[str, _Column] = {}
    domain = None
    moduli: set[str] = set()
    for i, name in enumerate(names):
        unit = units[i].strip() if i < len(units) else ""
        low = unit.lower().replace(" ", "")
        if name in _PYVISCO_X:
            domain = _PYVISCO_X[name]
            table = _TIME_UNITS if domain == "time" else _FREQ_UNITS
            if low not in table:
                raise InputError(f"{path}, line {units_line}: unknown unit {unit!r} of column "
                                 f"{name} (expected one of {', '.join(table)})")
            scale = table[low]
            if name == "omega" and low == "hz":
                scale = 2.0 * math.pi
            cols["x"] = _Column("x", i, scale)
        elif re.fullmatch(r"[EG]_(relax|stor|loss)", name):
            moduli.add(name[0])
            if low not in _MODULUS_UNITS:
                raise InputError(f"{path}, line {units_line}: unknown unit {unit!r} of column "
                                 f"{name} (expected one of Pa, kPa, MPa, GPa)")
            kind = "y2" if name.endswith("loss") else "y"
            cols[kind] = _Column(kind, i, _MODULUS_UNITS[low])
        elif name == "T":
            if low not in _TEMP_UNITS:
                raise InputError(f"{path}, line {units_line}: unknown unit {unit!r} of column T "
                                 "(expected C, °C or K)")
            cols["temp"] = _Column("temp", i, 1.0, -273.15 if low == "k" else 0.0)
        elif name == "Set":
            cols["set"] = _Column("set", i)
    if domain is None:
        raise InputError(f"{path}: no time or frequency column (pyvisco's t or f; the project's "
                         f"time_s or freq_hz); header has: {', '.join(n for n in names if n)}")
    if len(moduli) > 1:
        raise InputError(f"{path}: mixes E_ and G_ columns")
    need = ["y", "temp"] + (["y2"] if domain == "freq" else [])
    labels = {"y": "E_relax" if domain == "time" else "E_stor", "y2": "E_loss", "temp": "T"}
    missing = [labels[k] for k in need if k not in cols]
    if missing:
        raise InputError(f"{path}: missing column(s) {', '.join(missing)}")
    return domain, moduli.pop() if moduli else "E", cols


def _load_one(path: Path, gauge_length_mm: float | None, area_mm2: float | None
              ) -> tuple[str, str, list[MeasuredSet]]:
    rows = _read_rows(path)
    header_line, header = rows[0]
    project = any(h.strip().lower() in ("time_s", "freq_hz", "omega_rad_s") for h in header)
    if project:
        domain, modulus, cols = _project_columns(path, header)
        data = rows[1:]
    else:
        if len(rows) < 2 or all(_is_number(c) for c in rows[1][1] if c.strip()):
            names = ", ".join(h.strip() for h in header)
            raise InputError(f"{path}, line {rows[1][0] if len(rows) > 1 else header_line + 1}: "
                             f"missing the units row under the names ({names}); pyvisco's "
                             "format has one, e.g. s, MPa, °C, -")
        domain, modulus, cols = _pyvisco_columns(path, header, rows[1][1], rows[1][0])
        data = rows[2:]
    if "y" not in cols and (gauge_length_mm is None or area_mm2 is None):
        raise InputError(f"{path}: force_n and displacement_mm give a modulus only with the "
                         "specimen's --gauge-length-mm and --area-mm2")
    values: dict[str, list[float]] = {k: [] for k in cols}
    lines: list[int] = []
    for line, row in data:
        for kind, col in cols.items():
            text = row[col.index].strip() if col.index < len(row) else ""
            try:
                v = parse_number(text)
            except ValueError:
                raise InputError(f"{path}, line {line}: {_kind_name(kind)} value {text!r} is not "
                                 "a number") from None
            if not math.isfinite(v):
                raise InputError(f"{path}, line {line}: {_kind_name(kind)} value {text!r} is not "
                                 "finite")
            values[kind].append(v * col.scale + col.offset)
        lines.append(line)
    if not lines:
        raise InputError(f"{path}: no data rows")
    arr = {k: np.array(v) for k, v in values.items()}
    if "y" not in cols:
        assert gauge_length_mm is not None
        assert area_mm2 is not None
        strain = arr["disp"] / (gauge_length_mm * 1e-3)
        with np.errstate(divide="ignore", invalid="ignore"):
            arr["y"] = (arr["force"] / (area_mm2 * 1e-6)) / strain
        bad = np.flatnonzero(~(strain > 0))
        if bad.size:
            raise InputError(f"{path}, line {lines[bad[0]]}: displacement must be > 0 for a "
                             "relaxation modulus")
    for kind in ("y", "y2"):
        if kind in arr:
            bad = np.flatnonzero(~(arr[kind] > 0))
            if bad.size:
                what = "modulus" if kind == "y" else "loss modulus"
                raise InputError(f"{path}, line {lines[bad[0]]}: {what} must be > 0, got "
                                 f"{arr[kind][bad[0]]:.6g} Pa")
    bad = np.flatnonzero(~(arr["x"] > 0))
    if bad.size:
        what = "time" if domain == "time" else "frequency"
        raise InputError(f"{path}, line {lines[bad[0]]}: {what} must be > 0")
    bad = np.flatnonzero(arr["temp"] <= -273.15)
    if bad.size:
        raise InputError(f"{path}, line {lines[bad[0]]}: temperature below absolute zero")

    # Sets: the Set column, or runs within 1 K of their first row.
    groups: list[list[int]] = []
    if "set" in arr:
        ids: dict[float, list[int]] = {}
        for i, sid in enumerate(arr["set"]):
            ids.setdefault(float(sid), []).append(i)
        groups = list(ids.values())
        set_names = [f"set {sid:g}" for sid in ids]
    else:
        for i, t in enumerate(arr["temp"]):
            if groups and abs(t - arr["temp"][groups[-1][0]]) <= _SET_TOLERANCE_K:
                groups[-1].append(i)
            else:
                groups.append([i])
        set_names = [f"set {k} (from line {lines[g[0]]})" for k, g in enumerate(groups)]
    sets = []
    for name, g in zip(set_names, groups, strict=True):
        label = f"{path}, {name}"
        x = arr["x"][g]
        if x.size < MIN_OVERLAP_POINTS:
            raise InputError(f"{label}: {x.size} point(s), a set needs at least "
                             f"{MIN_OVERLAP_POINTS} to be shifted")
        dx = np.diff(x)
        direction = np.sign(dx[0]) if dx.size else 1.0
        wrong = np.flatnonzero(~(np.sign(dx) == direction)) if dx.size else np.array([], int)
        if dx.size and (direction == 0 or wrong.size):
            j = g[int(wrong[0]) + 1] if wrong.size else g[1]
            what = "time goes backwards" if domain == "time" else "frequency goes backwards"
            raise InputError(f"{label}, line {lines[j]}: {what} within the set "
                             f"({x[0 if direction == 0 else int(wrong[0])]:.6g} then "
                             f"{arr['x'][j]:.6g})")
        order = np.argsort(x)
        y2 = arr["y2"][g][order] if "y2" in arr else None
        sets.append(MeasuredSet(float(np.mean(arr["temp"][g])), x[order], arr["y"][g][order],
                                y2, label))
    return domain, modulus, sets


def load_measurements(paths: list[Path], gauge_length_mm: float | None = None,
                      area_mm2: float | None = None) -> Measurements:
    """Read measurement CSV files (see the module docstring) into SI :class:`Measurements`.

    Raises
    ------
    relaxgrip.errors.InputError
        One line naming the file, the line or the set, and the problem: a
        missing units row or an unknown unit, a missing column, a value that is
        not a finite number, a negative, zero or NaN modulus, time (frequency)
        going backwards within a set, a set of too few points, files of
        different domains or moduli, or a single temperature.
    """
    if not paths:
        raise InputError("no measurement file given")
    all_sets: list[MeasuredSet] = []
    kinds: set[tuple[str, str]] = set()
    for p in paths:
        domain, modulus, sets = _load_one(Path(p), gauge_length_mm, area_mm2)
        kinds.add((domain, modulus))
        if len(kinds) > 1:
            raise InputError(f"{p}: its {domain}-domain {modulus} data cannot be fitted together "
                             f"with the other files' ({', '.join(f'{d} {m}' for d, m in kinds)})")
        all_sets.extend(sets)
    temps = sorted({round(s.temp_c, 1) for s in all_sets})
    if len(temps) < 2:
        where = ", ".join(str(p) for p in paths)
        raise InputError(f"{where}: a single temperature ({temps[0]:.1f} °C); superposition "
                         "needs measurements at two or more")
    domain, modulus = kinds.pop()
    all_sets.sort(key=lambda s: s.temp_c)
    return Measurements(domain, modulus, tuple(all_sets), tuple(str(p) for p in paths))


@dataclass(frozen=True)
class MaterialFitResult:
    """Everything ``fit-material`` found.

    Attributes
    ----------
    measurements : Measurements
        What was fitted.
    material : Material
        The identified material (written by ``--out``).
    shift : ShiftFactors
        The automatic shift factors (relative to the reference's anchor set).
    log_at_ref : ndarray
        Those shift factors referenced to ``ref_temp_c`` (decades).
    law_fits : list of ShiftLawFit
        Every shift law's fit to the shift factors, with held-out errors.
    law_sigma : ndarray
        Standard errors of the chosen law's parameters after the joint refinement.
    prony : PronyChoice
        The term selection on the master curve.
    rms_log10 : float
        Whole model against every measured point.
    rms_log10_master : float
        Prony series against the shifted master curve.
    scatter_log10 : float
        The data's own scatter (the selection's target).
    """

    measurements: Measurements
    material: Material
    shift: ShiftFactors
    log_at_ref: FloatArray
    law_fits: list[ShiftLawFit]
    law_sigma: FloatArray
    prony: PronyChoice
    rms_log10: float
    rms_log10_master: float
    scatter_log10: float

    def master_curve(self) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        """Reduced coordinates (log10) and measured values of the master curve."""
        return _master(self.measurements, self.log_at_ref)

    def to_dict(self) -> dict[str, Any]:
        """The ``--json`` object."""
        mat = self.material
        names = SHIFT_PARAMS[mat.shift.model]
        temps = self.measurements.temps_c
        return {
            "ref_temp_c": mat.ref_temp_c,
            "domain": self.measurements.domain,
            "modulus": mat.modulus,
            "sources": list(self.measurements.sources),
            "shift": {
                "model": mat.shift.model,
                "params": dict(zip(names, mat.shift.params, strict=True)),
                "params_sigma": dict(zip(names, (float(v) for v in self.law_sigma), strict=True)),
                "selection": [
                    {"model": f.model, "heldout_rms_decades": f.heldout_decades,
                     "rms_decades": f.rms_decades,
                     "params": dict(zip(SHIFT_PARAMS[f.model], (float(v) for v in f.params),
                                        strict=True)),
                     "params_sigma": dict(zip(SHIFT_PARAMS[f.model],
                                              (float(v) for v in f.sigma), strict=True))}
                    for f in self.law_fits],
            },
            "log_aT": {f"{round(t):d}": float(v) for t, v in zip(temps, self.log_at_ref,
                                                                  strict=True)},
            "log_aT_sigma": {f"{round(t):d}": float(v) for t, v in zip(temps, self.shift.sigma,
                                                                        strict=True)},
            "log_aT_model": {f"{round(t):d}": float(v)
                             for t, v in zip(temps, mat.shift.log10_at(temps), strict=True)},
            "temps_c": [float(t) for t in temps],
            "prony": {
                "e_inf_pa": mat.e_inf_pa,
                "terms": [{"modulus_pa": e, "tau_s": t}
                          for e, t in zip(mat.moduli_pa, mat.tau_s, strict=True)],
                "n_terms": len(mat.tau_s),
                "selection": self.prony.table,
                "target_rms_log10": self.prony.target_log10,
            },
            "fit": {"rms_log10": self.rms_log10, "rms_log10_master": self.rms_log10_master,
                    "scatter_log10": self.scatter_log10,
                    "n_points": self.measurements.n_points},
        }


def _master(meas: Measurements, log_at: FloatArray) -> tuple[FloatArray, FloatArray,
                                                              FloatArray | None]:
    u = np.concatenate([np.log10(s.x) + meas.sign * a for s, a in zip(meas.sets, log_at,
                                                                      strict=True)])
    y = np.concatenate([s.y for s in meas.sets])
    y2 = None
    if meas.domain == "freq":
        y2 = np.concatenate([s.y2 for s in meas.sets if s.y2 is not None])
    return u, y, y2


def _file_digest(path: str) -> str:
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return ""


def fit_material(meas: Measurements, ref_temp_c: float | None = None,
                 max_terms: int = DEFAULT_MAX_TERMS) -> MaterialFitResult:
    """Identify the temperature-dependent material (the four steps of
    :mod:`relaxgrip.physics.material_fit`).

    Parameters
    ----------
    meas : Measurements
        Two or more temperatures.
    ref_temp_c : float, optional
        Reference temperature (°C); default the measured set nearest the middle
        of the list (a measured temperature near the middle).
    max_terms : int
        Most Prony terms tried.

    Raises
    ------
    relaxgrip.errors.InputError
        Neighbouring sets that do not overlap enough to shift (named), or a
        reference temperature outside the measured range.
    """
    temps = meas.temps_c
    if ref_temp_c is None:
        anchor = len(meas.sets) // 2
        ref = float(temps[anchor])
    else:
        if not (temps.min() <= ref_temp_c <= temps.max()):
            raise InputError(f"--ref-temp-c {ref_temp_c:g} is outside the measured "
                             f"{temps.min():.1f}-{temps.max():.1f} °C")
        anchor = int(np.argmin(np.abs(temps - ref_temp_c)))
        ref = float(ref_temp_c)
    sf = shift_factors(meas, anchor)
    chosen, fits = select_shift_law(sf, ref)
    law = next(f for f in fits if f.model == chosen)
    # Shift factors referenced to ``ref`` through the chosen law (exact when ref is measured).
    offset = float(log10_shift(chosen, law.params, temps[anchor], ref))
    log_at_ref = sf.log_at + offset
    u, y, y2 = _master(meas, log_at_ref)
    scatter = data_scatter_log10(u, y, y2)
    prony = select_terms(meas.domain, u, y, y2, scatter, max_terms)
    params, sigma, e_inf, moduli, taus = refine(meas, chosen, law.params, ref, prony.e_inf,
                                                prony.moduli, prony.taus)
    provenance = {
        "made_by": "relaxgrip fit-material",
        "sources": [{"file": Path(p).name, "sha256": _file_digest(p)} for p in meas.sources],
        "domain": meas.domain,
        "n_sets": len(meas.sets),
        "n_points": meas.n_points,
        "shift_model": chosen,
        "shift_params_sigma": dict(zip(SHIFT_PARAMS[chosen], (float(v) for v in sigma),
                                       strict=True)),
    }
    material = to_material(meas.modulus, chosen, params, ref, e_inf, moduli, taus,
                           (float(temps.min()), float(temps.max())), "{}")
    rms = float(np.sqrt(np.mean(model_residuals_log10(material, meas) ** 2)))
    # The Prony series against the master curve of the automatic shift factors.
    rms_master = master_rms_log10(meas.domain, u, y, y2, material.e_inf_pa,
                                  np.asarray(material.moduli_pa), np.asarray(material.tau_s))
    provenance["fit"] = {"rms_log10": rms, "rms_log10_master": rms_master,
                         "n_terms": len(material.tau_s)}
    material = Material(material.modulus, material.e_inf_pa, material.moduli_pa,
                        material.tau_s, material.shift, material.temp_range_c,
                        json.dumps(provenance, sort_keys=True))
    return MaterialFitResult(meas, material, sf, log_at_ref, fits, sigma, prony, rms,
                             rms_master, scatter)
