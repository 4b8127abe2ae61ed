"""Datasets on disk: Parquet tables, a JSON manifest and a README describing every column.

A dataset directory holds::

    icfn.parquet            one row per ICFN sample
    rcfn_sequences.parquet  one row per RCFN sequence (labels, onset features)
    rcfn_features.parquet   RCFN features along each hold
    rcfn_curves.parquet     true force along each hold
    manifest.json           format, versions, feature schemas, spec, counts, noise levels
    README.md               every column, its unit and meaning

Everything is written into a temporary sibling directory first and moved into
place at the end, so an interrupted build never leaves a half-written
dataset where a complete one is expected.
"""

from __future__ import annotations

import json
import math
import os
import secrets
import shutil
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.fileio import check_input_dir, check_output_dir, one_line, read_manifest
from relaxgrip.interrupts import deferred
from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA, FeatureSchema
from relaxgrip.physics.fitting import MAX_FORCE_N, osculating_reduced
from relaxgrip.validate import ABSOLUTE_ZERO_C

FloatArray = NDArray[np.float64]

__all__ = ["DATASET_FORMAT", "MAX_SET_TEMP_C", "Dataset", "check_dataset_out", "load_dataset",
           "split_counts", "training_gaps", "write_dataset"]

DATASET_FORMAT = "relaxgrip-dataset"
DATASET_VERSION = 1
TABLES = ("icfn", "rcfn_sequences", "rcfn_features", "rcfn_curves")

_META: dict[str, tuple[str, str]] = {
    "episode": ("", "ICFN episode (one grasp closed through a range of forces)"),
    "sequence": ("", "RCFN sequence (one hold)"),
    "condition": ("", "RCFN condition (contact x temperature x start force x object); "
                      "all repeats of a condition share a split"),
    "split": ("", "train, val or test"),
    "object": ("", "object grasped (catalogue name)"),
    "temp_set_c": ("degC", "finger temperature the heaters were set to (an ICFN episode "
                           "during a change of stiffness mode: the mean finger temperature "
                           "it began to close at)"),
    "contact_set_m": ("m", "nominal contact position along the finger"),
    "speed_mm_s": ("mm/s", "closing speed of the episode"),
    "force_set_n": ("N", "start force the hold was closed to"),
    "repeat": ("", "repeat index of the condition"),
    "t_s": ("s", "time (ICFN: twin time; RCFN: since the hold onset)"),
    "force_n": ("N", "true contact force (the label)"),
    "truth_temp_c": ("degC", "true mean finger temperature (ground truth, not a feature)"),
    "truth_deflection_m": ("m", "true finger deflection at the marker (ground truth)"),
    "truth_contact_m": ("m", "true contact position of this run (ground truth)"),
    "ir_age_s": ("s", "age of the infrared frame the thermal features came from"),
    "f0_n": ("N", "true force at the hold onset (F_inst of Eq. 9)"),
    "f_end_n": ("N", "true force at the end of the hold"),
    "amp_n": ("N", "relaxation amplitude Amp = F0 - F_end"),
    "k_n": ("N", "label: K of the reduced model anchored at F0, least squares"),
    "tau_s": ("s", "label: tau of the same fit"),
    "kappa": ("", "label: K / F0"),
    "fit_nrmse": ("", "NRMSE of that fit against the true curve"),
}


def _describe(name: str, unit: str) -> str:
    """A sentence for a feature column, from its name."""
    if name.startswith("onset_"):
        return f"at the hold onset: {_describe(name[6:], unit)}"
    axis = {"x": "x", "y": "y", "z": "z"}
    if name.startswith("marker_d") and name.endswith("2_m2"):
        return f"square of the marker translation along camera {axis[name[8]]}"
    if name.startswith("marker_d"):
        return f"marker translation from the zero pose along camera {axis[name[8]]}"
    if name.startswith("marker_r"):
        return f"marker rotation from the zero pose, Rodrigues component {axis[name[8]]}"
    if name[:2] in ("dx", "dy", "dz"):
        return f"marker translation from the zero pose along camera {name[1]}"
    if name[:2] in ("rx", "ry", "rz"):
        return f"marker rotation from the zero pose, Rodrigues component {name[1]}"
    if name.startswith("vd") or name.startswith("vr"):
        return f"rate of change over the last second of {_describe(name[1:3] + '_', unit)}"
    if name == "temp_c":
        return "mean temperature of both fingers from the infrared camera"
    finger = f"finger {name[1]}"
    if "_beam" in name:
        return f"{finger}, infrared temperature of beam region {name.split('beam')[1][0]}"
    what = {"mean": "mean", "max": "maximum", "min": "minimum", "std": "spread (std)"}
    for key, word in what.items():
        if f"_temp_{key}" in name:
            return f"{finger}, {word} of the infrared temperature over its top face"
    if "_grad_" in name:
        return f"{finger}, temperature gradient from root to tip"
    return name


def _columns_table(columns: list[str]) -> str:
    units = dict(zip(ICFN_SCHEMA.names, ICFN_SCHEMA.units, strict=True))
    units.update(zip(RCFN_SCHEMA.names, RCFN_SCHEMA.units, strict=True))
    lines = ["| column | unit | meaning |", "|---|---|---|"]
    for col in columns:
        if col in _META:
            unit, text = _META[col]
        else:
            base = col[6:] if col.startswith("onset_") else col
            unit = units.get(base, "")
            text = _describe(col, unit)
        lines.append(f"| `{col}` | {unit} | {text} |")
    return "\n".join(lines)


def _readme(tables: dict[str, pd.DataFrame], manifest: dict[str, Any]) -> str:
    counts = manifest["counts"]
    intro = {
        "icfn": "ICFN samples: frames rendered while a grasp closes, perceived by the real "
                "pipeline; label `force_n`, features in the ICFN schema order.",
        "rcfn_sequences": "RCFN sequences: a grasp closed to a start force, its aperture held "
                          "for the hold length; labels `k_n`, `tau_s`, `kappa`, and the ICFN "
                          "features at the onset (`onset_*`).",
        "rcfn_features": "RCFN features along each hold (RCFN schema order), "
                         f"{manifest['spec']['feature_rate_hz']:g} Hz.",
        "rcfn_curves": f"True force along each hold, {manifest['spec']['curve_rate_hz']:g} Hz. "
                       "`relaxgrip train` labels each RCFN feature row with the Eq. 10 curve "
                       "that touches its hold's curve at the row's time (same force and slope); "
                       "the sequences' `k_n`, `tau_s` fit the whole hold.",
    }
    parts = [
        "# relaxgrip dataset",
        "",
        f"Generated by relaxgrip {manifest['relaxgrip_version']} on the digital twin "
        f"`{manifest['twin_version']}`, seed {manifest['spec']['seed']}. Features come from "
        "rendered frames through the perception pipeline; labels from the twin's truth. "
        "Open any table with `pandas.read_parquet(path)`.",
        "",
        f"ICFN features: `{ICFN_SCHEMA.version}`; RCFN features: `{RCFN_SCHEMA.version}`.",
        f"Sizes: {counts['icfn_samples']} ICFN samples, {counts['rcfn_sequences']} RCFN "
        "sequences; splits by episode / condition: "
        + ", ".join(f"{k} {v}" for k, v in counts["splits"].items()) + ".",
        "",
        "Noise and scatter kept on (see `manifest.json`, `noise`): "
        + "; ".join(f"{k} {v}" for k, v in manifest["noise"].items()) + ".",
    ]
    for name in TABLES:
        parts += ["", f"## {name}.parquet", "", intro[name], "",
                  _columns_table(list(tables[name].columns))]
    return "\n".join(parts) + "\n"


def split_counts(tables: Mapping[str, pd.DataFrame]) -> dict[str, int]:
    """Episodes and sequences per split, as ``{"icfn train": n, "rcfn_sequences val": n, ...}``."""
    counts: dict[str, int] = {}
    for name, key in (("icfn", "episode"), ("rcfn_sequences", "sequence")):
        table = tables[name]
        if len(table):
            for split, n in table.groupby("split")[key].nunique().items():
                counts[f"{name} {split}"] = int(n)
    return counts


def training_gaps(counts: Mapping[str, int], needs: Mapping[str, str]) -> list[str]:
    """What ``relaxgrip train`` will miss: a line for each table with no train or val rows.

    ``needs`` says, per table (``icfn``, ``rcfn_sequences``), what would give it some.
    """
    return [f"no {name} {part} rows: `relaxgrip train` needs {need}"
            for name, need in needs.items() for part in ("train", "val")
            if not counts.get(f"{name} {part}")]


def check_dataset_out(out_dir: Path) -> Path:
    """Check that a dataset can be written at ``out_dir`` (before building it).

    Raises
    ------
    InputError
        If ``out_dir`` is a file, a directory of something else, an earlier
        dataset with files that are not its own, or not writable.
    """
    own = {f"{name}.parquet" for name in TABLES} | {"manifest.json", "README.md"}
    return check_output_dir(Path(out_dir), DATASET_FORMAT, own, InputError)


def write_dataset(out_dir: Path, tables: dict[str, pd.DataFrame], manifest: dict[str, Any]) -> Path:
    """Write a dataset atomically (a previous relaxgrip dataset there is replaced).

    Raises
    ------
    InputError
        As :func:`check_dataset_out`.
    """
    out = check_dataset_out(out_dir)
    # Not mkdtemp: its directory is private (0700); a dataset gets the umask's mode.
    tmp = out.with_name(f".{out.name}.{os.getpid()}.{secrets.token_hex(4)}")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp.mkdir()
    except OSError as exc:
        raise InputError(f"{out}: cannot write ({exc.strerror or exc})") from None
    try:
        for name in TABLES:
            tables[name].to_parquet(tmp / f"{name}.parquet", index=False)
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
        (tmp / "README.md").write_text(_readme(tables, manifest))
        if out.exists():
            old = out.with_name(f".{out.name}.old")
            shutil.rmtree(old, ignore_errors=True)
            with deferred():  # cut between the renames, no dataset would be at ``out``
                os.replace(out, old)
                os.replace(tmp, out)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, out)
    except OSError as exc:  # a full disk: pyarrow's text names no file
        shutil.rmtree(tmp, ignore_errors=True)
        raise InputError(f"{out}: cannot write ({exc.strerror or one_line(exc)})") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


@dataclass(frozen=True)
class Dataset:
    """A loaded dataset.

    Attributes
    ----------
    icfn, sequences, rcfn_features, curves : pandas.DataFrame
        The four tables.
    manifest : dict
        Its manifest.
    """

    icfn: pd.DataFrame
    sequences: pd.DataFrame
    rcfn_features: pd.DataFrame
    curves: pd.DataFrame
    manifest: dict[str, Any]

    def icfn_rows(self, split: str) -> pd.DataFrame:
        """The ICFN table's rows of a split (``"all"``: every row)."""
        return self.icfn if split == "all" else self.icfn[self.icfn["split"] == split]

    def icfn_xy(self, split: str) -> tuple[FloatArray, FloatArray]:
        """ICFN features and force labels of a split (``"all"``: every row)."""
        rows = self.icfn_rows(split)
        return (rows[list(ICFN_SCHEMA.names)].to_numpy(np.float64),
                rows["force_n"].to_numpy(np.float64))

    def rcfn_xy(self, split: str) -> tuple[FloatArray, FloatArray]:
        """RCFN features along the holds of a split and their per-frame ``[kappa, log tau]`` labels.

        Each feature row is labelled with the Eq. 10 curve that touches its
        hold's force curve at the row's time (same force and slope,
        :func:`relaxgrip.physics.fitting.osculating_reduced`): the curve the
        estimator should follow from that frame on.  Where the force is not
        relaxing at that instant (it rises), the sequence's whole-hold fit
        (``kappa``, ``tau_s`` of the sequences table) stands in.
        """
        labels = self.sequences.set_index("sequence")
        rows = self.rcfn_features
        if split != "all":
            rows = rows[rows["sequence"].map(labels["split"]) == split]
        kappa = rows["sequence"].map(labels["kappa"]).to_numpy(np.float64, copy=True)
        tau = rows["sequence"].map(labels["tau_s"]).to_numpy(np.float64, copy=True)
        curves = self.curves.groupby("sequence")
        times = rows["t_s"].to_numpy(np.float64)
        for seq_id, idx in rows.groupby("sequence").indices.items():
            curve = curves.get_group(seq_id)
            k, t = osculating_reduced(curve["t_s"].to_numpy(np.float64),
                                      curve["force_n"].to_numpy(np.float64),
                                      float(labels.at[seq_id, "f0_n"]), times[idx])
            ok = np.isfinite(k) & (k > 0)
            kappa[idx[ok]], tau[idx[ok]] = k[ok], t[ok]
        return rows[list(RCFN_SCHEMA.names)].to_numpy(np.float64), np.column_stack(
            [kappa, np.log(tau)])


#: The splits a row may belong to.
_SPLITS = ("train", "val", "test")
#: Hottest set temperature a dataset may hold (°C).  The heaters' own limits stop far below
#: (``relaxgrip.control.temperature.ThermalLimits``: set points to 65 °C, cut-off at 70 °C by
#: default); 200 °C leaves ample room for a rig configured otherwise, so a value past it is
#: a damaged cell, not a recipe.
MAX_SET_TEMP_C = 200.0
#: Fewest rows per sequence, by table: a force curve needs two times to say how it relaxes
#: (the Eq. 10 labels and the metrics take slopes and integrals over it); recordings may end
#: a hold's features after one row.
_MIN_ROWS = {"rcfn_features": 1, "rcfn_curves": 2}


#: What a value in each unit can be on any gripper, bounds included: past them a cell is
#: damaged or a unit slipped (millimetres in a metre column), and values like 1e300 would
#: overflow the scalers and fits downstream.  Wide on purpose: the twin's and a lab's
#: measurements lie orders of magnitude inside.  A unit not listed is only checked finite.
_UNIT_RANGES: dict[str, tuple[float, float]] = {
    "m": (-1.0, 1.0),  # the marker within a metre of its zero pose
    "m^2": (0.0, 1.0),
    "rad": (-2.0 * math.pi, 2.0 * math.pi),  # a rotation vector's components lie within pi
    "m/s": (-100.0, 100.0),
    "rad/s": (-1000.0, 1000.0),
    "degC": (ABSOLUTE_ZERO_C, 1000.0),  # past any infrared camera's range
    "K": (0.0, 1000.0),  # a spread of temperatures
    "K/m": (-1e6, 1e6),  # a thousand kelvin over a millimetre
    "s": (0.0, math.inf),  # hold_time_s: time since the hold onset
    "N": (-MAX_FORCE_N, MAX_FORCE_N),  # what a relaxation fit takes
}


def _units(schema: FeatureSchema, prefix: str = "") -> dict[str, str]:
    return {prefix + name: unit for name, unit in zip(schema.names, schema.units, strict=True)}


@dataclass(frozen=True)
class _Columns:
    """The columns of a table that its readers (``Dataset``, training, evaluation, the
    observer's fit) use, by what they must hold."""

    finite: tuple[str, ...]  # numbers, every one finite
    numbers: tuple[str, ...] = ()  # numbers, NaN where unknown (recordings lack set points)
    other: tuple[str, ...] = ()  # any type
    units: Mapping[str, str] = field(default_factory=dict)  # finite ones: within _UNIT_RANGES

    @property
    def names(self) -> list[str]:
        """All of them: an empty table is given these."""
        return [*self.finite, *self.numbers, *self.other]


_COLUMNS: dict[str, _Columns] = {
    "icfn": _Columns(finite=("episode", "t_s", "force_n", *ICFN_SCHEMA.names), other=("split",),
                     units={"force_n": "N", **_units(ICFN_SCHEMA)}),
    "rcfn_sequences": _Columns(
        finite=("sequence", "f0_n", "kappa", "tau_s", *(f"onset_{n}" for n in ICFN_SCHEMA.names)),
        numbers=("temp_set_c", "contact_set_m", "force_set_n", "repeat"),
        other=("split", "object"),
        units={"f0_n": "N", **_units(ICFN_SCHEMA, "onset_")},
    ),
    "rcfn_features": _Columns(finite=("sequence", "t_s", *RCFN_SCHEMA.names),
                              units=_units(RCFN_SCHEMA)),
    "rcfn_curves": _Columns(finite=("sequence", "t_s", "force_n"), units={"force_n": "N"}),
}


def _listed(names: list[str], most: int = 3) -> str:
    """``'a', 'b', 'c' and 4 more``: a few names for a one-line message."""
    text = ", ".join(repr(n) for n in names[:most])
    return text + (f" and {len(names) - most} more" if len(names) > most else "")


def _short(value: Any, most: int = 40) -> str:
    text = repr(value)
    return text if len(text) <= most else text[: most - 3] + "..."


def _name_difference(stored: list[str], expected: tuple[str, ...]) -> str:
    """How a dataset's feature names differ from the ones computed now, for a message."""
    lacking = [n for n in expected if n not in stored]
    extra = [n for n in stored if n not in expected]
    parts = []
    if lacking:
        parts.append(f"the dataset lacks {_listed(lacking)}")
    if extra:
        parts.append(f"has {_listed(extra)}, which this relaxgrip does not compute")
    if parts:
        return "; ".join(parts)
    if len(stored) != len(expected):
        return "the dataset repeats a name"
    first = next(i for i, (a, b) in enumerate(zip(stored, expected, strict=True)) if a != b)
    return (f"same names in another order: feature {first} is {stored[first]!r} vs "
            f"{expected[first]!r}")


def _check_schema(manifest: dict[str, Any], key: str, schema: FeatureSchema, path: Path) -> None:
    stored = manifest.get(key)
    if not (isinstance(stored, dict) and isinstance(stored.get("names"), list)
            and all(isinstance(n, str) for n in stored["names"])):
        raise InputError(f"{path}: the manifest's {key} is {_short(stored)}, not a feature "
                         "schema; rebuild the dataset")
    names: list[str] = stored["names"]
    if stored.get("version") != schema.version:
        raise InputError(
            f"{path}: built with features {stored.get('version')!r} but this relaxgrip computes "
            f"{schema.version!r}; rebuild the dataset"
        )
    if tuple(names) != schema.names:
        raise InputError(
            f"{path}: built with {key[:4].upper()} features {schema.version!r} under other names "
            f"than this relaxgrip computes ({_name_difference(names, schema.names)}); "
            "rebuild the dataset"
        )


def _check_manifest_entries(manifest: dict[str, Any], path: Path) -> None:
    """What ``relaxgrip train`` records from the manifest must be there (before it trains)."""
    spec = manifest.get("spec")
    seed = spec.get("seed") if isinstance(spec, dict) else None
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise InputError(f"{path}: no spec with an integer seed; rebuild the dataset")
    if not isinstance(manifest.get("counts"), dict):
        raise InputError(f"{path}: no counts object; rebuild the dataset")
    if not isinstance(manifest.get("twin_version"), str):
        raise InputError(f"{path}: no twin_version text; rebuild the dataset")


def _read_table(path: Path, columns: _Columns) -> pd.DataFrame:
    """One table, read and checked to hold the columns its readers use, with sound values.

    The checks are vectorised: they run on every load, on millions of curve rows.
    """
    if path.is_dir():
        raise InputError(f"{path}: a directory, not a Parquet table")
    try:
        table = pd.read_parquet(path)
    except FileNotFoundError:
        raise InputError(f"{path}: missing table") from None
    except Exception as exc:  # pyarrow raises several types for damaged files
        raise InputError(f"{path}: unreadable Parquet table ({type(exc).__name__})") from None
    if len(table) == 0:  # a dataset without ICFN samples or without holds
        return table.reindex(columns=columns.names)
    missing = [c for c in columns.names if c not in table.columns]
    if missing:
        raise InputError(f"{path}: no column{'s' if len(missing) > 1 else ''} "
                         f"{_listed(missing)}; rebuild the dataset")
    for name in (*columns.finite, *columns.numbers):
        dtype = table[name].dtype
        if not pd.api.types.is_numeric_dtype(dtype) or pd.api.types.is_bool_dtype(dtype):
            raise InputError(f"{path}: column {name!r} holds {dtype}, not numbers; "
                             "rebuild the dataset")
    values = table[list(columns.finite)].to_numpy(np.float64, na_value=np.nan)
    bad = np.count_nonzero(~np.isfinite(values), axis=0)
    if bad.any():
        where = np.flatnonzero(bad)
        others = f" (and in {where.size - 1} other columns)" if where.size > 1 else ""
        count = int(bad[where[0]])
        raise InputError(f"{path}: {count} NaN or infinite value{'s' if count > 1 else ''} in "
                         f"column {columns.finite[where[0]]!r}{others}; rebuild the dataset")
    _check_ranges(path, table, columns.units)
    if "split" in columns.other:
        foreign = ~table["split"].isin(_SPLITS)
        if foreign.any():
            count = int(foreign.sum())
            raise InputError(
                f"{path}: {count} row{'s' if count > 1 else ''} of split "
                f"{_short(table['split'][foreign].iloc[0])}, not train, val or test; "
                "rebuild the dataset"
            )
    if "tau_s" in columns.finite:  # labels take its log
        non_positive = int((table["tau_s"] <= 0).sum())
        if non_positive:
            raise InputError(f"{path}: column 'tau_s' has {non_positive} values <= 0; "
                             "rebuild the dataset")
    if "temp_set_c" in columns.numbers:  # NaN: a recording whose plan set no temperature
        _check_set_temperatures(path, table)
    return table


def _check_ranges(path: Path, table: pd.DataFrame, units: Mapping[str, str]) -> None:
    """Every value of a column with a unit in :data:`_UNIT_RANGES` within its range."""
    for unit, (low, high) in _UNIT_RANGES.items():
        names = [name for name, u in units.items() if u == unit]
        if not names:
            continue
        values = table[names].to_numpy(np.float64)
        outside = (values < low) | (values > high)
        if not outside.any():
            continue
        row, col = (int(i[0]) for i in np.nonzero(outside))
        count = int(np.count_nonzero(outside[:, col]))
        span = f"below {low:g}" if high == math.inf else f"outside {low:g} to {high:g}"
        raise InputError(
            f"{path}: column {names[col]!r} has {count} value{'s' if count > 1 else ''} "
            f"{span} {unit} (e.g. {values[row, col]:g}, row {row}), which no gripper gives: "
            "a damaged cell or another unit; rebuild the dataset"
        )


def _check_set_temperatures(path: Path, table: pd.DataFrame) -> None:
    """Every known set temperature above absolute zero and at most :data:`MAX_SET_TEMP_C`."""
    temps = table["temp_set_c"].to_numpy(np.float64, na_value=np.nan)
    with np.errstate(invalid="ignore"):  # NaN compares False: unknown set points pass
        bad = (temps <= ABSOLUTE_ZERO_C) | (temps > MAX_SET_TEMP_C)
    if bad.any():
        where = np.flatnonzero(bad)
        count = where.size
        raise InputError(
            f"{path}: column 'temp_set_c' has {count} set temperature{'s' if count > 1 else ''} "
            f"at or below absolute zero or above {MAX_SET_TEMP_C:g} °C, e.g. "
            f"{temps[where[0]]:g} °C (sequence {table['sequence'].iloc[where[0]]}); "
            "rebuild the dataset"
        )


def _check_times(path: Path, table: pd.DataFrame, min_rows: int) -> None:
    """Within each sequence ``t_s`` starts at >= 0 (the hold onset) and rises strictly in file
    order, over at least ``min_rows`` rows.

    Readers take each sequence's rows in file order (the builder writes them so): the
    metrics and the Eq. 10 labels need strictly increasing times.  Vectorised: one stable
    sort by sequence, which keeps file order within each.
    """
    if len(table) == 0:
        return
    order = np.argsort(table["sequence"].to_numpy(), kind="stable")
    seq = table["sequence"].to_numpy()[order]
    t = table["t_s"].to_numpy(np.float64)[order]
    first = np.empty(seq.size, dtype=bool)
    first[0] = True
    np.not_equal(seq[1:], seq[:-1], out=first[1:])
    starts = np.flatnonzero(first)

    def fail(problem: str, rows: NDArray[np.intp]) -> NoReturn:
        n_seq = np.unique(seq[rows]).size
        others = f" ({n_seq - 1} other sequences too)" if n_seq > 1 else ""
        raise InputError(f"{path}: {problem}{others}; rebuild the dataset")

    early = starts[t[starts] < 0]
    if early.size:
        fail(f"t_s of sequence {seq[early[0]]} starts at {t[early[0]]:g} s, before the hold "
             "onset at 0 s", early)
    stuck = np.flatnonzero(~first[1:] & (t[1:] <= t[:-1])) + 1
    if stuck.size:
        i = stuck[0]
        how = (f"repeats {t[i]:g} s" if t[i] == t[i - 1]
               else f"falls from {t[i - 1]:g} to {t[i]:g} s")
        fail(f"t_s of sequence {seq[i]} {how}, not strictly increasing", stuck)
    counts = np.diff(np.append(starts, seq.size))
    short = starts[counts < min_rows]
    if short.size:
        n = int(counts[counts < min_rows][0])
        fail(f"sequence {seq[short[0]]} has only {n} row{'s' if n > 1 else ''}, needs at least "
             f"{min_rows}", short)


def _check_sequences(d: Path, tables: Mapping[str, pd.DataFrame]) -> None:
    """Every sequence once, with feature rows and a curve whose times are sound
    (:func:`_check_times`); no rows of unknown sequences."""
    ids = tables["rcfn_sequences"]["sequence"]
    repeated = ids[ids.duplicated()]
    if len(repeated):
        raise InputError(f"{d / 'rcfn_sequences.parquet'}: sequence {repeated.iloc[0]} has "
                         f"{int((ids == repeated.iloc[0]).sum())} rows; ids must be unique")
    known = pd.Index(ids)
    for name in ("rcfn_features", "rcfn_curves"):
        path = d / f"{name}.parquet"
        have = pd.Index(pd.unique(tables[name]["sequence"]))
        stray = have.difference(known)
        if len(stray):
            raise InputError(f"{path}: rows of {len(stray)} sequences that "
                             f"rcfn_sequences.parquet does not have (e.g. {stray[0]}); "
                             "rebuild the dataset")
        lacking = known.difference(have)
        if len(lacking):
            raise InputError(f"{path}: no rows for {len(lacking)} of the {len(known)} sequences "
                             f"of rcfn_sequences.parquet (e.g. {lacking[0]}); "
                             "rebuild the dataset")
        _check_times(path, tables[name], _MIN_ROWS[name])


def load_dataset(directory: Path) -> Dataset:
    """Load and check a dataset directory.

    Raises
    ------
    InputError
        On a missing directory or table, a foreign or damaged manifest, a
        dataset built with other feature schemas, or a damaged table: a column
        its readers use missing, text where numbers belong, a NaN or infinite
        value, a value no gripper gives (past the ranges of its unit: a damaged
        cell, or millimetres in a metre column), a split other than train, val or
        test, a set temperature
        (``temp_set_c``, NaN where unknown) at or below absolute zero or above
        :data:`MAX_SET_TEMP_C`, rows of a sequence that the other tables lack,
        or a sequence of ``rcfn_features`` or ``rcfn_curves`` whose ``t_s``
        starts before 0 or does not rise strictly in file order, or a curve of
        fewer than two rows.
    """
    d = Path(directory)
    manifest_path = d / "manifest.json"
    check_input_dir(d, "dataset directory", InputError)
    if not manifest_path.is_file():
        raise InputError(f"{d}: no manifest.json, not a relaxgrip dataset")
    manifest = read_manifest(manifest_path, DATASET_FORMAT, DATASET_VERSION, InputError,
                             "a relaxgrip dataset")
    _check_schema(manifest, "icfn_schema", ICFN_SCHEMA, d)
    _check_schema(manifest, "rcfn_schema", RCFN_SCHEMA, d)
    _check_manifest_entries(manifest, manifest_path)
    tables = {name: _read_table(d / f"{name}.parquet", _COLUMNS[name]) for name in TABLES}
    _check_sequences(d, tables)
    return Dataset(tables["icfn"], tables["rcfn_sequences"], tables["rcfn_features"],
                   tables["rcfn_curves"], manifest)
