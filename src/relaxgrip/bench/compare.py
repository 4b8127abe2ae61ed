"""``relaxgrip bench --compare REF``: the same benchmarks on another git ref, in the same run.

The ref is checked out into a temporary git worktree (detached, removed
afterwards) of the repository this package runs from, and its own
``relaxgrip bench NAMES --repeat N --json`` runs in a subprocess whose
``PYTHONPATH`` is that worktree's ``src``: its code, this interpreter and
its libraries.  The reference workload is timed in this process right after
the ref's run, so that the ref's medians are normalised against the machine
as it was loaded then (a ref that predates the reference workload reports
none of its own).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from relaxgrip.bench.core import time_reference
from relaxgrip.errors import InputError

__all__ = ["checkout_root", "compare_reports", "resolve_ref", "run_on_ref"]

#: Longest a ref's benchmarks may take (s): the slowest (a dataset build) take minutes.
REF_TIMEOUT_S = 4 * 3600.0


def checkout_root() -> Path:
    """The git checkout this package runs from.

    Raises
    ------
    InputError
        When the package is not run from a git checkout (an installed wheel).
    """
    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "-C", str(here), "rev-parse", "--show-toplevel"],
                             capture_output=True, text=True, check=False, timeout=30)
    except FileNotFoundError:
        raise InputError("--compare needs git, and git is not installed") from None
    if out.returncode != 0:
        raise InputError(f"--compare needs relaxgrip run from a git checkout; {here} is not "
                         "in one")
    return Path(out.stdout.strip())


def resolve_ref(root: Path, ref: str) -> str:
    """The commit ``ref`` names in the checkout at ``root``.

    Raises
    ------
    InputError
        When ``ref`` names no commit there.
    """
    if not ref or ref.startswith("-"):
        raise InputError(f"--compare takes a git ref (a branch, tag or commit), got {ref!r}")
    out = subprocess.run(["git", "-C", str(root), "rev-parse", "--verify", "--quiet",
                          f"{ref}^{{commit}}"], capture_output=True, text=True, check=False,
                         timeout=30)
    if out.returncode != 0:
        raise InputError(f"--compare: no commit {ref!r} in the git checkout {root}")
    return out.stdout.strip()


def _last_line(text: str) -> str:
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    return lines[-1] if lines else "no output"


def run_on_ref(ref: str, names: list[str], repeat: int) -> dict[str, Any]:
    """Run ``relaxgrip bench NAMES --repeat REPEAT --json`` on ``ref``; its report.

    The report gains ``ref`` (as given), ``commit`` and ``reference_s``: this
    process's reference workload timed right after the ref's run.

    Raises
    ------
    InputError
        When ``ref`` names no commit, cannot be checked out, or its benchmarks
        do not run (an import error, an unknown benchmark there): the reason is
        the last line its command printed.
    """
    root = checkout_root()
    commit = resolve_ref(root, ref)
    with tempfile.TemporaryDirectory(prefix="relaxgrip-bench-") as tmp:
        tree = Path(tmp) / "tree"
        add = subprocess.run(["git", "-C", str(root), "worktree", "add", "--detach", "--quiet",
                              str(tree), commit], capture_output=True, text=True, check=False,
                             timeout=600)
        if add.returncode != 0:
            raise InputError(f"--compare: cannot check out {ref!r}: {_last_line(add.stderr)}")
        try:
            env = {**os.environ, "PYTHONPATH": str(tree / "src")}
            run = subprocess.run(
                [sys.executable, "-m", "relaxgrip", "bench", *names, "--repeat", str(repeat),
                 "--json"], capture_output=True, text=True, check=False, cwd=tree, env=env,
                timeout=REF_TIMEOUT_S)
        finally:
            subprocess.run(["git", "-C", str(root), "worktree", "remove", "--force", str(tree)],
                           capture_output=True, check=False, timeout=600)
            subprocess.run(["git", "-C", str(root), "worktree", "prune"], capture_output=True,
                           check=False, timeout=600)
    if run.returncode != 0:
        raise InputError(f"--compare: the benchmarks do not run on {ref!r} ({commit[:10]}): "
                         f"{_last_line(run.stderr or run.stdout)}")
    try:
        report: dict[str, Any] = json.loads(run.stdout)
    except json.JSONDecodeError:
        raise InputError(f"--compare: {ref!r} ({commit[:10]}) printed no JSON report: "
                         f"{_last_line(run.stdout)}") from None
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        report["reference_s"] = statistics.median(time_reference())
    report["ref"] = ref
    report["commit"] = commit
    return report


def compare_reports(here: dict[str, Any], there: dict[str, Any]) -> list[dict[str, Any]]:
    """Per benchmark of both reports: each median, and how many times faster this one is.

    ``speedup`` is the ref's median over this one's; ``speedup_normalised``
    divides each median by the reference workload timed beside it first (the
    figure to quote on a shared machine, whose load moves between the runs).
    """
    theirs = {b["name"]: b for b in there["benchmarks"]}
    rows = []
    for b in here["benchmarks"]:
        other = theirs.get(b["name"])
        if other is None:
            continue
        ours_rel = b["median_s"] / here["reference_s"]
        theirs_rel = other["median_s"] / there["reference_s"]
        rows.append({
            "name": b["name"],
            "median_s": b["median_s"],
            "ref_median_s": other["median_s"],
            "speedup": other["median_s"] / b["median_s"],
            "speedup_normalised": theirs_rel / ours_rel,
            "realtime_factor": b.get("realtime_factor"),
            "ref_realtime_factor": other.get("realtime_factor"),
        })
    return rows
