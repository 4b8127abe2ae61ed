"""Fit the relaxation models to a measured step-and-hold record.

A record is a CSV file with the columns ``time_s`` (s), ``displacement_mm``
(mm) and ``force_n`` (N), e.g. the VHB4910 stress-relaxation tests in
``shared/data/vhb4910-relaxation``.  :func:`fit_relaxation` locates the hold
phase, fits the reduced model (Eqs. 9–10) and an ``N``-term Prony series
(Eq. 4) to its first ``window_s`` seconds, and scores both with the paper's
NRMSE and AUC_rel (§V-B) over the fitted window.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.fileio import check_input_file, read_text_csv
from relaxgrip.metrics import auc_rel, nrmse
from relaxgrip.physics.fitting import (
    WEIGHTINGS,
    PronyFit,
    ReducedFit,
    find_hold,
    fit_prony,
    fit_reduced,
)
from relaxgrip.validate import parse_number

FloatArray = NDArray[np.float64]

__all__ = [
    "COLUMNS",
    "MIN_FIT_SAMPLES",
    "MIN_ROWS",
    "RelaxationFitResult",
    "RelaxationRecord",
    "fit_relaxation",
    "load_relaxation_csv",
]

COLUMNS: tuple[str, ...] = ("time_s", "displacement_mm", "force_n")
# A hold needs at least 10 samples (find_hold), plus the ramp before it.
MIN_ROWS = 12
# Fewest hold samples a fit window may hold, whatever the number of parameters.
MIN_FIT_SAMPLES = 10


def _frozen(a: FloatArray) -> FloatArray:
    """A read-only copy, so that frozen dataclasses really are immutable."""
    out = np.array(a, dtype=np.float64)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class RelaxationRecord:
    """A step-and-hold record as read from a CSV file.

    Attributes
    ----------
    time_s : ndarray, shape (n,)
        Strictly increasing sample times (s).
    displacement_mm : ndarray, shape (n,)
        Displacement (mm).
    force_n : ndarray, shape (n,)
        Force (N).
    source : pathlib.Path
        The file the record was read from.
    """

    time_s: FloatArray
    displacement_mm: FloatArray
    force_n: FloatArray
    source: Path


@dataclass(frozen=True, eq=False)
class RelaxationFitResult:
    """Both model fits of one record, their scores, and curves for plotting.

    Attributes
    ----------
    source : pathlib.Path
        The record's file.
    hold_start_s : float
        Time of the first hold sample, in the record's time base (s).
    window_s : float
        Length of the fitted part of the hold (s), measured from its start.
    weighting : str
        Objective of both fits, ``"time"`` or ``"sample"``.
    reduced, prony : ReducedFit, PronyFit
        The least-squares fits.
    reduced_nrmse, reduced_auc_rel, prony_nrmse, prony_auc_rel : float
        NRMSE and AUC_rel of each fit over the fitted window.
    time_s : ndarray, shape (m,)
        Times since the hold start of the whole hold phase (s).
    force_n : ndarray, shape (m,)
        Measured force over the whole hold phase (N).
    reduced_force_n, prony_force_n : ndarray, shape (m,)
        Both models on ``time_s`` (N); beyond ``window_s`` they extrapolate.
    """

    source: Path
    hold_start_s: float
    window_s: float
    weighting: str
    reduced: ReducedFit
    prony: PronyFit
    reduced_nrmse: float
    reduced_auc_rel: float
    prony_nrmse: float
    prony_auc_rel: float
    time_s: FloatArray
    force_n: FloatArray
    reduced_force_n: FloatArray
    prony_force_n: FloatArray

    @property
    def in_window(self) -> NDArray[np.bool_]:
        """Mask of the hold samples that were fitted."""
        return self.time_s <= self.window_s

    def to_dict(self) -> dict[str, Any]:
        """The JSON form printed by ``relaxgrip fit-relaxation --json``.

        Returns
        -------
        dict
            ``{"file", "hold_start_s", "window_s", "weighting", "reduced":
            {"f_inst_n", "k_n", "tau_s", "nrmse", "auc_rel"}, "prony":
            {"f_eq_n", "terms": [{"k_n", "tau_s"}, ...], "nrmse", "auc_rel"}}``,
            with plain Python scalars only.
        """
        return {
            "file": str(self.source),
            "hold_start_s": self.hold_start_s,
            "window_s": self.window_s,
            "weighting": self.weighting,
            "reduced": {
                "f_inst_n": self.reduced.f_inst_n,
                "k_n": self.reduced.k_n,
                "tau_s": self.reduced.tau_s,
                "nrmse": self.reduced_nrmse,
                "auc_rel": self.reduced_auc_rel,
            },
            "prony": {
                "f_eq_n": self.prony.f_eq_n,
                "terms": [
                    {"k_n": k, "tau_s": tau}
                    for k, tau in zip(self.prony.k_n, self.prony.tau_s, strict=True)
                ],
                "nrmse": self.prony_nrmse,
                "auc_rel": self.prony_auc_rel,
            },
        }


def load_relaxation_csv(path: str | Path) -> RelaxationRecord:
    """Read a step-and-hold record from a CSV file.

    The first row names the columns; ``time_s``, ``displacement_mm`` and
    ``force_n`` must be among them (in any order, other columns are ignored).
    Fields are separated by commas, or by semicolons or tabs when the header
    has no comma, and then numbers may have a decimal comma (a European
    spreadsheet's export).  Blank rows are skipped.

    Parameters
    ----------
    path : str or pathlib.Path
        The CSV file.

    Returns
    -------
    RelaxationRecord
        The three columns as read-only float arrays.

    Raises
    ------
    relaxgrip.errors.InputError
        With a one-line message naming the file and the problem: the file is
        missing, unreadable or not a regular file (a FIFO, a device), not a
        text CSV, lacks a column or has one twice (named), has an
        unparseable or non-finite value (column and line named), time that
        does not strictly increase (line named), or fewer than
        :data:`MIN_ROWS` data rows.
    """
    path = check_input_file(Path(path), "file", InputError)
    text = read_text_csv(path, InputError)

    rows: list[tuple[int, list[str]]] = []
    # A European spreadsheet's export: semicolons between fields, commas in numbers.
    first = text.lstrip().split("\n", 1)[0]
    delimiter = next((d for d in (";", "\t") if "," not in first and d in first), ",")
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
    try:
        rows.extend((reader.line_num, row) for row in reader if any(c.strip() for c in row))
    except csv.Error as exc:
        raise InputError(f"{path}, line {reader.line_num}: not a valid CSV file: {exc}") from None
    if not rows:
        raise InputError(f"{path}: empty file, expected a header with {', '.join(COLUMNS)}")

    header = [name.strip() for name in rows[0][1]]
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        found = ", ".join(h for h in header if h) or "none"
        raise InputError(f"{path}: missing column(s) {', '.join(missing)} (header has: {found})")
    twice = [c for c in COLUMNS if header.count(c) > 1]
    if twice:
        raise InputError(f"{path}: the header names {', '.join(twice)} more than once; "
                         "keep one column of each name")
    index = [header.index(c) for c in COLUMNS]

    data = np.empty((len(rows) - 1, len(COLUMNS)), dtype=np.float64)
    for i, (line, row) in enumerate(rows[1:]):
        if len(row) != len(header):
            raise InputError(
                f"{path}, line {line}: {len(row)} fields, the header has {len(header)}"
            )
        for j, (col, k) in enumerate(zip(COLUMNS, index, strict=True)):
            cell = row[k].strip()
            if delimiter != ",":
                cell = cell.replace(",", ".")
            try:  # not float(): it takes "0_4" for 4
                value = parse_number(cell)
            except ValueError:
                raise InputError(
                    f"{path}, line {line}: {col} value {cell!r} is not a number"
                ) from None
            if not math.isfinite(value):
                raise InputError(f"{path}, line {line}: {col} is {cell!r}, not a finite number")
            data[i, j] = value

    if data.shape[0] < MIN_ROWS:
        raise InputError(f"{path}: only {data.shape[0]} data rows, need at least {MIN_ROWS}")
    time_s = data[:, 0]
    back = np.flatnonzero(np.diff(time_s) <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise InputError(
            f"{path}, line {rows[i + 1][0]}: time_s {time_s[i]:g} does not increase "
            f"(previous {time_s[i - 1]:g})"
        )
    return RelaxationRecord(
        time_s=_frozen(time_s),
        displacement_mm=_frozen(data[:, 1]),
        force_n=_frozen(data[:, 2]),
        source=path,
    )


def fit_relaxation(
    record: RelaxationRecord,
    window_s: float | None = None,
    n_terms: int = 3,
    weighting: str = "time",
) -> RelaxationFitResult:
    """Fit the reduced model and a Prony series to the hold phase of a record.

    Parameters
    ----------
    record : RelaxationRecord
        The measured record.
    window_s : float, optional
        Fit only the first ``window_s`` seconds of the hold (``> 0``); a
        window longer than the hold is the whole hold.  Default: the whole hold.
    n_terms : int
        Number of Prony terms, ``>= 1``.
    weighting : {"time", "sample"}
        Least-squares objective, see
        :func:`relaxgrip.physics.fitting.quadrature_weights`.

    Returns
    -------
    RelaxationFitResult
        Fits, scores over the fitted window, and curves over the whole hold.

    Raises
    ------
    relaxgrip.errors.InputError
        If an argument is invalid, the record has no hold phase, the window
        holds fewer than :data:`MIN_FIT_SAMPLES` samples (or fewer than the
        Prony parameters), or the force in the window is constant.
    """
    if weighting not in WEIGHTINGS:
        raise InputError(f"weighting must be one of {', '.join(WEIGHTINGS)}, got {weighting!r}")
    if isinstance(n_terms, bool) or not isinstance(n_terms, int) or n_terms < 1:
        raise InputError(f"the number of Prony terms must be an integer >= 1, got {n_terms!r}")
    if window_s is not None and not (math.isfinite(window_s) and window_s > 0):
        raise InputError(f"the fit window must be a finite number of seconds > 0, got {window_s}")

    source = record.source
    try:
        start, stop = find_hold(record.time_s, record.displacement_mm)
    except InputError as exc:
        raise InputError(f"{source}: {exc}") from None
    hold_start_s = float(record.time_s[start])
    time_s = record.time_s[start:stop] - hold_start_s
    force_n = record.force_n[start:stop]
    hold_s = float(time_s[-1])
    window = hold_s if window_s is None else min(float(window_s), hold_s)

    fitted = time_s <= window
    n_fit = int(np.count_nonzero(fitted))
    need = max(MIN_FIT_SAMPLES, 2 * n_terms + 1)
    if n_fit < need:
        raise InputError(
            f"{source}: the first {window:g} s of the hold hold {n_fit} samples; "
            f"a {n_terms}-term fit needs at least {need} (use a longer --window-s)"
        )
    t_fit, f_fit = time_s[fitted], force_n[fitted]
    try:
        reduced = fit_reduced(t_fit, f_fit, weighting=weighting)
        prony = fit_prony(t_fit, f_fit, n_terms=n_terms, weighting=weighting)
        reduced_fit_n, prony_fit_n = reduced.predict(t_fit), prony.predict(t_fit)
        scores = (
            nrmse(t_fit, reduced_fit_n, f_fit),
            auc_rel(t_fit, reduced_fit_n, f_fit),
            nrmse(t_fit, prony_fit_n, f_fit),
            auc_rel(t_fit, prony_fit_n, f_fit),
        )
    except ValueError as exc:  # InputError included: degenerate force in the window
        raise InputError(f"{source}: {exc}") from None

    return RelaxationFitResult(
        source=source,
        hold_start_s=hold_start_s,
        window_s=window,
        weighting=weighting,
        reduced=reduced,
        prony=prony,
        reduced_nrmse=scores[0],
        reduced_auc_rel=scores[1],
        prony_nrmse=scores[2],
        prony_auc_rel=scores[3],
        time_s=_frozen(time_s),
        force_n=_frozen(force_n),
        reduced_force_n=_frozen(reduced.predict(time_s)),
        prony_force_n=_frozen(prony.predict(time_s)),
    )
