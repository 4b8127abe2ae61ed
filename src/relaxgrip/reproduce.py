"""``relaxgrip reproduce``: every experiment of the paper's §V, its figure, and one report.

Each section runs one experiment on the twin, draws its figure into the
output directory and states the paper's figures beside ours.  Sections are
independent: they run in parallel worker processes (joblib), longest first,
and the report is written once they are all back (``report.md`` and
``results.json``, each atomically: an interrupted run leaves the previous
report intact).  ``quick`` shrinks datasets, grids and holds so the whole run
fits in about three minutes on two cores.
"""

from __future__ import annotations

import json
import math
import os
import platform
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from relaxgrip.errors import InputError
from relaxgrip.twin import TWIN_VERSION

__all__ = ["SECTIONS", "Row", "Section", "reproduce", "write_report"]


@dataclass(frozen=True)
class Row:
    """One quantity, the paper's value and ours, as text for the report."""

    quantity: str
    paper: str
    ours: str


@dataclass(frozen=True)
class Section:
    """One experiment's part of the report.

    Attributes
    ----------
    key : str
        Section key (a key of :data:`SECTIONS`).
    title : str
        Heading, naming the paper's figure.
    rows : list of Row
        The paper's figures beside ours.
    finding : str
        One or two sentences: the effect, in our numbers.
    figure : str or None
        File name of the figure in the output directory.
    results : dict
        The experiment's ``to_dict()``, for ``results.json``.
    seconds : float
        Wall time of the section (s).
    """

    key: str
    title: str
    rows: list[Row]
    finding: str
    figure: str | None
    results: dict[str, Any]
    seconds: float = 0.0


def _pct(share: float) -> str:
    return f"{100.0 * share:.0f} %"


def _range(values: Sequence[float], fmt: str = "{:.0f}") -> str:
    lo, hi = fmt.format(min(values)), fmt.format(max(values))
    return lo if lo == hi else f"{lo}–{hi}"


# --- sections ---------------------------------------------------------------------------


def characterization_section(out_dir: Path, quick: bool, seed: int) -> Section:
    """Stiffness characterization (Fig. "deform"): k80, z(80 mm), A_z, local stiffness."""
    from relaxgrip.experiments.characterization import characterize
    from relaxgrip.plots.characterization import plot_characterization

    result = characterize()
    figure = "characterization.png"
    plot_characterization(result, out_dir / figure)
    d = result.to_dict()
    drops = list(d["k80_drop_pct"].values())
    ratios = list(d["z80_ratio"].values())
    area_key = next(k for k in d if k.startswith("area_") and k.endswith("n_mm2"))
    (t0, a0), (t1, a1) = list(d[area_key].items())
    rows = [
        Row("k80 drop, 27 → 60 °C, each load 2–8 N", "35–45 %", f"{_range(drops)} %"),
        Row("z(80 mm) ratio, 27 → 60 °C", "× 1.6–1.7", f"× {_range(ratios, '{:.2f}')}"),
        Row("A_z at 8 N, 27 → 60 °C", "361 → 626 mm² (+73 %)",
            f"{a0:.0f} → {a1:.0f} mm² ({100 * (a1 / a0 - 1):+.0f} %)"),
    ]
    import numpy as np

    monotone = bool(np.all(np.diff(result.z80_m, axis=1) > 0))
    finding = (f"Deformation at 80 mm {'grows monotonically' if monotone else 'does NOT grow'} "
               f"with temperature at every load; k80 falls {_range(drops)} % from {t0} to "
               f"{t1} °C.")
    d["z80_monotone_in_temp"] = monotone
    return Section("characterization", 'Stiffness characterization (Fig. "deform")', rows,
                   finding, figure, d)


def accuracy_section(out_dir: Path, quick: bool, seed: int) -> Section:
    """Force perception and relaxation accuracy (Fig. "acc") of the shipped models.

    A fresh dataset is generated on a seed the shipped models never saw, and
    all of it is scored (every curve and sample is held out).
    """
    import tempfile

    from relaxgrip.learning.build import build_dataset
    from relaxgrip.learning.datasets import REPEAT_TEMPS_C, REPEATS_PER_GROUP, DatasetSpec
    from relaxgrip.learning.datastore import load_dataset
    from relaxgrip.learning.evaluation import evaluate
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.plots.accuracy import plot_accuracy

    repeats = REPEATS_PER_GROUP * len(REPEAT_TEMPS_C)
    spec = DatasetSpec(icfn_samples=600 if quick else 3000,
                       rcfn_sequences=repeats + (18 if quick else 180), seed=1000 + seed,
                       hold_s=140.0 if quick else 280.0)
    with tempfile.TemporaryDirectory(prefix="relaxgrip-reproduce-") as tmp:
        build_dataset(Path(tmp) / "data", spec, jobs=1)
        data = load_dataset(Path(tmp) / "data")
    result = evaluate(data, load_default_models(), split="all")
    figure = "accuracy.png"
    plot_accuracy(result, out_dir / figure)
    d = result.to_dict()
    icfn, rcfn, rep = d["icfn"], d["rcfn"], d["repeatability"]
    rows = [
        Row("ICFN MAE / RMSE / R²", "0.651 N / 0.886 N / 0.848",
            f"{icfn['mae_n']:.3f} N / {icfn['rmse_n']:.3f} N / {icfn['r2']:.3f}"),
        Row("RCFN NRMSE mean / median", "0.160 / 0.118",
            f"{rcfn['nrmse_mean']:.3f} / {rcfn['nrmse_median']:.3f}"),
        Row("RCFN AUC_rel mean / median", "0.065 / 0.049",
            f"{rcfn['auc_rel_mean']:.3f} / {rcfn['auc_rel_median']:.3f}"),
        Row("RCFN curve correlation (mean)", "0.990", f"{rcfn['corr_mean']:.3f}"),
        Row("repeat std of the end force, 40 / 50 / 60 °C", "≈ 0.04 / 0.04 / 0.12 N",
            " / ".join(f"{rep[k]['gt_end_std_n']:.3f}" for k in ("40", "50", "60") if k in rep)
            + " N"),
    ]
    finding = (f"On {result.icfn_truth_n.size} fresh ICFN samples and {len(result.curves)} fresh "
               f"relaxation curves (twin seed {spec.seed}, never trained on), the shipped "
               f"models estimate force with MAE {icfn['mae_n']:.3f} N and reconstruct the "
               f"relaxation with median NRMSE {rcfn['nrmse_median']:.3f}.")
    d["dataset"] = {"icfn_samples": spec.icfn_samples, "rcfn_sequences": spec.rcfn_sequences,
                    "seed": spec.seed, "hold_s": spec.hold_s}
    return Section("accuracy", 'Force perception and relaxation accuracy (Fig. "acc")', rows,
                   finding, figure, d)


def holding_section(out_dir: Path, quick: bool, seed: int) -> Section:
    """The 280 s relaxation-aware hold (Fig. "sphere"): fixed, icfn, relax on one seed."""
    from relaxgrip.experiments.controlled_hold import compare_holds
    from relaxgrip.plots.holding import plot_hold_comparison

    duration = 140.0 if quick else 280.0
    result = compare_holds(duration_s=duration, seed=seed)
    figure = "holding.png"
    plot_hold_comparison(result, out_dir / figure)
    d = result.to_dict()
    mae = {name: hold["mae_n"] for name, hold in d["holds"].items()}
    red = d["mae_reduction"]
    window = d["holds"]["relax"]["window_s"]
    rows = [
        Row(f"MAE from 5 N, {window[0]:g}–{window[1]:g} s: fixed aperture", "0.333 N",
            f"{mae['fixed']:.3f} N"),
        Row("MAE: ICFN only", "1.327 N", f"{mae['icfn']:.3f} N"),
        Row("MAE: ICFN + RCFN (ours)", "0.066 N", f"{mae['relax']:.3f} N"),
        Row("reduction vs fixed / vs ICFN only", "80 % / 95 %",
            f"{_pct(red['vs_fixed'])} / {_pct(red['vs_icfn'])}"),
    ]
    finding = (f"A {duration:g} s hold at 5 N, 40 °C: the fixed aperture's force decays, the "
               "ICFN-only loop holds the finger's deflection while the true force drifts from "
               f"the target, and Eq. 10 in the loop keeps it within {mae['relax']:.3f} N.")
    return Section("holding", 'Holding with relaxation-aware control (Fig. "sphere")', rows,
                   finding, figure, d)


def timing_section(out_dir: Path, quick: bool, seed: int) -> Section:
    """Latency per stage (Fig. "network" b)."""
    from relaxgrip.experiments.timing import PAPER_LATENCY_MS, run_timing
    from relaxgrip.plots.timing import plot_timing

    result = run_timing(seed=seed, quick=quick)
    figure = "timing.png"
    plot_timing(result, out_dir / figure)
    m = result.median_ms
    rows = [
        Row("ArUco pose extraction", f"{PAPER_LATENCY_MS['aruco_pose']:g} ms",
            f"{m['aruco_pose']:.2f} ms tracked ({m['aruco_full_frame']:.2f} ms full-frame "
            "detection)"),
        Row("ICFN inference", f"{PAPER_LATENCY_MS['icfn']:g} ms", f"{m['icfn']:.3f} ms"),
        Row("RCFN inference", f"{PAPER_LATENCY_MS['rcfn']:g} ms", f"{m['rcfn']:.3f} ms"),
        Row("instantaneous force latency", f"{PAPER_LATENCY_MS['instantaneous']:g} ms",
            f"{m['instantaneous']:.2f} ms"),
        Row("relaxation-compensated latency", f"{PAPER_LATENCY_MS['compensated']:g} ms",
            f"{m['compensated']:.2f} ms"),
    ]
    finding = (f"Medians on one core of {platform.machine()}: the compensated estimate costs "
               f"{m['compensated']:.2f} ms per frame, "
               f"{PAPER_LATENCY_MS['compensated'] / m['compensated']:.0f}× under the paper's.")
    return Section("timing", 'Timing (Fig. "network" b)', rows, finding, figure,
                   result.to_dict())


#: Section key -> runner, in the report's (the paper's) order.
SECTIONS: dict[str, Callable[[Path, bool, int], Section]] = {
    "characterization": characterization_section,
    "accuracy": accuracy_section,
    "holding": holding_section,
    "timing": timing_section,
}
#: Rough relative cost, to start the longest sections first.
_COST = {"accuracy": 5, "holding": 4, "timing": 1, "characterization": 0}


def _run_section(key: str, out_dir: Path, quick: bool, seed: int) -> Section:
    import cv2

    cv2.setNumThreads(1)
    start = time.perf_counter()
    section = SECTIONS[key](out_dir, quick, seed)
    return Section(section.key, section.title, section.rows, section.finding, section.figure,
                   section.results, time.perf_counter() - start)


def reproduce(
    out_dir: Path,
    quick: bool = False,
    seed: int = 0,
    jobs: int = 2,
    only: Sequence[str] | None = None,
    progress: Callable[[Section, int, int], None] | None = None,
) -> list[Section]:
    """Run the experiments, draw their figures into ``out_dir`` and write the report.

    Parameters
    ----------
    out_dir : Path
        Output directory (created if missing; its parent must exist).
    quick : bool
        Smaller datasets, shorter grids and holds.
    seed : int
        Twin seed of every experiment.
    jobs : int
        Sections run at once (worker processes).
    only : sequence of str, optional
        Run these sections only (default: all).
    progress : callable, optional
        Called as ``progress(section, done, total)`` when a section finishes.

    Returns
    -------
    list of Section
        In the report's order.
    """
    from joblib import Parallel, delayed

    if jobs < 1:
        raise InputError(f"--jobs must be >= 1, got {jobs}")
    keys = list(SECTIONS) if only is None else list(only)
    unknown = [k for k in keys if k not in SECTIONS]
    if unknown:
        raise InputError(f"unknown section(s) {', '.join(unknown)}; sections: "
                         f"{', '.join(SECTIONS)}")
    out_dir = Path(out_dir)
    if not out_dir.parent.is_dir():
        raise InputError(f"{out_dir}: directory {out_dir.parent} does not exist")
    out_dir.mkdir(exist_ok=True)
    start = time.perf_counter()
    ordered = sorted(keys, key=lambda k: -_COST.get(k, 3))
    done: dict[str, Section] = {}
    # Each section is single-threaded; the parallelism is across sections.
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    parallel = Parallel(n_jobs=min(jobs, len(ordered)), return_as="generator_unordered")
    for section in parallel(delayed(_run_section)(k, out_dir, quick, seed) for k in ordered):
        done[section.key] = section
        if progress is not None:
            progress(section, len(done), len(ordered))
    sections = [done[k] for k in SECTIONS if k in done]
    write_report(out_dir, sections, quick=quick, seed=seed,
                 seconds=time.perf_counter() - start)
    return sections


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def write_report(out_dir: Path, sections: Sequence[Section], quick: bool, seed: int,
                 seconds: float) -> None:
    """Write ``report.md`` and ``results.json`` for ``sections`` into ``out_dir``."""
    mode = "quick" if quick else "full"
    lines = [
        "# relaxgrip: the paper's experiments, reproduced on the twin",
        "",
        f"Twin `{TWIN_VERSION}`, seed {seed}, {mode} run "
        f"(`relaxgrip reproduce{' --quick' if quick else ''}`), {seconds:.0f} s on "
        f"{os.cpu_count()} cores. Each section states what the paper reports beside what we "
        "measured in this run.",
        "",
    ]
    for s in sections:
        lines += [f"## {s.title}", "", "| quantity | paper | relaxgrip |", "|---|---|---|"]
        lines += [f"| {_cell(r.quantity)} | {_cell(r.paper)} | {_cell(r.ours)} |" for r in s.rows]
        lines += ["", s.finding, ""]
        if s.figure is not None:
            lines += [f"![{s.title}]({s.figure})", ""]
    _atomic_write(out_dir / "report.md", "\n".join(lines))
    payload = {
        "twin_version": TWIN_VERSION,
        "seed": seed,
        "quick": quick,
        "seconds": seconds,
        "sections": {s.key: {"title": s.title, "seconds": s.seconds, "figure": s.figure,
                             "paper_vs_ours": [vars(r) for r in s.rows],
                             "results": s.results} for s in sections},
    }
    _atomic_write(out_dir / "results.json", json.dumps(_json_safe(payload), indent=1))


def _json_safe(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_safe(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item):  # numpy scalars
        return _json_safe(obj.item())
    return obj

