"""Build a dataset in parallel: joblib over episodes and sequences, any joblib backend.

Each unit of work (an ICFN episode, an RCFN sequence) is a pure function of
its spec and seed, so the result does not depend on how many workers run it,
on which backend, or in what order they finish.  ``loky`` (processes on this
machine) is the default; ``dask`` and ``ray`` (optional extras) run the same
units on a cluster: set ``DASK_SCHEDULER_ADDRESS`` or ``RAY_ADDRESS`` to use
an existing one, otherwise a local one is started.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict
from pathlib import Path
from typing import Any

import pandas as pd

from relaxgrip import __version__
from relaxgrip.errors import InputError
from relaxgrip.fileio import json_digest
from relaxgrip.learning.datasets import (
    REPEAT_TEMPS_C,
    REPEATS_PER_GROUP,
    DatasetSpec,
    UnitResult,
    iter_units,
    run_unit,
)
from relaxgrip.learning.datastore import (
    DATASET_FORMAT,
    DATASET_VERSION,
    check_dataset_out,
    split_counts,
    training_gaps,
    write_dataset,
)
from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
from relaxgrip.serialize import json_safe
from relaxgrip.twin import TWIN_VERSION, TwinConfig
from relaxgrip.validate import check_jobs

__all__ = ["BACKENDS", "build_dataset", "check_backend", "gripper_record", "parallel_backend"]

BACKENDS: tuple[str, ...] = ("loky", "dask", "ray")

ProgressFn = Callable[[int, int], None]


def check_backend(name: str) -> str:
    """Return ``name`` if it is a backend whose optional dependency imports.

    Checked before a build starts (and before a progress bar shows), not when
    its workers are wanted.

    Raises
    ------
    InputError
        For an unknown backend, or one whose optional dependency is missing.
    """
    if name not in BACKENDS:
        raise InputError(f"unknown backend {name!r}; choose one of {', '.join(BACKENDS)}")
    if name == "dask":
        try:
            import dask.distributed  # noqa: F401
        except ImportError:
            raise InputError("--backend dask needs Dask: pip install 'relaxgrip[dask]'") from None
    if name == "ray":
        try:
            import ray.util.joblib  # noqa: F401
        except ImportError:
            raise InputError("--backend ray needs Ray: pip install 'relaxgrip[ray]'") from None
    return name


@contextmanager
def parallel_backend(name: str, jobs: int) -> Iterator[int]:
    """Configure joblib for ``name``; yields the ``n_jobs`` to pass to ``Parallel``.

    Raises
    ------
    InputError
        For an unknown backend, or one whose optional dependency is missing.
    """
    import joblib

    check_backend(name)
    if name == "loky":
        with joblib.parallel_config(backend="loky", inner_max_num_threads=1):
            yield jobs
        return
    if name == "dask":
        from dask.distributed import Client, LocalCluster

        address = os.environ.get("DASK_SCHEDULER_ADDRESS")
        cluster = None if address else LocalCluster(
            n_workers=jobs, threads_per_worker=1, processes=True, host="127.0.0.1",
            dashboard_address=None,
        )
        client = Client(address or cluster)
        try:
            with joblib.parallel_config(backend="dask"):
                yield -1
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
        return
    if name == "ray":
        import ray
        from ray.util.joblib import register_ray

        register_ray()
        started = not ray.is_initialized()
        if started:
            ray.init(address=os.environ.get("RAY_ADDRESS"), num_cpus=None
                     if os.environ.get("RAY_ADDRESS") else jobs, include_dashboard=False)
        try:
            with joblib.parallel_config(backend="ray"):
                yield -1
        finally:
            if started:
                ray.shutdown()
        return


def _run(unit: Any, config: TwinConfig) -> UnitResult:
    """One unit in a worker: OpenCV on one thread (the parallelism is across units)."""
    import cv2

    cv2.setNumThreads(1)
    return run_unit(unit, config)


def _noise_levels(cfg: TwinConfig) -> dict[str, Any]:
    """The imperfections the twin has, as the manifest records them."""
    assert cfg.rgb is not None
    assert cfg.ir is not None
    assert cfg.force_sensor is not None
    sc = cfg.scatter
    return {
        "unit": cfg.unit,
        "unit_scatter": "stiffness, Tg and the infrared camera offset are drawn once per unit",
        "rgb_pixel_noise_dn": cfg.rgb.noise_dn,
        "rgb_marker_drawing": ("exact area of each pixel" if cfg.rgb.drawing == "exact"
                               else f"supersampled {cfg.rgb.supersample}x"),
        "ir_netd_k": cfg.ir.netd_k,
        "ir_camera_offset_max_k": cfg.ir.max_offset_k,
        "ir_finger_emissivity": cfg.ir.finger_emissivity,
        "contact_position_scatter_m": sc.contact_position_m,
        "stiffness_scatter_rel": sc.stiffness_rel,
        "relaxing_share_scatter_rel": sc.relax_fraction_rel,
        "relaxing_share_scatter_rubbery_rel": sc.relax_fraction_rel_rubbery,
        "tau_scatter_rel": sc.tau_rel,
        "tg_scatter_k": sc.tg_k,
        "ambient_scatter_k": sc.ambient_k,
        "temperature_field": ("steady heated profile of each finger (non-uniform along it); "
                              "about a fifth of the ICFN episodes close as the fingers cool "
                              "with the heaters off, and a twentieth after heating at full "
                              "duty (a change of stiffness mode)"),
    }


def gripper_record(cfg: TwinConfig) -> dict[str, Any]:
    """Which gripper a dataset was recorded on: a digest of everything the rig file sets
    (every field of the twin but the experiment's object and scene), and a few of them."""
    parts = ("finger", "heat", "relax", "motor", "rig", "force_sensor", "force_ball")
    gripper: dict[str, Any] = {name: None if getattr(cfg, name) is None
                               else asdict(getattr(cfg, name)) for name in parts}
    gripper["contact_position_m"] = cfg.contact_position_m
    return {"digest": json_digest(json_safe(gripper)),
            "finger_length_m": cfg.finger.length_m,
            "marker": {"dictionary": cfg.rig.marker.dictionary, "id": cfg.rig.marker.marker_id}}


def _table(parts: list[dict[str, list[Any]]], order: list[str]) -> pd.DataFrame:
    frames = [pd.DataFrame(p) for p in parts if any(len(v) for v in p.values())]
    if not frames:
        return pd.DataFrame()
    return pd.concat(frames, ignore_index=True).sort_values(order, kind="stable",
                                                            ignore_index=True)


def build_dataset(
    out_dir: Path,
    spec: DatasetSpec,
    jobs: int = 1,
    backend: str = "loky",
    progress: ProgressFn | None = None,
    config: TwinConfig | None = None,
) -> dict[str, Any]:
    """Generate a dataset into ``out_dir`` and return its manifest.

    Parameters
    ----------
    out_dir : Path
        Target directory (created; a previous relaxgrip dataset is replaced).
    spec : DatasetSpec
        Sizes and seed.
    jobs : int
        Parallel workers (``loky``; the Dask and Ray backends use their cluster's).
    backend : {"loky", "dask", "ray"}
        joblib backend.
    progress : callable, optional
        Called as ``progress(done, total)`` after every unit.
    config : TwinConfig, optional
        The twin the data is recorded on (default: our gripper; a rig's from
        :func:`relaxgrip.hardware.rig_twin.twin_config_for_rig`); the manifest
        records its gripper (``gripper``).
    """
    from joblib import Parallel, delayed

    check_jobs(jobs)
    check_backend(backend)
    check_dataset_out(out_dir)  # before minutes of building, not after
    cfg = config if config is not None else TwinConfig()
    units = list(iter_units(spec, cfg))
    start = time.perf_counter()
    results: list[UnitResult] = []
    # No more workers than units: each is a process that imports the package.
    with parallel_backend(backend, max(1, min(jobs, len(units)))) as n_jobs:
        parallel = Parallel(n_jobs=n_jobs, return_as="generator_unordered")
        for result in parallel(delayed(_run)(unit, cfg) for unit in units):
            results.append(result)
            if progress is not None:
                progress(len(results), len(units))
    results.sort(key=lambda r: (r.kind, r.index))
    icfn = [r for r in results if r.kind == "icfn"]
    rcfn = [r for r in results if r.kind == "rcfn"]
    tables = {
        "icfn": _table([r.rows for r in icfn], ["episode", "t_s"]),
        "rcfn_sequences": _table([{k: [v] for k, v in r.sequence.items()} for r in rcfn],
                                 ["sequence"]),
        "rcfn_features": _table([r.features for r in rcfn], ["sequence", "t_s"]),
        "rcfn_curves": _table([r.curve for r in rcfn], ["sequence", "t_s"]),
    }
    counts = split_counts(tables)
    repeats = REPEATS_PER_GROUP * len(REPEAT_TEMPS_C)
    warnings = training_gaps(counts, {
        "icfn": "more --icfn-samples",
        "rcfn_sequences": f"more --rcfn-sequences (the first {repeats} are the repeatability "
                          "holds, all kept for test)"})
    manifest = {
        "format": DATASET_FORMAT,
        "format_version": DATASET_VERSION,
        "relaxgrip_version": __version__,
        "twin_version": TWIN_VERSION,
        "icfn_schema": ICFN_SCHEMA.to_dict(),
        "rcfn_schema": RCFN_SCHEMA.to_dict(),
        "spec": {**spec.__dict__, "split": list(spec.split)},
        "counts": {
            "icfn_samples": len(tables["icfn"]),
            "icfn_dropped": sum(r.dropped for r in icfn),
            "rcfn_sequences": len(tables["rcfn_sequences"]),
            "rcfn_dropped": sum(r.dropped for r in rcfn),
            "splits": counts,
        },
        "warnings": warnings,
        "noise": _noise_levels(cfg),
        "gripper": gripper_record(cfg),
        "build": {"backend": backend, "jobs": jobs, "seconds": time.perf_counter() - start},
    }
    write_dataset(out_dir, tables, manifest)
    return manifest
