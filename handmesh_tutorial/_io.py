"""Atomic file writes (temp file in the same folder + rename): a crash never leaves half a file."""

from __future__ import annotations

import glob
import io
import os
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["atomic_write_bytes", "atomic_savez", "leftover_temporaries"]


_TMP_SUFFIX = ".tmp"


def leftover_temporaries(path: str | os.PathLike) -> list[Path]:
    """The temp files `atomic_write_bytes` of ``path`` leaves when killed mid-write
    (``.<name>.<random>.tmp`` beside ``path``)."""
    path = Path(path)
    pattern = f".{glob.escape(path.name)}.*{_TMP_SUFFIX}"
    return sorted(p for p in path.parent.glob(pattern) if p.is_file())


def atomic_write_bytes(path: str | os.PathLike, data: bytes, durable: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically; parent folders are created.

    Args:
        path: destination file.
        data: the bytes.
        durable: ``fsync`` the file before the rename (a crash then leaves the old or the new
            file, never a truncated one, even on a power cut).

    Returns:
        The written path.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=_TMP_SUFFIX)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            if durable:
                fh.flush()
                os.fsync(fh.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def atomic_savez(path: str | os.PathLike, **arrays) -> Path:
    """``numpy.savez_compressed`` to ``path`` atomically (no pickled objects allowed).

    Args:
        path: destination ``.npz``.
        **arrays: the arrays by name.

    Returns:
        The written path.
    """
    buf = io.BytesIO()
    np.savez_compressed(buf, **{k: np.asarray(v) for k, v in arrays.items()})
    return atomic_write_bytes(path, buf.getvalue())
