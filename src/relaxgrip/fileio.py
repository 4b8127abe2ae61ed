"""Writing files so that a crash never leaves a half-written one.

Every file relaxgrip writes for a user (models, reports, figures) goes
through :func:`write_files_atomically`: each file is written to a temporary
name beside its destination, flushed to disk, and renamed into place; a
failure removes the temporaries and leaves whatever was there before.
"""

from __future__ import annotations

import hashlib
import io
import os
import secrets
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["file_entry", "npz_bytes", "write_files_atomically", "write_text_atomically"]


def npz_bytes(arrays: Mapping[str, Any]) -> bytes:
    """``arrays`` as the bytes of an uncompressed ``.npz`` file (no pickled objects)."""
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


def file_entry(name: str, data: bytes) -> dict[str, Any]:
    """A manifest's record of one file: its name, size and SHA-256."""
    return {"file": name, "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}


def write_files_atomically(directory: Path, files: Sequence[tuple[str, bytes]]) -> None:
    """Write each ``(name, data)`` to a temporary file, then rename all into place, in order.

    Parameters
    ----------
    directory : Path
        An existing directory.
    files : sequence of (str, bytes)
        File names inside ``directory`` and their contents; the last one is
        renamed last (put a manifest there).
    """
    temporaries: list[tuple[Path, Path]] = []
    try:
        for name, data in files:
            # Not mkstemp: its files are private (0600); these get the umask's mode.
            tmp = directory / f".{name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            temporaries.append((tmp, directory / name))
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
        for tmp, final in temporaries:
            os.replace(tmp, final)
    finally:
        for tmp, _ in temporaries:
            tmp.unlink(missing_ok=True)
    try:  # make the renames durable; not every platform can open a directory
        dir_fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dir_fd)
    except OSError:
        pass
    finally:
        os.close(dir_fd)


def write_text_atomically(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file and a rename."""
    path = Path(path)
    write_files_atomically(path.parent, [(path.name, text.encode("utf-8"))])
