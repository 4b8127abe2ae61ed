"""What every figure shares: where it may be written, and the headless backend."""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

from relaxgrip.errors import InputError
from relaxgrip.fileio import check_writable, write_files_atomically

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["PLOT_FORMATS", "check_plot_path", "new_figure", "save_figure"]

PLOT_FORMATS: tuple[str, ...] = (".png", ".pdf", ".svg")


def check_plot_path(path: str | Path) -> Path:
    """Check that a figure can be written to ``path``.

    Parameters
    ----------
    path : str or pathlib.Path
        Output file; its extension selects the format.

    Returns
    -------
    pathlib.Path
        ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    relaxgrip.errors.InputError
        If the extension is not one of :data:`PLOT_FORMATS`, the parent
        directory does not exist (it is not created) or cannot be written,
        or ``path`` is a directory.
    """
    path = Path(path)
    if path.suffix.lower() not in PLOT_FORMATS:
        raise InputError(
            f"{path}: unsupported plot format {path.suffix or '(none)'!r}; "
            f"use one of {', '.join(PLOT_FORMATS)}"
        )
    if not path.parent.is_dir():
        raise InputError(f"{path}: directory {path.parent} does not exist")
    if path.is_dir():
        raise InputError(f"{path}: is a directory; name the figure file to write")
    check_writable(path, InputError)
    return path


def new_figure(width_in: float, height_in: float) -> Figure:
    """A matplotlib figure that needs no display (no pyplot state)."""
    from matplotlib.figure import Figure

    return Figure(figsize=(width_in, height_in), layout="constrained")


def save_figure(fig: Figure, path: str | Path, dpi: int = 150) -> Path:
    """Write ``fig`` to ``path`` atomically (rendered in memory, then one rename)."""
    path = check_plot_path(path)
    buffer = io.BytesIO()
    fig.savefig(buffer, format=path.suffix[1:].lower(), dpi=dpi)
    write_files_atomically(path.parent, [(path.name, buffer.getvalue())])
    return path
