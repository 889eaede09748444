"""Bounded reads of untrusted ``.npz`` and checkpoint files: declared sizes are checked first.

A few hundred bytes can declare gigabytes: an ``.npy`` header inside an ``.npz`` names a shape
that numpy allocates before it reads the data, a zip member can be a deflate stream that
expands a thousand times, and a checkpoint's storage can be such a member. `open_npz` reads every
member's header from the zip directory and refuses object dtypes, a shape whose bytes differ from
what the member holds, and more than ``max_bytes`` in all, then opens the file with
``allow_pickle=False``. `load_torch_file` refuses an archive whose members expand past the
file's own size (``torch.save`` stores them uncompressed), a member that fails its CRC-32
(torch's reader checks none, so a flipped bit would load) or a file over
`MAX_CHECKPOINT_BYTES`, loads with ``weights_only=True``, and refuses a tensor that claims more
elements than its storage holds (a zero-stride view that any copy would blow up). Every refusal
is a `ValueError` naming the file (docs page *Reliability*, "Files are never trusted").
"""

from __future__ import annotations

import contextlib
import math
import os
import pickle
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np

__all__ = ["MAX_NPZ_BYTES", "MAX_CHECKPOINT_BYTES", "check_npz", "open_npz", "read_npz",
           "check_checkpoint", "load_torch_file"]

MAX_NPZ_BYTES = 256 * 2**20
"""Most bytes the arrays of one ``.npz`` may declare, all members together (the largest the
library writes, the MakeHuman template, holds about 1 MB)."""
MAX_CHECKPOINT_BYTES = 4 * 2**30
"""Largest checkpoint file read, bytes (a paper-scale ResNet-50 run with its Adam state is
under 1 GB)."""


def check_npz(fh, name: str | os.PathLike, max_bytes: int = MAX_NPZ_BYTES) -> dict:
    """Check an open ``.npz`` from its zip directory and ``.npy`` headers, reading no array.

    Args:
        fh: the file, opened binary (its position is left anywhere).
        name: the path, for messages.
        max_bytes: most bytes all members together may declare.

    Returns:
        ``{member name: (shape, dtype)}`` for the ``.npy`` members.

    Raises:
        ValueError: not a zip; a member with an object dtype, a header that declares a size the
            member does not hold, or more than ``max_bytes`` in all (the message names the file
            and the member).
    """
    try:
        zf = zipfile.ZipFile(fh)
    except (zipfile.BadZipFile, OSError, EOFError) as e:
        raise ValueError(f"{name}: not a readable npz ({type(e).__name__}: {e})") from None
    out, total = {}, 0
    with zf:
        for info in zf.infolist():
            total += info.file_size
            if total > max_bytes:
                raise ValueError(f"{name}: its members hold more than {max_bytes:,} bytes "
                                 f"(member '{info.filename}': {info.file_size:,}); refused "
                                 "before reading")
            if not info.filename.endswith(".npy"):
                continue
            try:
                with zf.open(info) as f:
                    version = np.lib.format.read_magic(f)
                    read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                            else np.lib.format.read_array_header_2_0)
                    shape, _fortran, dtype = read(f)
                    header = f.tell()
            except (ValueError, OSError, EOFError, zipfile.BadZipFile, NotImplementedError,
                    zlib.error) as e:  # a damaged header, compression method or stream
                raise ValueError(f"{name}: member '{info.filename}' has no readable .npy header "
                                 f"({type(e).__name__}: {e})") from None
            if dtype.hasobject:
                raise ValueError(f"{name}: member '{info.filename}' has dtype {dtype} (Python "
                                 "objects); refused")
            declared = math.prod(shape) * dtype.itemsize
            if header + declared != info.file_size:
                raise ValueError(f"{name}: member '{info.filename}' declares shape {shape} of "
                                 f"{dtype} ({declared:,} bytes) but holds "
                                 f"{info.file_size - header:,} bytes; refused before reading")
            out[info.filename[:-4]] = (shape, dtype)
    return out


@contextlib.contextmanager
def open_npz(path: str | os.PathLike, max_bytes: int = MAX_NPZ_BYTES) -> Iterator:
    """``numpy.load(path, allow_pickle=False)`` after `check_npz` on the same open file.

    Args:
        path: the ``.npz``.
        max_bytes: most bytes all its arrays together may declare.

    Yields:
        The ``numpy.lib.npyio.NpzFile`` (closed on exit).

    Raises:
        FileNotFoundError: no such file.
        ValueError: see ``check_npz``.
    """
    with open(path, "rb") as fh:
        check_npz(fh, path, max_bytes)
        fh.seek(0)
        with np.load(fh, allow_pickle=False) as z:
            yield z


def read_npz(path: str | os.PathLike, keys=None, max_bytes: int = MAX_NPZ_BYTES) -> dict:
    """The arrays of an untrusted ``.npz`` through `open_npz`, every failure a ValueError.

    Args:
        path: the ``.npz``.
        keys: names to read (those the file has); ``None``: all.
        max_bytes: most bytes all its arrays together may declare.

    Returns:
        ``{name: array}``.

    Raises:
        FileNotFoundError: no such file.
        ValueError: refused by `check_npz`, or unreadable (a damaged zip, a short member...):
            the message names the file.
    """
    try:
        with open_npz(path, max_bytes) as z:
            return {k: z[k] for k in (z.files if keys is None else keys) if k in z.files}
    except FileNotFoundError:
        raise
    except Exception as e:  # BadZipFile, OSError, numpy's ValueError...
        if isinstance(e, ValueError) and str(e).startswith(f"{path}:"):
            raise  # check_npz's refusal names the file already
        raise ValueError(f"{path}: not a readable npz ({type(e).__name__}: {e})") from e


def check_checkpoint(path: str | os.PathLike, max_bytes: int = MAX_CHECKPOINT_BYTES) -> None:
    """Check a ``torch.save`` file's size and zip directory before ``torch.load`` reads it.

    Args:
        path: the file.
        max_bytes: largest file accepted.

    Raises:
        FileNotFoundError: no such file.
        ValueError: larger than ``max_bytes``; not a zip archive (truncated, foreign, or the
            pre-1.6 format, whose loader allocates the sizes it declares); members that expand
            past the file's size (a compressed archive, which ``torch.save`` never writes); or
            a member whose CRC-32 does not match its bytes (every member is read once).
    """
    path = Path(path)
    size = path.stat().st_size
    if size > max_bytes:
        raise ValueError(f"{path}: {size:,} bytes, more than the {max_bytes:,} a checkpoint may "
                         "have; refused")
    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
            expanded = sum(i.file_size for i in infos)
            if expanded > size:
                big = max(infos, key=lambda i: i.file_size - i.compress_size)
                raise ValueError(
                    f"{path}: its members expand to {expanded:,} bytes from a {size:,}-byte file "
                    f"(member '{big.filename}': {big.compress_size:,} -> {big.file_size:,}); "
                    "torch.save stores them uncompressed, so this file was crafted or altered; "
                    "refused before reading")
            damaged = zf.testzip()  # torch's reader checks no CRC: a flipped bit loads
    except (zipfile.BadZipFile, OSError, EOFError, NotImplementedError, zlib.error) as e:
        raise ValueError(f"{path}: unreadable checkpoint (truncated, or not a zip archive as "
                         f"torch.save writes: {type(e).__name__}: {e})") from None
    if damaged is not None:
        raise ValueError(f"{path}: member '{damaged}' fails its CRC-32 check: the file is "
                         "damaged (a flipped bit, a bad copy); refused")


def load_torch_file(path: str | os.PathLike, map_location="cpu",
                    max_bytes: int = MAX_CHECKPOINT_BYTES):
    """``torch.load(path, weights_only=True)`` with the checks of `check_checkpoint` before and
    a check of every tensor's extent after.

    Args:
        path: a file written by ``torch.save``.
        map_location: as for ``torch.load``.
        max_bytes: largest file accepted.

    Returns:
        What the file holds (tensors and plain containers).

    Raises:
        ValueError: see ``check_checkpoint``; or a tensor with more elements than its storage
            (the message names the file and the tensor's place).
            Objects other than tensors and plain containers are a ``ValueError`` too, naming
            the file (never torch's advice to load with ``weights_only=False``).
        RuntimeError: as ``torch.load`` (damaged data).
    """
    import torch

    check_checkpoint(path, max_bytes)
    try:
        obj = torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as err:
        # torch's text advises weights_only=False, i.e. running the file's code: say otherwise
        what = [ln.strip().split(". Please")[0][:120] for ln in str(err).splitlines()
                if "Unsupported" in ln]
        raise ValueError(
            f"{path}: refused: the file holds objects other than tensors and plain containers"
            + (f" ({what[0]})" if what else "") + ". It was not written by handmesh_tutorial "
            "or was altered; never load it with weights_only=False, which runs any code it "
            "carries.") from None
    stack, seen = [(obj, "")], set()
    while stack:
        item, where = stack.pop()
        if id(item) in seen:  # shared or cyclic containers: each once
            continue
        seen.add(id(item))
        if isinstance(item, torch.Tensor):
            held = item.untyped_storage().nbytes() // max(item.element_size(), 1)
            if item.numel() > held:
                raise ValueError(f"{path}: tensor {where or '(top level)'} of shape "
                                 f"{tuple(item.shape)} claims {item.numel():,} elements over a "
                                 f"storage of {held:,} (a repeated view); refused")
        elif isinstance(item, dict):
            stack.extend((v, f"{where}[{k!r}]") for k, v in item.items())
        elif isinstance(item, list | tuple):
            stack.extend((v, f"{where}[{i}]") for i, v in enumerate(item))
    return obj
