"""The files of one sample folder: encode, write atomically, read back and validate.

A sample folder holds ``image.png``, ``scene_mask.png``, ``alone_<l>.png`` (and optionally
``alone_rgb_<l>.png``), ``annotation.npz`` and ``annotation.json``. Every file is deterministic
(same sample -> same bytes: no time stamps in PNG, JSON or zip headers), and every folder appears
atomically (written in a temporary sibling ``.tmp-<name>-<pid>-<8 hex>``, then renamed). Taught in
notebook 05 ("Rendering and the visibility ratio").

Why one file: writing and reading a sample folder must agree on every name, and the one rule of
what a reader may open (no link, only the sample's own regular files) sits beside both.
"""

from __future__ import annotations

import functools
import io
import json
import os
import re
import shutil
import stat
import uuid
import zipfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._io import atomic_write_bytes, fsync_dir, json_safe, names_path
from .._untrusted import read_npz
from .schema import (
    _KNOWN_KEYS,
    _TMP_PREFIX,
    FORMAT_VERSION,
    MAX_IMAGE_SIZE,
    READABLE_FORMAT_VERSIONS,
    _canonical,
    _check_camera,
    _check_points,
    _label,
)

__all__ = ["encode_sample", "write_sample", "read_annotation", "read_sample", "read_target",
           "ANNOTATION_MAX_BYTES"]

ANNOTATION_MAX_BYTES = 64 * 2**20
"""Most bytes the arrays of one sample's ``annotation.npz`` may declare (a hand-chain scene holds
well under 1 MB): a small file that declares more is refused before it is read."""

_ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # fixed zip entry date: np.savez would store the wall clock
_PNG_LEVEL = 6
_JSON_KW = {"indent": 1, "sort_keys": True, "ensure_ascii": False, "allow_nan": False}


# --------------------------------------------------------------------------------------------
# encoding and writing
# --------------------------------------------------------------------------------------------
def _png(array: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    # No pnginfo: Pillow then writes IHDR/IDAT/IEND only (no time chunk), so bytes are stable.
    Image.fromarray(array).save(buf, format="PNG", compress_level=_PNG_LEVEL)
    return buf.getvalue()


def npz_bytes(arrays: Mapping[str, np.ndarray]) -> bytes:
    """A deterministic ``.npz`` (zip of ``.npy``) that ``numpy.load`` reads.

    Every byte is pinned explicitly: entries sorted by name, dated 1980-01-01, fixed permission
    bits, deflated at level 1. (``numpy.savez`` is deterministic today only because CPython's
    ``ZipFile.open(name, "w")`` happens to default to that date; ``ZipFile.writestr(name)`` would
    stamp the wall clock. We do not rely on either detail.)

    Args:
        arrays: name -> array (numeric or bool; no object arrays).

    Returns:
        The file's bytes.
    """
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(arrays):
            npy = io.BytesIO()
            np.lib.format.write_array(npy, np.ascontiguousarray(arrays[name]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, npy.getvalue(), compresslevel=1)  # 3x faster than 6, +3% size
    return buf.getvalue()


def _json_bytes(obj: Any) -> bytes:
    return (json.dumps(obj, **_JSON_KW) + "\n").encode("utf-8")


def encode_sample(sample: Mapping) -> dict[str, bytes]:
    """Validate a sample and encode it as the files of its folder (name -> bytes).

    Args:
        sample: a sample dict (see
            [`InterSHDataset`][handmesh_tutorial.data.reader.InterSHDataset]); ``index``,
            ``seed``, ``attempt``, ``names``, ``pose``, ``alone_images``, ``stats`` are optional.
            Extra keys are kept: numpy arrays go to ``annotation.npz`` as ``extra_<key>``, other
            values (JSON-able) to ``annotation.json`` under ``extra``.

    Returns:
        ``{"image.png": ..., "scene_mask.png": ..., "alone_<l>.png": ..., "annotation.npz": ...,
        "annotation.json": ...}``.

    Raises:
        ValueError: a key is missing or has the wrong shape, dtype or value (the message names it).
    """
    return _encode(_canonical(sample, lambda f: f"sample[{f!r}]"))


def _encode(s: dict) -> dict[str, bytes]:
    mask = s["scene_mask"]
    bits = 8 if mask.max(initial=0) <= 255 else 16
    files = {"image.png": _png(s["image"]),
             "scene_mask.png": _png(mask.astype(np.uint8 if bits == 8 else np.uint16))}
    for lab, m in s["alone_masks"].items():
        files[f"alone_{lab}.png"] = _png(m)
    for lab, m in s["alone_images"].items():
        files[f"alone_rgb_{lab}.png"] = _png(m)
    arrays = {"K": s["K"]}
    for lab, (v, f) in s["meshes"].items():
        arrays[f"vertices_{lab}"], arrays[f"faces_{lab}"] = v, f
    arrays.update({f"joints_{lab}": j for lab, j in s["joints"].items()})
    arrays.update({f"pose_{lab}": p for lab, p in s["pose"].items()})
    extra_json = {}
    for key in sorted(set(s) - _KNOWN_KEYS):
        if isinstance(s[key], np.ndarray):
            arrays[f"extra_{key}"] = s[key]
        else:
            extra_json[key] = s[key]
    files["annotation.npz"] = npz_bytes(arrays)
    target = s["target"]
    ann = {
        "format_version": FORMAT_VERSION, "index": s["index"], "seed": s["seed"],
        "attempt": s["attempt"], "kind": s["kind"], "image_size": list(s["image"].shape[:2]),
        "labels": list(s["meshes"]), "hands": list(s["sides"]), "target": target,
        "target_vr": s["vr"][target], "names": s["names"], "sides": s["sides"], "vr": s["vr"],
        "pose_labels": list(s["pose"]), "alone_image_labels": list(s["alone_images"]),
        "scene_mask_bits": bits, "stats": s["stats"], "extra": extra_json,
        "extra_arrays": sorted(k for k in s if k not in _KNOWN_KEYS
                               and isinstance(s[k], np.ndarray)),
    }
    files["annotation.json"] = _json_bytes(json_safe(ann, "annotation"))
    return files


def _write_file(path: Path, data: bytes, durable: bool) -> None:
    with open(path, "wb") as fh:
        fh.write(data)
        if durable:
            fh.flush()
            os.fsync(fh.fileno())


def _temporary(path: Path) -> Path:
    """Where a writer puts ``path`` before renaming it: ``.tmp-<name>-<pid>-<8 hex>`` beside it
    (the form `_is_own_temporary` recognises)."""
    return path.with_name(f"{_TMP_PREFIX}{path.name}-{os.getpid()}-{uuid.uuid4().hex[:8]}")


def _write_atomic(path: Path, data: bytes, durable: bool = True) -> None:
    """Write a file atomically with a temporary name `_is_own_temporary` recognises."""
    atomic_write_bytes(path, data, durable, tmp_path=_temporary(path))


def _write_folder(directory: Path, files: Mapping[str, bytes], durable: bool) -> None:
    """Write files into a hidden sibling folder, then rename it to ``directory`` in one step."""
    parent = directory.parent
    tmp = _temporary(directory)
    tmp.mkdir()
    try:
        with names_path(directory):  # a full disk's error names no file otherwise
            for name, data in files.items():
                _write_file(tmp / name, data, durable)
        if durable:
            fsync_dir(tmp)
        try:
            os.replace(tmp, directory)  # atomic: readers see no folder or a complete one
        except OSError:
            if not directory.is_dir():
                raise
            # another writer (e.g. an orphaned worker of a killed run) finished this sample
            # first; samples are deterministic per index, so its folder is the same: keep it
            shutil.rmtree(tmp, ignore_errors=True)
            return
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if durable:
        fsync_dir(parent)


def write_sample(directory: str | os.PathLike, sample: Mapping, *, overwrite: bool = False,
                 durable: bool = True) -> Path:
    """Write one sample folder atomically (temporary sibling folder + rename).

    Args:
        directory: the sample folder to create, e.g. ``root/samples/000123``.
        sample: the sample dict (see
            [`encode_sample`][handmesh_tutorial.data.files.encode_sample] and
            [`InterSHDataset`][handmesh_tutorial.data.reader.InterSHDataset]).
        overwrite: replace an existing folder (the swap is then not atomic).
        durable: fsync files and folders, so a power cut cannot leave a renamed but empty file.

    Returns:
        The folder's path.

    Raises:
        FileExistsError: the folder exists and ``overwrite`` is False.
        ValueError: the sample is invalid (the message names the key).
    """
    directory = Path(directory)
    files = encode_sample(sample)
    directory.parent.mkdir(parents=True, exist_ok=True)
    if directory.exists():
        if not overwrite:
            raise FileExistsError(f"{directory} exists (pass overwrite=True to replace it)")
        shutil.rmtree(directory)
    _write_folder(directory, files, durable)
    return directory


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------
def _named_errors(read):
    """Make a reader of one (untrusted) sample folder raise only ``OSError`` or ``ValueError``:
    anything else parsing it raises (``TypeError``, ``IndexError``...) becomes a ``ValueError``
    naming the folder, a bad sample for `verify_dataset` and ``--skip-bad``."""

    @functools.wraps(read)
    def wrapper(directory: str | os.PathLike, *args: Any, **kwargs: Any) -> Any:
        try:
            return read(directory, *args, **kwargs)
        except (OSError, ValueError, MemoryError):
            raise
        except Exception as e:  # noqa: BLE001 - any other error of a damaged file
            raise ValueError(f"{directory}: not a readable sample folder ({type(e).__name__}: "
                             f"{e})") from e

    return wrapper


def _own_file(path: Path) -> Path:
    """The reader rule for a file of a root (``meta.json``, a sample's files), links not
    followed: every reader of a root (train, evaluate, verify, merge, the lean read,
    pretraining's ``--scenes-from``) reads only regular files that are the root's own, so a
    link to a file elsewhere is never read nor copied (`_own_folder` is the rule for a sample
    folder).

    Returns:
        ``path``.

    Raises:
        FileNotFoundError: nothing at ``path``.
        ValueError: a symbolic link (its target named) or not a regular file there.
    """
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path} missing") from None
    if stat.S_ISLNK(st.st_mode):
        raise ValueError(f"{path} is a symbolic link (to {os.readlink(path)}): a root's files "
                         "are read only from the root itself, never through a link")
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"{path} is not a regular file")
    return path


def _own_folder(path: Path) -> bool:
    """The reader rule for a sample folder: a real folder, not a symbolic link (a link to a
    folder elsewhere is no sample of the root: never read, copied or counted as present)."""
    return path.is_dir() and not path.is_symlink()


def _read_json(path: Path) -> Any:
    _own_file(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not valid JSON ({e})") from e
    except RecursionError as e:  # '[[[[...' deeper than the interpreter's stack
        raise ValueError(f"{path}: not valid JSON (nested too deeply: {e})") from e


def _read_png(path: Path, modes: Sequence[str], size: Sequence[int] | None = None) -> np.ndarray:
    """Decode a PNG of mode in ``modes``; with ``size`` = (H, W), check the header's size first,
    so that no other size is decoded (a decompression bomb costs nothing)."""
    import warnings

    from PIL import Image

    _own_file(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                if size is not None and (im.height, im.width) != tuple(size):
                    got, want = (im.height, im.width), tuple(int(x) for x in size)
                    raise _SizeError(f"{path} has shape {got}, expected {want} (the image size "
                                     "annotation.json declares; not decoded)")
                im.load()
                mode, arr = im.mode, np.array(im)
    except _SizeError:
        raise
    except Exception as e:  # PIL raises OSError, SyntaxError, zlib.error, DecompressionBomb...
        raise ValueError(f"{path}: not a readable PNG ({type(e).__name__}: {e})") from e
    if mode not in modes:
        raise ValueError(f"{path}: PNG mode {mode}, expected one of {list(modes)}")
    return arr


class _SizeError(ValueError):
    """A PNG whose header declares another size than the sample's (raised before decoding)."""


@_named_errors
def read_annotation(directory: str | os.PathLike) -> dict:
    """Read only ``annotation.json`` of a sample folder (fast: no images, no arrays).

    Returns:
        The annotation with integer labels: ``index``, ``seed``, ``attempt``, ``kind``,
        ``image_size`` [H, W], ``labels``, ``hands``, ``target``, ``target_vr``, ``names``,
        ``sides``, ``vr``, ``stats``, ...

    Raises:
        FileNotFoundError: the file is missing. ValueError: it is corrupt (the path is named).
    """
    path = Path(directory) / "annotation.json"
    ann = _read_json(path)
    if not isinstance(ann, dict):
        raise ValueError(f"{path}: expected a JSON object")
    required = ("format_version", "kind", "image_size", "labels", "hands", "target", "names",
                "sides", "vr")
    missing = [k for k in required if k not in ann]
    if missing:
        raise ValueError(f"{path}: missing keys {missing}")
    if ann["format_version"] not in READABLE_FORMAT_VERSIONS:
        raise ValueError(f"{path}: format_version {ann['format_version']}, this library reads "
                         f"{list(READABLE_FORMAT_VERSIONS)}")
    where = str(path)
    for key in ("names", "sides", "vr"):
        if not isinstance(ann[key], dict):
            raise ValueError(f"{path}: '{key}' must be an object")
        ann[key] = {_label(k, f"{where}: '{key}'"): v for k, v in ann[key].items()}
    for key in ("labels", "hands", "pose_labels", "alone_image_labels"):
        if not isinstance(ann.get(key, []), list):  # "12" would read as labels 1 and 2
            raise ValueError(f"{path}: '{key}' must be a list of labels, got "
                             f"{ann[key]!r}")
        ann[key] = [_label(k, f"{where}: '{key}'") for k in ann.get(key, [])]
    for lab, v in ann["vr"].items():
        if isinstance(v, bool) or not isinstance(v, int | float) or not 0.0 <= v <= 1.0:
            raise ValueError(f"{path}: 'vr' of label {lab} must be a number in [0, 1], got "
                             f"{v!r}")
    size = ann["image_size"]
    if not (isinstance(size, list) and len(size) == 2 and all(
            type(x) is int and 1 <= x <= MAX_IMAGE_SIZE for x in size)):
        raise ValueError(f"{path}: 'image_size' must be [height, width], integers in [1, "
                         f"{MAX_IMAGE_SIZE}] (MAX_IMAGE_SIZE), got {str(size)[:80]}")
    for key, kind in (("stats", dict), ("extra", dict), ("extra_arrays", list)):
        if ann.get(key) is not None and not isinstance(ann[key], kind):
            what = "object" if kind is dict else "list"
            raise ValueError(f"{path}: '{key}' must be a JSON {what}, got "
                             f"{type(ann[key]).__name__}")
    if not all(isinstance(k, str) and re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", k)
               for k in ann.get("extra_arrays") or []):
        raise ValueError(f"{path}: 'extra_arrays' must list identifiers, got "
                         f"{str(ann['extra_arrays'])[:80]}")
    extra_keys = [*(ann.get("extra") or {}), *(ann.get("extra_arrays") or [])]
    shadow = sorted({k for k in extra_keys if k in _KNOWN_KEYS or k == "alone_images"}
                    | {k for k in extra_keys if extra_keys.count(k) > 1})
    bad_name = [k for k in ann.get("extra") or {}
                if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", k)]
    if shadow or bad_name:  # an extra entry never replaces a validated field
        raise ValueError(f"{path}: 'extra' entries {str(shadow or bad_name)[:80]} "
                         + ("would replace sample fields (or each other)" if shadow
                            else "are not identifiers") + ": a damaged or foreign file")
    for key in ("index", "seed", "attempt"):
        v = ann.get(key)
        if v is not None and (type(v) is not int or v < 0):
            raise ValueError(f"{path}: '{key}' must be a non-negative integer or null, got "
                             f"{str(v)[:40]}")
    if ann.get("scene_mask_bits", 8) not in (8, 16):
        raise ValueError(f"{path}: 'scene_mask_bits' must be 8 or 16, got "
                         f"{str(ann['scene_mask_bits'])[:20]}")
    ann["target"] = _label(ann["target"], f"{where}: 'target'")
    if ann["target"] not in ann["hands"] or ann["target"] not in ann["vr"]:
        raise ValueError(f"{path}: 'target' {ann['target']} is not a hand label with a VR "
                         f"(hands {ann['hands']}, vr labels {sorted(ann['vr'])})")
    return ann


def _read_npz(npz_path: Path, keys=None) -> dict:
    """An ``annotation.npz``'s arrays, declared sizes checked first (`ANNOTATION_MAX_BYTES`)."""
    return read_npz(_own_file(npz_path), keys, ANNOTATION_MAX_BYTES)


@_named_errors
def read_sample(directory: str | os.PathLike) -> dict:
    """Read and validate one sample folder.

    Args:
        directory: a folder written by
            [`write_sample`][handmesh_tutorial.data.files.write_sample].

    Returns:
        The sample dict (see [`InterSHDataset`][handmesh_tutorial.data.reader.InterSHDataset]),
        numpy arrays with the documented dtypes.

    Raises:
        FileNotFoundError: a file is missing (the message names it).
        ValueError: a file is corrupt or inconsistent (the message names the file and key).
    """
    d = Path(directory)
    ann = read_annotation(d)
    npz_path = d / "annotation.npz"
    arrays = _read_npz(npz_path)
    labels, hands = ann["labels"], ann["hands"]
    need = ["K", *(f"{p}_{lab}" for lab in labels for p in ("vertices", "faces")),
            *(f"joints_{lab}" for lab in hands), *(f"pose_{lab}" for lab in ann["pose_labels"]),
            *(f"extra_{k}" for k in ann.get("extra_arrays", []))]
    for key in need:
        if key not in arrays:
            raise ValueError(f"{npz_path}: missing key '{key}' (annotation.json lists it)")

    mask_modes = ("L",) if ann.get("scene_mask_bits", 8) == 8 else ("I;16", "I")
    hw = ann["image_size"]
    sample: dict[str, Any] = {
        "image": _read_png(d / "image.png", ("RGB",), hw),
        "scene_mask": _read_png(d / "scene_mask.png", mask_modes, hw),
        "alone_masks": {lab: _read_png(d / f"alone_{lab}.png", ("1", "L"), hw) != 0
                        for lab in labels},
        "alone_images": {lab: _read_png(d / f"alone_rgb_{lab}.png", ("RGB",), hw)
                         for lab in ann["alone_image_labels"]},
        "meshes": {lab: (arrays[f"vertices_{lab}"], arrays[f"faces_{lab}"]) for lab in labels},
        "joints": {lab: arrays[f"joints_{lab}"] for lab in hands},
        "pose": {lab: arrays[f"pose_{lab}"] for lab in ann["pose_labels"]},
        "K": arrays["K"],
        **{k: ann.get(k) for k in ("vr", "kind", "target", "sides", "names", "stats", "index",
                                   "seed", "attempt")},
    }
    if sorted(sample["sides"]) != sorted(hands):
        raise ValueError(f"{d / 'annotation.json'}: 'sides' labels {sorted(sample['sides'])} "
                         f"differ from 'hands' {hands}")
    files = {"image": "image.png", "scene_mask": "scene_mask.png"}

    def loc(f: str) -> str:
        if f in files:
            return str(d / files[f])
        if f.startswith("alone_") and f not in ("alone_masks", "alone_images"):
            return str(d / f"{f}.png")
        if f == "K" or f.split("_")[0] in ("vertices", "faces", "joints", "pose"):
            return f"{npz_path}: key '{f}'"
        return f"{d / 'annotation.json'}: '{f}'"

    s = _canonical(sample, loc)
    if list(s["image"].shape[:2]) != list(ann["image_size"]):
        raise ValueError(f"{d / 'image.png'}: size {s['image'].shape[:2]}, annotation.json "
                         f"says {ann['image_size']}")
    if not s["alone_images"]:  # returned only when stored
        del s["alone_images"]
    for k, v in (ann.get("extra") or {}).items():  # never a field: read_annotation checks
        s[k] = v
    for k in ann.get("extra_arrays", []):
        s[k] = arrays[f"extra_{k}"]
    return s


@_named_errors
def read_target(directory: str | os.PathLike) -> tuple:
    """Read only what a training crop of the target hand needs (a lean
    [`read_sample`][handmesh_tutorial.data.files.read_sample]).

    Skips the masks and the other bodies' arrays, which training never reads, so a data
    loader's item costs less (docs page "Performance", ``benchmarks/data.py``).

    Returns:
        ``(image, K, vertices, joints, side, vr)``: ``(H, W, 3)`` uint8, ``(3, 3)`` float64
        pixels, ``(V, 3)`` and ``(21, 3)`` float32 metres in the camera frame, ``"left"`` or
        ``"right"``, the target's VR (float). The same values as ``read_sample``'s entries of
        the target label.

    Raises:
        FileNotFoundError: a file is missing. ValueError: a file is corrupt or inconsistent (the
            message names the file and key).
    """
    return _read_target(directory)[0]


@_named_errors
def _read_target(directory: str | os.PathLike) -> tuple[tuple, dict]:
    """`read_target`'s tuple and the annotation it read (for the checks against ``meta.json``
    that `InterSHDataset.target` shares with the full read)."""
    d = Path(directory)
    ann = read_annotation(d)
    t = ann["target"]
    npz_path = d / "annotation.npz"
    keys = ("K", f"vertices_{t}", f"joints_{t}")
    found = _read_npz(npz_path, keys)
    missing = [k for k in keys if k not in found]
    if missing:
        raise ValueError(f"{npz_path}: missing key '{missing[0]}' (annotation.json names target "
                         f"{t})")
    K, verts, joints = (found[k] for k in keys)
    for key, arr, shape in (("K", K, (3, 3)), (keys[1], verts, None), (keys[2], joints, (21, 3))):
        ok = arr.shape == shape if shape else (arr.ndim == 2 and arr.shape[1] == 3)
        if not ok or arr.dtype.kind not in "fiu" or not np.all(np.isfinite(arr)):
            raise ValueError(f"{npz_path}: key '{key}' has shape {arr.shape}, dtype {arr.dtype} "
                             f"or non-finite values (expected {shape or '(V, 3)'}, numbers)")
    _check_camera(K.astype(np.float64), ann["image_size"], f"{npz_path}: key 'K'")
    _check_points(verts, f"{npz_path}: key '{keys[1]}'", hand=True)
    _check_points(joints, f"{npz_path}: key '{keys[2]}'", hand=True)
    image = _read_png(d / "image.png", ("RGB",), ann["image_size"])
    side = ann["sides"].get(t)
    if side not in ("left", "right"):
        raise ValueError(f"{d / 'annotation.json'}: side of target {t} is {side!r}")
    return (image, K.astype(np.float64), verts.astype(np.float32), joints.astype(np.float32),
            side, float(ann["vr"][t])), ann
