"""The paper's grasping tasks by name: what ``relaxgrip task NAME`` runs.

A task is one closed-loop scenario on the twin (a grasp of the hammer, a pinch
of the 1 kg weight, the integrated cup demo, ...) that ends in a
:class:`TaskResult`: whether it succeeded, each success criterion checked
(read from the twin's ground truth by the experiment, never by the
controller), and the figures that back them.  The task functions live with
their experiments; this module only names them, so that the command line and
``relaxgrip reproduce`` import an experiment only when it is run.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from relaxgrip.errors import InputError
from relaxgrip.twin import TwinConfig

__all__ = ["TASKS", "TaskResult", "finite_figures", "run_task", "task_names"]


@dataclass(frozen=True)
class TaskResult:
    """Outcome of one task run.

    Attributes
    ----------
    name : str
        Task name (a key of :data:`TASKS`).
    seed : int
        Twin seed.
    criteria : mapping of str to bool
        Each success criterion and whether it held (``lifted``,
        ``not_crushed``, ``force_within_band``, ...).
    figures : mapping of str to float
        The numbers behind the criteria (peak force, steady-state error,
        lift height, ...), SI units named in the key (``_n``, ``_s``, ``_mm``, ``_c``).
    detail : mapping of str to Any
        Anything else worth printing (events, phases reached), JSON-serialisable.
    """

    name: str
    seed: int
    criteria: Mapping[str, bool]
    figures: Mapping[str, float]
    detail: Mapping[str, Any] = field(default_factory=dict)

    @property
    def success(self) -> bool:
        """Whether every criterion held."""
        return bool(self.criteria) and all(self.criteria.values())

    def to_dict(self) -> dict[str, Any]:
        """The ``--json`` object: ``success``, ``criteria`` and the figures."""
        return {
            "task": self.name,
            "seed": self.seed,
            "success": self.success,
            "criteria": {k: bool(v) for k, v in self.criteria.items()},
            "figures": {k: float(v) for k, v in self.figures.items()},
            **({"detail": dict(self.detail)} if self.detail else {}),
        }


def finite_figures(figures: Mapping[str, float]) -> dict[str, float]:
    """The finite entries of ``figures`` as floats (a task's figures are plain numbers)."""
    return {k: float(v) for k, v in figures.items() if math.isfinite(v)}


#: Task name -> (module, function); the function takes ``seed`` and ``config`` (the twin,
#: our gripper by default) and returns a TaskResult.
TASKS: dict[str, tuple[str, str]] = {
    "hammer": ("relaxgrip.experiments.stiffness_modulation", "hammer_task"),
    "orange": ("relaxgrip.experiments.stiffness_modulation", "orange_task"),
    "balloon": ("relaxgrip.experiments.stiffness_modulation", "balloon_task"),
    "feather": ("relaxgrip.experiments.stiffness_modulation", "feather_task"),
    "brush": ("relaxgrip.experiments.stiffness_modulation", "brush_task"),
    "wrench": ("relaxgrip.experiments.stiffness_modulation", "wrench_task"),
    "pinch-1kg": ("relaxgrip.experiments.multimode", "pinch_1kg_task"),
    "can": ("relaxgrip.experiments.multimode", "can_task"),
    "adhesive": ("relaxgrip.experiments.multimode", "adhesive_task"),
    "cup": ("relaxgrip.experiments.cup_demo", "cup_task"),
}


def task_names() -> list[str]:
    """Every task name, in the paper's order."""
    return list(TASKS)


def task_function(name: str) -> Callable[..., TaskResult]:
    """The function that runs task ``name``.

    Raises
    ------
    InputError
        If there is no such task (the message lists them).
    """
    try:
        module, attr = TASKS[name]
    except KeyError:
        raise InputError(f"unknown task {name!r}; tasks: {', '.join(TASKS)}") from None
    fn: Callable[..., TaskResult] = getattr(importlib.import_module(module), attr)
    return fn


def run_task(name: str, seed: int = 0, config: TwinConfig | None = None) -> TaskResult:
    """Run task ``name`` with ``seed`` on the twin ``config`` (our gripper by default)."""
    return task_function(name)(seed=seed, config=config)
