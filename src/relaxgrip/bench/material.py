"""``relaxgrip bench material``: fit-material side by side with pyvisco on the same files.

pyvisco (NREL, BSD-3) is never a dependency: it runs in a separate Python
environment the benchmark is told about (``RELAXGRIP_PYVISCO_PYTHON``, the
interpreter of a virtualenv with pyvisco installed) or finds
(``.venv-pyvisco/bin/python`` in the working directory).  Without one the
benchmark says so and reports relaxgrip alone.

For each file both tools find shift factors at the same reference
temperature, fit their shift functions and a Prony series; the whole
temperature-dependent model of each (Prony series through its shift
function) is scored against every measured point (RMS of log10 model minus
log10 measured), with the same code for both.  Times are medians of
``repeat`` runs of the whole identification (reading the file included).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np

from relaxgrip.bench.core import BenchResult
from relaxgrip.experiments.material_fit import fit_material, load_measurements
from relaxgrip.physics.material import Material, ShiftLaw
from relaxgrip.physics.material_fit import model_residuals_log10

__all__ = ["FILES", "bench_material", "find_pyvisco"]

DATA = Path(__file__).resolve().parents[3] / "tests" / "data" / "pyvisco"
#: The files compared: (file, domain, the independent shift factors beside it).
FILES = (("time_user_raw.csv", "time", "time_user_raw__shift_factors.csv"),
         ("freq_user_raw.csv", "freq", "freq_Eplexor_raw_aT.csv"))

_CHILD = r"""
import json, sys, time
import numpy as np
import pyvisco as visco
path, domain, ref_t, repeat = sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4])
times, times_opt = [], []
for _ in range(repeat):
    t0 = time.perf_counter()
    data = visco.load.file(path)
    df_raw, arr_ref, units = visco.load.user_raw(data, domain, "E")
    df_aT, _ = visco.master.get_aT(df_raw, ref_t)
    df_master = visco.master.get_curve(df_raw, df_aT, ref_t)
    df_master = visco.master.smooth(df_master, 1)
    df_wlf = visco.shift.fit_WLF(df_master.RefT, df_aT)
    df_C = visco.shift.fit_poly(df_aT)
    df_dis = visco.prony.discretize(df_master)
    prony, _ = visco.prony.fit(df_dis, df_master, opt=False)
    times.append(time.perf_counter() - t0)
    dict_prony, n_opt, err = visco.opt.nprony(df_master, prony, window="min")
    times_opt.append(time.perf_counter() - t0)
C = df_C[0] if isinstance(df_C, tuple) else df_C
d4 = [float(v) for v in np.asarray(C.loc["D4"], dtype=float).ravel()[:5]]
def terms(p):
    t = p["df_terms"]
    return {"E_0": float(p["E_0"]), "tau": [float(v) for v in t["tau_i"]],
            "alpha": [float(v) for v in t["alpha_i"]]}
print(json.dumps({"log_aT": {str(float(t)): float(a) for t, a in zip(df_aT["T"], df_aT["log_aT"])},
                  "wlf": [float(df_wlf["C1"].iloc[0]), float(df_wlf["C2"].iloc[0])], "d4": d4,
                  "prony": terms(prony), "prony_opt": terms(dict_prony[n_opt]), "n_opt": int(n_opt),
                  "seconds": times, "seconds_with_term_selection": times_opt,
                  "version": visco.__version__}))
"""


def find_pyvisco() -> str | None:
    """The interpreter of an environment with pyvisco, or None."""
    given = os.environ.get("RELAXGRIP_PYVISCO_PYTHON")
    candidates = [given] if given else []
    candidates.append(str(Path.cwd() / ".venv-pyvisco" / "bin" / "python"))
    for exe in candidates:
        if exe and Path(exe).is_file():
            probe = subprocess.run([exe, "-c", "import pyvisco"], capture_output=True,
                                   check=False, timeout=120)
            if probe.returncode == 0:
                return exe
    return None


def _pyvisco_material(p: dict[str, Any], law: ShiftLaw, temps: tuple[float, float]) -> Material:
    e0, alpha, tau = p["E_0"] * 1e6, np.array(p["alpha"]), np.array(p["tau"])
    keep = alpha > 0
    return Material("E", float(e0 * (1 - alpha.sum())), tuple(float(v) for v in e0 * alpha[keep]),
                    tuple(float(v) for v in tau[keep]), law, temps)


def _poly_law(d4: list[float], ref_c: float) -> ShiftLaw:
    q = np.polynomial.Polynomial(d4)(np.polynomial.Polynomial([ref_c, 1.0]))
    c = list(q.coef[1:5]) + [0.0] * (4 - len(q.coef[1:5]))
    return ShiftLaw("poly", tuple(float(v) for v in c), ref_c)


def _compare(ours: dict[str, float], theirs: dict[float, float], ref_c: float,
             glassy_below_c: float) -> dict[str, Any]:
    """Largest differences (decades) of two shift-factor sets, both referenced at ``ref_c``."""
    t_ref = min(theirs, key=lambda t: abs(t - ref_c))
    trans: list[float] = []
    glassy: list[float] = []
    for t, a in theirs.items():
        key = f"{round(t):d}"
        if key not in ours:
            continue
        diff = abs(ours[key] - (a - theirs[t_ref]))
        (glassy if t < glassy_below_c else trans).append(diff)
    return {"max_diff_transition_decades": max(trans) if trans else math.nan,
            "max_diff_glassy_decades": max(glassy) if glassy else math.nan}


def bench_material(repeat: int) -> BenchResult:
    """Time and score fit-material and pyvisco on pyvisco's example files."""
    exe = find_pyvisco()
    notes: dict[str, Any] = {"pyvisco": exe or "not found: set RELAXGRIP_PYVISCO_PYTHON to the "
                             "python of a virtualenv with pyvisco installed"}
    headline: dict[str, Any] = {}
    seconds: list[float] = []
    for name, domain, ref_file in FILES:
        path = DATA / name
        runs = []
        for _ in range(max(repeat, 1)):
            t0 = time.perf_counter()
            result = fit_material(load_measurements([path]), max_terms=12)
            runs.append(time.perf_counter() - t0)
        seconds.extend(runs)
        meas = result.measurements
        ref_c = result.material.ref_temp_c
        d = result.to_dict()
        raw = np.genfromtxt(DATA / ref_file, delimiter=",", skip_header=2 if "shift" in ref_file
                            else 1)
        independent = {float(t): float(a) for t, a in raw}
        # The glassy plateau: the sets whose storage modulus moves less than 0.03 decades
        # per decade of time or frequency.
        slopes = [abs(np.polyfit(np.log10(s.x), np.log10(s.y), 1)[0]) for s in meas.sets]
        glassy_below = min((s.temp_c for s, g in zip(meas.sets, slopes, strict=True)
                            if g >= 0.03), default=math.inf)
        entry: dict[str, Any] = {
            "ref_temp_c": ref_c, "relaxgrip_seconds_median": float(np.median(runs)),
            "relaxgrip_terms": len(result.material.tau_s),
            "relaxgrip_shift_model": result.material.shift.model,
            "relaxgrip_rms_log10": result.rms_log10, "relaxgrip_log_aT": d["log_aT"],
            "relaxgrip_log_aT_sigma": d["log_aT_sigma"],
            "glassy_below_c": glassy_below,
            "vs_" + ref_file: _compare(d["log_aT"], independent, ref_c, glassy_below),
        }
        if exe is not None:
            proc = subprocess.run([exe, "-c", _CHILD, str(path), domain, str(round(ref_c)),
                                   str(max(repeat, 1))], capture_output=True, text=True,
                                  check=False, timeout=3600)
            if proc.returncode != 0:
                entry["pyvisco_error"] = proc.stderr.strip().splitlines()[-1:]
            else:
                pv = json.loads(proc.stdout.strip().splitlines()[-1])
                temps = (float(meas.temps_c.min()), float(meas.temps_c.max()))
                pv_ref = float(round(ref_c))
                scores = {}
                for label, law in (("wlf", ShiftLaw("wlf", tuple(pv["wlf"]), pv_ref)),
                                   ("poly4", _poly_law(pv["d4"], pv_ref))):
                    for which in ("prony", "prony_opt"):
                        try:
                            mat = _pyvisco_material(pv[which], law, temps)
                            rms = float(np.sqrt(np.mean(model_residuals_log10(mat, meas) ** 2)))
                        except ValueError as exc:
                            rms = math.nan
                            entry.setdefault("pyvisco_notes", []).append(f"{label}: {exc}")
                        scores[f"{label}_{which}"] = {"rms_log10": rms,
                                                      "terms": len(pv[which]["tau"])}
                entry.update({
                    "pyvisco_version": pv["version"],
                    "pyvisco_seconds_median": float(np.median(pv["seconds"])),
                    "pyvisco_seconds_with_term_selection_median":
                        float(np.median(pv["seconds_with_term_selection"])),
                    "pyvisco_models": scores,
                    "pyvisco_log_aT": pv["log_aT"],
                    "vs_pyvisco_shift_factors": _compare(
                        d["log_aT"], {float(k): v for k, v in pv["log_aT"].items()}, ref_c,
                        glassy_below),
                })
        notes[name] = entry
        headline[f"{domain}_rms_log10"] = result.rms_log10
        headline[f"{domain}_terms"] = len(result.material.tau_s)
        headline[f"{domain}_seconds"] = float(np.median(runs))
        if "pyvisco_seconds_median" in entry:
            headline[f"{domain}_pyvisco_seconds"] = entry["pyvisco_seconds_median"]
    return BenchResult(name="material", description="fit-material vs pyvisco on pyvisco's "
                       "example files (12 terms at most)", seconds=seconds, notes=notes,
                       headline=headline)
