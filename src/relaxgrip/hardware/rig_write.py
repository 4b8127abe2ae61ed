"""Writing measured values into a rig file: its comments and layout kept, all or nothing.

``relaxgrip calibrate-camera --write`` puts the RGB camera's intrinsics and
distortion into ``[rgb]``; ``relaxgrip zero-pose --write`` puts the marker's
pose at rest into ``[zero_pose]``.  The file is edited as a document
(tomlkit), so every comment, blank line and key order a lab wrote stays;
only the values written change, each keeping its comment where it was.

:func:`update_rig_file` writes nothing unless the edited file is still a
valid rig file (:func:`relaxgrip.hardware.rig_file.parse_rig`), the file is
writable (a read-only file is refused, though renaming over it would
succeed), and nobody changed it since it was read (a live calibration takes
minutes).  The new text goes to a temporary file beside it, with the old
file's permissions and line endings, and is renamed over it: a crash leaves
the old file or the new one, never half of either.
"""

from __future__ import annotations

import math
import os
import stat
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import tomlkit
from tomlkit.items import Item, Table
from tomlkit.toml_document import TOMLDocument

from relaxgrip.errors import InputError
from relaxgrip.fileio import atomic_file, check_writable
from relaxgrip.hardware.rig_file import RigFile, ZeroPoseSpec, parse_rig, read_rig_text
from relaxgrip.rig import CameraIntrinsics

__all__ = ["check_rig_writable", "read_rig_for_edit", "remove_zero_pose", "set_rgb_intrinsics",
           "set_zero_pose", "update_rig_file"]

#: Decimals written: a thousandth of a pixel, ten thousandths of a mm and of a degree.
_PX_DECIMALS = 3
_MM_DECIMALS = 4
_DEG_DECIMALS = 4
#: Significant digits of a distortion coefficient.
_DIST_DIGITS = 8


def _set(table: Table | Any, key: str, value: Any) -> None:
    """Set ``table[key]``, keeping an existing key's comment in its column."""
    new: Item = tomlkit.item(value)
    if key in table:
        old = table.item(key)
        if isinstance(old, Item) and old.trivia.comment:
            column = len(f"{key} = {old.as_string()}") + len(old.trivia.comment_ws)
            new.trivia.comment_ws = " " * max(1, column - len(f"{key} = {new.as_string()}"))
            new.trivia.comment = old.trivia.comment
        table[key] = new
    else:
        table.add(key, new)


def _round(value: float, decimals: int) -> float:
    out = round(float(value), decimals)
    return 0.0 if out == 0.0 else out  # no -0.0 in the file


def set_rgb_intrinsics(doc: TOMLDocument, intrinsics: CameraIntrinsics) -> None:
    """Write focal lengths, principal point and distortion into ``[rgb]``.

    Parameters
    ----------
    doc : tomlkit.TOMLDocument
        The rig file, parsed by tomlkit.
    intrinsics : CameraIntrinsics
        The calibrated camera (its image size must be the table's).

    Raises
    ------
    InputError
        No ``[rgb]`` table.
    """
    if "rgb" not in doc:
        raise InputError("the rig file has no [rgb] table (no RGB camera) to write intrinsics to")
    table = doc["rgb"]
    for key, value in (("fx_px", intrinsics.fx_px), ("fy_px", intrinsics.fy_px),
                       ("cx_px", intrinsics.cx_px), ("cy_px", intrinsics.cy_px)):
        _set(table, key, _round(value, _PX_DECIMALS))
    dist = tomlkit.array()
    dist.extend(float(f"{d:.{_DIST_DIGITS}g}") for d in intrinsics.dist)
    _set(table, "dist", dist)


def set_zero_pose(doc: TOMLDocument, zero: ZeroPoseSpec) -> None:
    """Write the marker's pose at rest into ``[zero_pose]`` (made at the end if absent)."""
    if "zero_pose" not in doc:
        table = tomlkit.table()
        table.add(tomlkit.comment("the marker at rest in the RGB camera frame (fingers unloaded, "
                                  "heaters off): relaxgrip zero-pose"))
        doc.add(tomlkit.nl())
        doc.add("zero_pose", table)
    table = doc["zero_pose"]
    position = tomlkit.array()
    position.extend(_round(v * 1e3, _MM_DECIMALS) for v in zero.position_m)
    rotation = tomlkit.array()
    rotation.extend(_round(math.degrees(v), _DEG_DECIMALS) for v in zero.rotation_rvec)
    _set(table, "position_mm", position)
    _set(table, "rotation_deg", rotation)
    _set(table, "frames", int(zero.frames))
    _set(table, "spread_mm", _round(zero.spread_m * 1e3, _MM_DECIMALS))


def remove_zero_pose(doc: TOMLDocument) -> bool:
    """Drop ``[zero_pose]`` (measured through intrinsics being replaced); whether there was one."""
    if "zero_pose" not in doc:
        return False
    del doc["zero_pose"]
    return True


def read_rig_for_edit(path: str | Path) -> tuple[RigFile, str]:
    """A rig file, validated, and its text for :func:`update_rig_file`.

    Raises
    ------
    InputError
        As :func:`relaxgrip.hardware.rig_file.load_rig`.
    """
    text = read_rig_text(path)
    try:
        return parse_rig(tomllib.loads(text), str(path)), text
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"rig file {path} is not valid TOML: {exc}") from None


def check_rig_writable(path: str | Path) -> Path:
    """Check that a rig file can be replaced by its edited text; return the file to write.

    Raises
    ------
    InputError
        The file (a link's target) has no write permission (even where
        renaming over it would succeed: a read-only file says "leave me"),
        or its folder cannot be written.
    """
    p = Path(path)
    target = p.resolve()
    try:
        mode = stat.S_IMODE(os.stat(target).st_mode)
    except OSError as exc:
        raise InputError(f"rig file {p}: {exc.strerror or exc}") from None
    if not mode & 0o222 or not os.access(target, os.W_OK):
        raise InputError(f"rig file {p} is not writable (mode {mode:04o}): nothing written; "
                         "make it writable, or leave --write out to print the values")
    check_writable(target, InputError)
    return target


def update_rig_file(path: str | Path, before: str, edit: Callable[[TOMLDocument], Any]) -> RigFile:
    """Edit a rig file and write it back atomically, unless that would lose something.

    Parameters
    ----------
    path : str or Path
        The rig file (a symbolic link is written through, to the file it names).
    before : str
        Its text as read when the command started
        (:func:`relaxgrip.hardware.rig_file.read_rig_text`).
    edit : callable
        Changes the parsed document in place (:func:`set_rgb_intrinsics`, ...).

    Returns
    -------
    RigFile
        The rig file as written.

    Raises
    ------
    InputError
        The edited file is no valid rig file, the file is read-only or its
        folder cannot be written, or the file changed since ``before`` was
        read; nothing is written.
    OSError
        From the file system while writing (the old file stays whole).
    """
    p = Path(path)
    try:
        doc = tomlkit.parse(before)
    except Exception as exc:  # tomlkit's ParseError; tomllib read the file already
        raise InputError(f"rig file {p} cannot be edited as TOML: {exc}") from None
    edit(doc)
    text = tomlkit.dumps(doc)
    try:
        rig = parse_rig(tomllib.loads(text), str(p))
    except tomllib.TOMLDecodeError as exc:  # pragma: no cover - tomlkit writes valid TOML
        raise InputError(f"rig file {p}: the edit gave no valid TOML ({exc}): nothing "
                         "written") from None
    target = check_rig_writable(p)
    mode = stat.S_IMODE(os.stat(target).st_mode)
    raw = target.read_bytes()
    if read_rig_text(target) != before:
        raise InputError(f"rig file {p} changed since it was read: nothing written; run again")
    if b"\r\n" in raw:  # the file's own line ends
        text = text.replace("\r\n", "\n").replace("\n", "\r\n")
    with atomic_file(target) as fh:
        os.fchmod(fh.fileno(), mode)
        fh.write(text.encode("utf-8"))
    return rig
