"""Writing files so that a crash never leaves a half-written one, and reading them back checked.

Every file relaxgrip writes for a user (models, reports, figures) goes
through :func:`write_files_atomically`: each file is written to a temporary
name beside its destination, flushed to disk, and renamed into place; a
failure while writing removes the temporaries and leaves whatever was there
before.  A destination that exists and is not a regular file (a FIFO, a
device, a socket, a directory) is refused before anything is written: a rename
would put a regular file in its place.  The renames of several files are not
one step: a failure between them (the machine dies) can leave new files beside
an old manifest, which is renamed last and records every file's SHA-256, so
loading detects it.

Model directories (a ``manifest.json`` naming its format and version, and
``.npz`` arrays recorded by :func:`file_entry`) are read back through
:func:`read_manifest` and :func:`read_npz_entry`, which raise the caller's
one-line error on anything missing, foreign, too new, truncated or modified.

Input files a command reads (a recording, a rig file, an image, a CSV) pass
:func:`check_input_file` first: a FIFO, a device or a socket is refused by
name rather than read (reading a FIFO without a writer blocks for ever,
``/dev/zero`` never ends), and a file far larger than its kind can be is
refused before it fills the memory.
"""

from __future__ import annotations

import errno
import hashlib
import io
import json
import os
import secrets
import stat
from collections.abc import Collection, Iterator, Mapping, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "atomic_file",
    "check_input_file",
    "check_output_dir",
    "check_replaceable",
    "check_writable",
    "entries",
    "file_entry",
    "json_digest",
    "made_directory",
    "named_errors",
    "npz_bytes",
    "one_line",
    "read_manifest",
    "read_npz_entry",
    "write_files_atomically",
    "write_text_atomically",
]


def npz_bytes(arrays: Mapping[str, Any]) -> bytes:
    """``arrays`` as the bytes of an uncompressed ``.npz`` file (no pickled objects)."""
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


def json_digest(value: Any) -> str:
    """Short hash (16 hex digits) of a JSON value, whatever its keys' order."""
    text = json.dumps(value, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


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

    Raises
    ------
    OSError
        From the file system, and before anything is written if a name exists
        there and is not a regular file (:func:`check_replaceable`).
    """
    for name, _ in files:  # before anything is written
        _check_replaceable(directory / name)
    temporaries: list[tuple[Path, Path]] = []
    try:
        for name, data in files:
            tmp, fd = _temporary(directory, name)
            temporaries.append((tmp, directory / name))
            with named_errors(directory / name), os.fdopen(fd, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
        for tmp, final in temporaries:
            os.replace(tmp, final)
    finally:
        for tmp, _ in temporaries:
            tmp.unlink(missing_ok=True)
    _sync_directory(directory)


@contextmanager
def named_errors(path: Path) -> Iterator[None]:
    """An error of the file system in the block names ``path`` where it names no file.

    A full disk's ``OSError`` names none: the one line relaxgrip prints would
    not say which output it was.
    """
    try:
        yield
    except OSError as exc:
        if exc.filename is not None:
            raise
        raise OSError(exc.errno, exc.strerror or one_line(exc), str(path)) from exc


@contextmanager
def made_directory(directory: Path) -> Iterator[Path]:
    """``directory``, made with its missing parents, for the block to write in.

    If the block fails (a full disk), the folders this made are removed
    again where they are empty: a failed output leaves nothing behind.
    """
    directory = Path(directory)
    missing = []
    folder = directory
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    directory.mkdir(parents=True, exist_ok=True)
    try:
        yield directory
    except BaseException:
        for folder in missing:  # the deepest first
            with suppress(OSError):  # not empty: someone wrote there meanwhile
                folder.rmdir()
        raise


def _temporary(directory: Path, name: str) -> tuple[Path, int]:
    """A new temporary file beside ``directory / name``, open for writing."""
    # Not mkstemp: its files are private (0600); these get the umask's mode.
    tmp = directory / f".{name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    try:
        return tmp, os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as exc:  # named by the file the caller asked for, not the temporary
        raise OSError(exc.errno, exc.strerror, str(directory / name)) from None


@contextmanager
def atomic_file(path: Path) -> Iterator[io.BufferedWriter]:
    """A binary file to write ``path`` through: it appears there, whole, only on success.

    For outputs too large to hold in memory (a recovered recording).  The
    file is a temporary beside ``path``, flushed to disk and renamed into
    place when the block ends; an exception in the block removes it and
    leaves whatever was at ``path`` before.

    Raises
    ------
    OSError
        From the file system (no such directory, no space, read-only), and
        if ``path`` exists and is not a regular file (:func:`check_replaceable`).
    """
    path = Path(path)
    _check_replaceable(path)
    tmp, fd = _temporary(path.parent, path.name)
    try:
        with named_errors(path), os.fdopen(fd, "wb") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    _sync_directory(path.parent)


def _special_kind(path: Path) -> str | None:
    """What ``path`` is if it exists and is not a regular file ("a FIFO"); else None.

    Symbolic links are followed: one to a regular file is a regular file.
    """
    try:
        mode = os.stat(path).st_mode
    except OSError:  # absent, or unreachable: the write itself reports that
        return None
    return _kind_of(mode)


def _kind_of(mode: int) -> str | None:
    """What a file of ``st_mode`` ``mode`` is if not a regular file ("a FIFO"); else None."""
    if stat.S_ISREG(mode):
        return None
    kinds = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"),
             (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
             (stat.S_ISSOCK, "a socket"))
    return next((kind for test, kind in kinds if test(mode)), "a special file")


def check_input_file(path: Path, what: str, error: type[Exception],
                     max_bytes: int | None = None) -> Path:
    """Check that ``path`` is a regular file to read (of at most ``max_bytes``), before opening it.

    Symbolic links are followed: one to a regular file is a regular file.  A
    FIFO (a shell's ``<(...)`` too), a device or a socket is refused, not
    read: reading a FIFO without a writer blocks for ever, ``/dev/zero``
    never ends, and a recording is read with seeks a pipe cannot make.

    Parameters
    ----------
    path : Path
        The file a command was given.
    what : str
        What it should be, for the messages ("recording", "rig file").
    error : exception class
        Raised, with one line naming ``path`` and the problem.
    max_bytes : int, optional
        The largest size taken (bytes); a larger file is refused before it is read.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    error
        ``path`` is missing ("no such <what>"), unreachable, a directory, not a
        regular file (saying what it is), or larger than ``max_bytes``.
    """
    path = Path(path)
    try:
        info = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        raise error(f"{path}: no such {what}") from None
    except OSError as exc:  # permission on a folder, a loop of links, a name too long
        raise error(f"{path}: cannot read ({exc.strerror or one_line(exc)})") from None
    kind = _kind_of(info.st_mode)
    if kind == "a directory":
        raise error(f"{path}: is a directory, not {_indefinite(what)}")
    if kind is not None:
        raise error(f"{path}: is {kind}, not a regular file")
    if max_bytes is not None and info.st_size > max_bytes:
        raise error(f"{path}: is {info.st_size:,} bytes, over the {_size_text(max_bytes)} "
                    f"limit for {_indefinite(what)}")
    return path


def _indefinite(noun: str) -> str:
    """``noun`` with its indefinite article ("a recording", "an image file")."""
    return f"{'an' if noun[:1].lower() in ('a', 'e', 'i', 'o', 'u') else 'a'} {noun}"


def _size_text(n_bytes: int) -> str:
    """A size as people read it: "512 bytes", "1 MiB", "2.5 GiB"."""
    size = float(n_bytes)
    for unit in ("bytes", "KiB", "MiB", "GiB"):
        if size < 1024.0:
            return f"{n_bytes:,} bytes" if unit == "bytes" else f"{size:.4g} {unit}"
        size /= 1024.0
    return f"{size:.4g} TiB"


def _check_replaceable(path: Path) -> None:
    """Refuse, before anything is written, to rename a file over a FIFO, a device, a socket
    or a directory: the rename would silently put a regular file in its place."""
    kind = _special_kind(path)
    if kind is not None:
        raise OSError(errno.EEXIST, f"is {kind}, not a regular file to replace", str(path))


def check_replaceable(path: Path, error: type[Exception]) -> None:
    """Check that ``path`` is absent or a regular file, which an atomic write may replace.

    Raises
    ------
    error
        Naming ``path`` and what it is instead (a FIFO, a device, a socket,
        a directory).
    """
    kind = _special_kind(Path(path))
    if kind is not None:
        raise error(f"{path} is {kind}, not a regular file: choose another output")


def _sync_directory(directory: Path) -> None:
    """Make the renames in ``directory`` durable."""
    try:  # not every platform can open a directory
        dir_fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dir_fd)
    except OSError:
        pass
    finally:
        os.close(dir_fd)


def check_writable(path: Path, error: type[Exception]) -> None:
    """Check, by writing a probe file, that ``path`` can be created where it is to go.

    The probe goes into ``path``'s nearest existing ancestor directory (the
    one a write would create the rest under) and is removed at once.  Run it
    before a long computation whose result goes to ``path``.

    Raises
    ------
    error
        Naming ``path`` and the system's reason (read-only, permission, no
        such directory, a file where a directory should be), or what ``path``
        is if it exists and is not a regular file (:func:`check_replaceable`).
    """
    path = Path(path)
    check_replaceable(path, error)
    folder = path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise error(f"{path}: {folder} is not a directory")
    try:
        tmp, fd = _temporary(folder, f"{path.name}.probe")
        os.close(fd)
        tmp.unlink()
    except OSError as exc:
        raise error(f"{path}: cannot write in {folder} ({exc.strerror or exc})") from None


def check_new_file(path: Path, flag: str, overwrite: bool, error: type[Exception]) -> Path:
    """Check that ``path`` (given with ``flag``) may be written: new, or ``overwrite`` given.

    A run that records for minutes must not silently replace the recording
    of an earlier one.

    Raises
    ------
    error
        ``path`` exists and ``overwrite`` is false, is a directory or a
        special file, or cannot be written where it is to go.
    """
    path = Path(path)
    if path.is_dir():
        raise error(f"{flag} {path} is a directory: give a file name")
    if (path.exists() or path.is_symlink()) and not overwrite:
        raise error(f"{flag} {path} exists: add --overwrite to replace it")
    check_writable(path, error)
    return path


def check_input_dir(path: Path, what: str, error: type[Exception]) -> Path:
    """Check that ``path`` is a directory (``what``: "dataset directory"), before reading it.

    Raises
    ------
    error
        ``path`` is missing ("no such <what>") or is a file, not a directory
        (named as such: a file given where a directory is expected).
    """
    path = Path(path)
    if path.is_dir():
        return path
    if path.exists():
        raise error(f"{path}: a file, not a directory ({_indefinite(what)} is expected)")
    raise error(f"{path}: no such {what}")


def entries(directory: Path) -> set[str]:
    """The names in ``directory``, but for the temporaries an interrupted write left there.

    Raises
    ------
    OSError
        If the directory cannot be listed.
    """
    return {p.name for p in Path(directory).iterdir()
            if not (p.name.startswith(".") and p.name.endswith(".tmp"))}


def check_output_dir(directory: Path, format_name: str, own: Collection[str],
                     error: type[Exception]) -> Path:
    """Check that a directory output can be written at ``directory`` and lose nothing.

    It may be absent, empty, or an earlier output of the same format
    (``manifest.json`` naming ``format_name``) that holds only ``own``
    files, which the new output replaces; and its place must be writable.

    Raises
    ------
    error
        A file there, a directory of something else, foreign files in an
        earlier output, or no permission to write.
    """
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise error(f"{directory} exists and is not a directory: choose another --out")
    if directory.is_dir():
        names = entries(directory)
        if names:
            try:
                found = json.loads((directory / "manifest.json").read_text("utf-8")).get("format")
            except (OSError, ValueError, AttributeError):
                found = None
            if found != format_name:
                raise error(f"{directory} is not empty and holds no {format_name} output: "
                            "choose another --out")
            foreign = sorted(names - set(own) - {"manifest.json"})
            if foreign:
                raise error(f"{directory} holds files that are not the {format_name} output's "
                            f"({', '.join(foreign[:3])}{', ...' if len(foreign) > 3 else ''}): "
                            "choose another --out")
    check_writable(directory / "manifest.json" if directory.is_dir() else directory, error)
    return directory


def read_text_csv(path: Path, error: type[Exception]) -> str:
    """The text of a CSV file already checked as an input file (UTF-8, a BOM allowed).

    Raises
    ------
    error
        The file is not UTF-8 text, holds NUL bytes (binary content), or cannot be read.
    """
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise error(f"{path}: not a text CSV file (not UTF-8)") from None
    except OSError as exc:
        raise error(f"{path}: cannot read: {exc.strerror or exc}") from None
    if "\0" in text:
        raise error(f"{path}: not a text CSV file (binary content)")
    return text


def write_text_atomically(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file and a rename."""
    path = Path(path)
    write_files_atomically(path.parent, [(path.name, text.encode("utf-8"))])


def one_line(exc: BaseException) -> str:
    """An exception's message on one line (its type's name if it has none)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def read_manifest(path: Path, format_name: str, format_version: int,
                  error: type[Exception], what: str) -> dict[str, Any]:
    """A manifest's JSON object, checked to be of ``format_name`` and at most ``format_version``.

    Parameters
    ----------
    path : Path
        The ``manifest.json``.
    format_name, format_version : str, int
        The format it must name, and the newest version this code reads.
    error : exception class
        Raised, with one line naming ``path`` and the problem.
    what : str
        What the directory should be, for the messages ("a relaxgrip model directory").
    """
    parent = path.parent
    if parent.exists() and not parent.is_dir():
        raise error(f"{parent}: a file, not a directory ({what} is expected)")
    if not path.is_file():
        raise error(f"{path}: missing (not {what}?)")
    try:
        manifest = json.loads(path.read_bytes().decode("utf-8"))
    except OSError as exc:
        raise error(f"{path}: cannot read: {one_line(exc)}") from exc
    except ValueError as exc:  # JSONDecodeError and UnicodeDecodeError
        raise error(f"{path}: unreadable manifest, not {what} ({one_line(exc)})") from exc
    if not isinstance(manifest, dict) or manifest.get("format") != format_name:
        raise error(f"{path}: not {what} (no {format_name!r} format)")
    version = manifest.get("format_version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise error(f"{path}: format version {version!r} is not a positive integer")
    if version > format_version:
        raise error(f"{path}: format version {version} is newer than this relaxgrip reads "
                    f"({format_version}); upgrade relaxgrip")
    return manifest


def read_npz_entry(directory: Path, entry: Mapping[str, Any],
                   error: type[Exception]) -> tuple[Path, dict[str, Any]]:
    """The arrays of the file a manifest entry (:func:`file_entry`) names, size and sha256 checked.

    Returns the file's path and its arrays (loaded without pickle); raises
    ``error`` with one line naming the file and the problem.
    """
    name = entry["file"]
    if not isinstance(name, str) or Path(name).name != name:
        raise error(f"{directory / 'manifest.json'}: bad file name {name!r}")
    path = directory / name
    if not path.is_file():
        raise error(f"{path}: missing")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise error(f"{path}: cannot read: {one_line(exc)}") from exc
    if len(data) != entry["bytes"]:
        raise error(f"{path}: truncated or modified ({len(data)} bytes, the manifest says "
                    f"{entry['bytes']})")
    if hashlib.sha256(data).hexdigest() != entry["sha256"]:
        raise error(f"{path}: truncated or modified (sha256 differs from the manifest)")
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            arrays = {key: npz[key] for key in npz.files}
    except Exception as exc:  # zipfile, npy-format and pickle refusals all land here
        raise error(f"{path}: unreadable npz: {one_line(exc)}") from exc
    return path, arrays
