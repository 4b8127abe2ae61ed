"""Plain-JSON forms of results: what every ``to_dict`` and ``--json`` output passes through."""

from __future__ import annotations

import math
from typing import Any, overload

__all__ = ["json_safe"]


@overload
def json_safe(obj: dict[str, Any]) -> dict[str, Any]: ...


@overload
def json_safe(obj: Any) -> Any: ...


def json_safe(obj: Any) -> Any:
    """``obj`` as strict JSON: non-finite floats become ``None``, NumPy scalars Python numbers.

    Dicts (keys as strings), lists and tuples are converted recursively;
    anything else is returned as it is.
    """
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item) and getattr(obj, "ndim", None) == 0:
        return json_safe(obj.item())  # a NumPy scalar
    return obj
