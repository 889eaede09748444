"""Atomic file writes and JSON-safe values: the one copy every writer of the library uses.

A write goes to a temporary file in the destination's folder and is renamed over it
(``os.replace``), so a crash or a kill leaves the old file or the new one, never half a file
(docs page *Reliability*). `json_safe` turns numpy scalars/arrays, paths and non-finite floats
into plain JSON values, and names where a value that JSON cannot hold sits.

Why one file: every way the library puts a file on disk (atomic writes, locks, the claim of an
``--out`` folder and its undoing) shares the temporary names and link checks defined here;
split, a writer could miss one of them.
"""

from __future__ import annotations

import contextlib
import fnmatch
import glob
import io
import json
import math
import os
import stat
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

__all__ = ["atomic_write_bytes", "atomic_write_text", "atomic_write_with", "atomic_savez",
           "write_json", "json_safe", "fsync_dir", "leftover_temporaries", "single_writer",
           "EnvironmentFailure", "names_path", "check_writable", "claim_out_dir", "out_marker",
           "json_record", "remove_outputs", "file_identity", "is_locked", "claim_state",
           "release_claim"]


_TMP_SUFFIX = ".tmp"


class EnvironmentFailure(RuntimeError):
    """A run stopped by its surroundings, not by its inputs or a bug: another process holds the
    writer lock, a worker process was killed. Resolve the cause and rerun the same command (it
    resumes). ``handmesh`` exits with code 6 (``cli.EXIT_CODES["environment"]``), as for a full
    disk or a read-only folder."""


@contextlib.contextmanager
def names_path(path: str | os.PathLike):
    """Re-raise an ``OSError`` that names no file (``write`` on a full disk: ``[Errno 28] No
    space left on device``) as the same error type and errno naming ``path``.

    Raises:
        OSError: the original error with ``filename=path`` (same subclass, e.g.
            ``PermissionError``), chained to it.
    """
    try:
        yield
    except OSError as err:
        if err.filename is not None or err.errno is None:
            raise
        raise OSError(err.errno, err.strerror or str(err), os.fspath(path)) from err


@contextlib.contextmanager
def single_writer(lock_file: str | os.PathLike, what: str):
    """One writer at a time: an exclusive ``flock`` on ``lock_file``, which the OS drops when the
    process dies (even on SIGKILL), so a stale lock never blocks a rerun.

    The lock is opened with ``O_NOFOLLOW``: a symbolic link in its place is refused, never
    followed (a planted ``.generate.lock -> /etc/nologin`` would otherwise create the link's
    target), and anything but a regular file there (a folder, a FIFO, a socket) is refused too.

    Args:
        lock_file: the lock's path (created if missing; its folder must exist).
        what: the resource, for the message (e.g. ``"runs/demo/data"``).

    Raises:
        EnvironmentFailure: another process holds the lock, or ``lock_file`` is a symbolic link
            or not a regular file (a ``RuntimeError``; the message names ``what`` and the file).
        OSError: the lock cannot be created (read-only or forbidden folder); names the file.
    """
    try:
        import fcntl
    except ImportError:  # not POSIX: no protection against two writers
        yield
        return
    flags = (os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
             | getattr(os, "O_NONBLOCK", 0))  # O_NONBLOCK: a FIFO planted there cannot block
    try:
        fd = os.open(lock_file, flags, 0o644)
    except OSError as err:
        if os.path.islink(lock_file):  # ELOOP (Linux) or EMLINK (BSD): a link in its place
            raise EnvironmentFailure(
                f"{lock_file} is a symbolic link (to {os.readlink(lock_file)}): a lock file is "
                f"never opened through a link, so {what} is not written; remove the link and "
                "rerun") from None
        if os.path.isdir(lock_file):
            raise EnvironmentFailure(f"{lock_file} is a folder: it cannot serve as the writer "
                                     f"lock of {what}; move it away and rerun") from None
        if os.path.exists(lock_file) and not os.path.isfile(lock_file):  # a socket: ENXIO
            raise EnvironmentFailure(f"{lock_file} is not a regular file: it cannot serve as "
                                     f"the writer lock of {what}; remove it and rerun") from None
        raise OSError(err.errno, err.strerror, os.fspath(lock_file)) from err
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise EnvironmentFailure(f"{lock_file} is not a regular file: it cannot serve as the "
                                     f"writer lock of {what}; remove it and rerun")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise EnvironmentFailure(f"{what} is being written by another process ({lock_file} "
                                     "is locked); wait for it to end, or stop it") from None
        try:
            yield
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


def is_locked(lock_file: str | os.PathLike) -> bool:
    """Whether another process holds `single_writer`'s lock on ``lock_file`` now (a reader's
    question: nothing is created, a link or a missing file is no lock)."""
    try:
        import fcntl
    except ImportError:
        return False
    try:
        fd = os.open(lock_file, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0)
                     | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    else:
        fcntl.flock(fd, fcntl.LOCK_UN)
        return False
    finally:
        os.close(fd)


def check_writable(folder: str | os.PathLike) -> Path:
    """Create ``folder`` (and its parents) and check that a file can be written in it, before a
    long computation whose results go there.

    Returns:
        The folder.

    Raises:
        OSError: it cannot be created or written (read-only file system, no permission, a file
            in the way); the error names the folder.
    """
    folder = Path(folder)
    with names_path(folder):
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder, prefix=".write-check-"):
            pass
    return folder


def leftover_temporaries(path: str | os.PathLike) -> list[Path]:
    """The temp files `atomic_write_bytes` of ``path`` leaves when killed mid-write
    (``.<name>.<random>.tmp`` beside ``path``)."""
    path = Path(path)
    pattern = f".{glob.escape(path.name)}.*{_TMP_SUFFIX}"
    return sorted(p for p in path.parent.glob(pattern) if p.is_file())


def fsync_dir(path: str | os.PathLike) -> None:
    """``fsync`` a folder so a rename inside it survives a power cut (a no-op where the
    platform or filesystem cannot)."""
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _new_file_mode() -> int:
    """The mode ``open()`` gives a new file: ``0o666`` less the process's umask (``0o644`` under
    the usual 022, ``0o600`` under 077), so an atomic write shares a file exactly as widely as
    the user's other files (and the sample folders the generator writes)."""
    try:  # Linux: read, never set (setting it for a moment would race other threads)
        with open("/proc/self/status", encoding="ascii") as fh:
            mask = next(int(ln.split()[1], 8) for ln in fh if ln.startswith("Umask:"))
    except (OSError, StopIteration, ValueError, IndexError):
        mask = os.umask(0)
        os.umask(mask)
    return 0o666 & ~mask


def atomic_write_with(path: str | os.PathLike, write: Callable[[IO], Any], *, binary: bool = True,
                      durable: bool = True, tmp_path: str | os.PathLike | None = None) -> Path:
    """Call ``write(file)`` on a temporary file beside ``path``, then rename it to ``path``.

    Args:
        path: destination file; parent folders are created.
        write: writes the content into the open file object it is given.
        binary: open the temporary file in ``"wb"`` (default) or ``"w"`` (UTF-8 text).
        durable: ``fsync`` the file before the rename and the folder after it (a crash then
            leaves the old or the new file, never a truncated one, even on a power cut).
        tmp_path: where to put the temporary file (must be in ``path``'s folder); default
            ``.<name>.<random>.tmp`` (the form `leftover_temporaries` finds).

    Returns:
        The written path, with the mode a new file gets under the user's umask (``0o644``
        under 022, ``0o600`` under 077).

    Raises:
        OSError: the write failed (full disk, read-only or forbidden folder); the error names
            ``path`` (see `names_path`).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if tmp_path is None:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=_TMP_SUFFIX)
    else:
        tmp = os.fspath(tmp_path)
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        mode = "wb" if binary else "w"
        with names_path(path), os.fdopen(fd, mode, **({} if binary else {"encoding": "utf-8"})) \
                as fh:
            write(fh)
            if durable:
                fh.flush()
                os.fsync(fh.fileno())
        os.chmod(tmp, _new_file_mode())  # mkstemp creates 0600: as open() would, by umask
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    if durable:
        fsync_dir(path.parent)
    return path


def atomic_write_bytes(path: str | os.PathLike, data: bytes, durable: bool = True, *,
                       tmp_path: str | os.PathLike | None = None) -> Path:
    """Write ``data`` to ``path`` atomically; parent folders are created.

    Args:
        path: destination file.
        data: the bytes.
        durable: ``fsync`` the file before the rename and its folder after it.
        tmp_path: where the temporary file goes (default: see `atomic_write_with`).

    Returns:
        The written path.
    """
    return atomic_write_with(path, lambda fh: fh.write(data), durable=durable, tmp_path=tmp_path)


def atomic_write_text(path: str | os.PathLike, text: str, durable: bool = True) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; see `atomic_write_bytes`."""
    return atomic_write_bytes(path, text.encode("utf-8"), durable)


def atomic_savez(path: str | os.PathLike, *, compressed: bool = True, **arrays) -> Path:
    """``numpy.savez_compressed`` (or ``savez``) to ``path`` atomically.

    Args:
        path: destination ``.npz``.
        compressed: ``savez_compressed`` (default) or plain ``savez`` (faster to read).
        **arrays: the arrays by name (object arrays are refused: they would need a pickle).

    Returns:
        The written path.
    """
    arrays = {k: np.asarray(v) for k, v in arrays.items()}
    for k, v in arrays.items():
        if v.dtype == object:
            raise ValueError(f"{path}: array {k!r} has dtype object (would need a pickle)")
    buf = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buf, **arrays)
    return atomic_write_bytes(path, buf.getvalue())


def json_safe(obj: Any, where: str = "value") -> Any:
    """Plain JSON values from numpy scalars/arrays, tuples and paths; non-finite floats -> ``None``.

    Args:
        obj: nested dicts / lists / tuples of numbers, strings, booleans, ``None``, numpy
            scalars or arrays, ``pathlib`` paths.
        where: a name for ``obj`` in error messages (nested keys are appended: ``stats['a']``).

    Returns:
        The same structure with only ``dict``, ``list``, ``str``, ``int``, ``float``, ``bool``
        and ``None``; dict keys become strings.

    Raises:
        ValueError: ``"<where>: value of type T cannot be stored in JSON"``.
    """
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist(), where)
    if isinstance(obj, (list, tuple)):
        return [json_safe(v, where) for v in obj]
    if isinstance(obj, Mapping):
        return {str(k): json_safe(v, f"{where}[{k!r}]") for k, v in obj.items()}
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise ValueError(f"{where}: value of type {type(obj).__name__} cannot be stored in JSON")


def write_json(path: str | os.PathLike, obj: Any, *, indent: int = 1, sort_keys: bool = True,
               durable: bool = True) -> Path:
    """`json_safe` ``obj`` and write it to ``path`` atomically (strict JSON: no NaN), with a
    final newline."""
    text = json.dumps(json_safe(obj, Path(path).name), indent=indent, sort_keys=sort_keys,
                      allow_nan=False)
    return atomic_write_text(path, text + "\n", durable)


def file_identity(path: str | os.PathLike) -> dict:
    """``{"name", "sha256", "bytes"}`` of a file: how a weight file's metadata names the file it
    started from, portably (no folder of the machine that made it)."""
    import hashlib

    path = Path(path)
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return {"name": path.name, "sha256": h.hexdigest(), "bytes": path.stat().st_size}


# ------------------------------------------------------------------ output folders

_MARKER = ".handmesh-{command}"
_RECORD_MAX_BYTES = 1 << 20


def out_marker(folder: str | os.PathLike, command: str) -> Path:
    """The small file that makes ``folder`` an output folder of ``command``:
    ``.handmesh-<command>``."""
    return Path(folder) / _MARKER.format(command=command)


def json_record(path: str | os.PathLike, *keys: str) -> bool:
    """Whether ``path`` is a JSON object (at most 1 MiB) holding every key of ``keys``: how an
    output folder of an older version, written before the marker files, is recognised."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read(_RECORD_MAX_BYTES + 1)
        obj = json.loads(raw) if len(raw) <= _RECORD_MAX_BYTES else None
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(obj, dict) and all(k in obj for k in keys)


def claim_out_dir(out: str | os.PathLike, command: str, outputs: tuple[str, ...] = (), *,
                  overwrite: bool = False, recognise: Callable[[Path], bool] | None = None,
                  hidden: tuple[str, ...] = ()) -> Path:
    """Make ``out`` an output folder of ``command``, or refuse it: the one rule every command
    with ``--out`` follows, checked before any work (docs page *Reliability*).

    A folder is the command's own when it holds the command's marker (`out_marker`, written
    here) or, for folders of older versions, when ``recognise(out)`` says so (the command's
    record, such as a run's ``config.json``). A missing or empty folder becomes the command's
    own. Any other folder holding files is refused, its files listed, unless ``overwrite``:
    the user then gives it to the command, whose outputs of the same names are replaced and
    whose other files are left. Nothing is written in a refused folder.

    A command never writes through a symbolic link inside ``out``: a link at the marker's
    name, at a name of ``outputs``, or directly inside an output that is a folder (a run's
    ``data/train``) is refused, ``overwrite`` or not (``out`` itself may be a link: the user
    named it).

    Args:
        out: the folder (``--out``); ``""`` is refused (it would mean the current folder).
        command: the command's name (``"train"``, ``"evaluate"``, ``"demo"``).
        outputs: the names of the files the command writes there (for the temporaries of a
            killed write, which do not make a folder foreign).
        overwrite: accept a folder holding files the command did not write.
        recognise: recognises an output folder of an older version (no marker yet).
        hidden: other names the command makes there (its lock file), which do not make a folder
            foreign either.

    Returns:
        The folder (created with its parents when missing).

    Raises:
        ValueError: ``out`` is empty.
        NotADirectoryError: ``out`` is a file.
        FileExistsError: ``out`` holds files the command did not write (the message lists up to
            eight and says what to do) and ``overwrite`` is false; or a symbolic link where the
            command writes (named, with its target).
        OSError: the folder or the marker cannot be written (the error names it).
    """
    raw = os.fspath(out)
    if not str(raw).strip():
        raise ValueError(f"the output folder of {command} is empty ({raw!r}): name a folder, "
                         f"e.g. --out runs/{command} (use --out . for the current folder)")
    folder = Path(raw)
    marker = out_marker(folder, command)
    if folder.exists() and not folder.is_dir():
        raise NotADirectoryError(f"{folder} is a file, not a folder: choose another --out")
    if folder.is_dir():
        _refuse_links(folder, command, (marker.name, *outputs))
    own = folder.is_dir() and (marker.is_file() or (recognise is not None and recognise(folder)))
    if folder.is_dir() and not own:
        ours = {marker.name, *hidden}
        pats = [f".{name}.*{_TMP_SUFFIX}" for name in outputs]
        foreign = sorted(e.name for e in os.scandir(folder) if e.name not in ours
                         and not any(fnmatch.fnmatchcase(e.name, p) for p in pats))
        if foreign and not overwrite:
            shown = ", ".join(foreign[:8]) + (f" and {len(foreign) - 8} more"
                                              if len(foreign) > 8 else "")
            raise FileExistsError(
                f"{folder} holds files that {command} did not write ({shown}): choose another "
                f"--out (a new or empty folder), move them away, or pass --overwrite to write "
                f"there anyway ({command}'s files of the same names are then replaced, the "
                "others left)")
    with names_path(folder):
        folder.mkdir(parents=True, exist_ok=True)
        if not marker.is_file():
            atomic_write_text(marker, json.dumps({"command": command, "written_by":
                                                  "handmesh_tutorial"}) + "\n", durable=False)
    return folder


def claim_state(out: str | os.PathLike | None) -> dict | None:
    """What an ``--out`` folder holds before a command runs, for `release_claim`:
    ``{"folder", "missing" (the folders of the path that do not exist yet, deepest first),
    "names" (its entries)}``; ``None`` without a folder."""
    if out is None or not str(out).strip():
        return None
    folder = Path(out)
    missing, p = [], folder
    try:
        while not os.path.lexists(p) and p != p.parent:
            missing.append(p)
            p = p.parent
        names = set(os.listdir(folder)) if folder.is_dir() and not folder.is_symlink() else set()
    except OSError:  # a name too long, a folder we may not read: nothing to release later
        return None
    return {"folder": folder, "missing": missing, "names": names}


def release_claim(state: dict | None) -> list[Path]:
    """Undo what claiming an output folder left when the command then stopped before writing
    any output (a refused option, an unreadable checkpoint): the command's marker and lock
    files it created (hidden, empty or a marker's few bytes) and the folders it created, when
    nothing else is in them. A folder holding any output, or any file of the user's, is left
    as it is (a run that wrote something resumes from it).

    Returns:
        The paths removed.
    """
    if state is None:
        return []
    folder, gone = state["folder"], []
    try:
        if not folder.is_dir() or folder.is_symlink():
            return []
        new = [folder / n for n in sorted(set(os.listdir(folder)) - state["names"])]
        ours = [p for p in new if p.name.startswith(".handmesh-")
                or (p.name.startswith(".") and p.name.endswith(".lock"))]
        if len(ours) != len(new) or any(p.is_symlink() or not p.is_file()
                                        or p.stat().st_size > 4096 for p in ours):
            return []  # the command wrote more than its bookkeeping: its folder now
        for p in ours:
            p.unlink()
            gone.append(p)
        for d in state["missing"]:  # deepest first; only those this command made, if empty
            if d.is_dir() and not d.is_symlink() and not any(d.iterdir()):
                d.rmdir()
                gone.append(d)
    except OSError:
        pass
    return gone


def _refuse_links(folder: Path, command: str, names: tuple[str, ...]) -> None:
    """Raise ``FileExistsError`` naming the first symbolic link at ``folder/name`` or directly
    inside such a name that is a real folder (links not followed)."""
    for name in names:
        path = folder / name
        inside = (sorted(path.iterdir()) if path.is_dir() and not path.is_symlink() else [])
        for p in (path, *inside):
            if p.is_symlink():
                raise FileExistsError(
                    f"{p} is a symbolic link (to {os.readlink(p)}): {command} never writes "
                    f"through a link nor over one; remove it, or choose another --out")


def remove_outputs(folder: str | os.PathLike, names: tuple[str, ...]) -> list[Path]:
    """Delete a command's previous outputs ``names`` from its own ``folder`` (in that order;
    links are removed, never followed), so that no file of an earlier run is left beside a new
    run's. Other files are left.

    Returns:
        The removed paths.

    Raises:
        OSError: one cannot be removed (a folder of that name, no permission); it is named.
    """
    gone = []
    for name in names:
        path = Path(folder) / name
        if os.path.lexists(path):
            path.unlink()
            gone.append(path)
    return gone
