"""INTER-SH on disk: a sample writer and reader, and a resumable, sharded generation driver.

One INTER-SH *sample* is one rendered scene (paper, Sec. "INTER-SH dataset"): the RGB image, the
label mask of the whole scene, the mask of every body rendered alone, the meshes and 21 joints in
the camera frame, the intrinsics ``K`` and the visibility ratio ``VR`` of every body. A *root*
holds ``meta.json`` and one folder per sample::

    root/
      meta.json                    format, generator version, seed, kinds, sizes, params, shards
      samples/000000/
        image.png                  (H, W, 3) RGB, 8 bit
        scene_mask.png             (H, W) labels, 0 = background; 8 bit (16 bit if a label > 255)
        alone_1.png, alone_2.png   (H, W) 1-bit masks of each body rendered alone
        annotation.npz             K, vertices_<l>, faces_<l>, joints_<l>, pose_<l> (no pickles)
        annotation.json            kind, target, sides, names, vr, seed, stats (small, readable)

Every file is deterministic (same sample -> same bytes: no time stamps in PNG, JSON or zip headers),
every sample folder appears atomically (written in a temporary folder, then renamed), and
[`generate_dataset`][handmesh_tutorial.dataset.generate_dataset] resumes an interrupted run to the
same bytes as an uninterrupted one. See ``docs/concepts/dataset_format.md`` for the format in full.

The driver knows nothing about hands or rendering: it calls ``make_sample(sample_seed) -> dict``.
[`synthetic_sample`][handmesh_tutorial.testing.synthetic_sample] is a tiny stand-in (two spheres
ray-cast with numpy) for tests and demos.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import pickle
import re
import shutil
import sys
import time
import uuid
import warnings
import zipfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._io import atomic_write_bytes, fsync_dir, json_safe
from .visibility import VR_BINS, vr_bin

FORMAT_NAME = "INTER-SH"
FORMAT_VERSION = 2
"""Version written by this library. 2: FreiHAND-like framing, photo backgrounds, anatomical
limits by default, and the VR probe of balanced sets in ``meta.json`` (``vr_probe``). The sample
files are laid out as in version 1.
"""
READABLE_FORMAT_VERSIONS = (1, 2)
"""Versions this library reads (version 1 roots read the same; resuming one with this version
is refused, as any change of parameters is).
"""
KINDS: tuple[str, ...] = ("hand-hand", "hand-object", "hand-chain")
"""Scene kinds of INTER-SH (``"mixed"`` in
[`make_sample`][handmesh_tutorial.interact.make_sample] draws one per sample)."""
META_FILE = "meta.json"
SAMPLES_DIR = "samples"
TMP_PREFIX = ".tmp-"
LOCK_FILE = ".generate.lock"
MIN_INDEX_WIDTH = 6
MAX_SAMPLES = 100_000_000
"""Largest ``num_samples`` a ``meta.json`` may declare (the paper's set is 40,000; a corrupt
or hostile file must not make the reader build a list of 1e11 indices).
"""
MAX_LABEL = 65535

_ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # fixed zip entry date: np.savez would store the wall clock
_PNG_LEVEL = 6
_JSON_KW = {"indent": 1, "sort_keys": True, "ensure_ascii": False, "allow_nan": False}
_KNOWN_KEYS = frozenset({
    "image", "scene_mask", "alone_masks", "alone_images", "meshes", "joints", "K", "vr", "kind",
    "target", "sides", "names", "pose", "stats", "index", "seed", "attempt",
})
PROBE_MIN_HITS = 2
"""A bin is filled by VR balancing when at least this many probe candidates hit it: one lucky
hit would keep a bin reachable once in a hundred candidates, whose samples would then mostly end up
off their bin after ``max_attempts`` candidates each.
"""
_SEED_RULE = ("numpy.random.SeedSequence(entropy=seed, spawn_key=(index, attempt))"
              ".generate_state(1, uint64)[0] >> 11")


# --------------------------------------------------------------------------------------------
# seeds and shards
# --------------------------------------------------------------------------------------------
class SampleRejected(Exception):
    """Raised by a ``make_sample`` callable for a seed that yields no valid sample.

    [`generate_dataset`][handmesh_tutorial.dataset.generate_dataset] treats it as a rejected
    candidate (like ``accept`` returning ``False``): it tries the next attempt's seed instead of
    stopping. Any other exception stops generation.
    [`handmesh_tutorial.interact.InteractionError`][handmesh_tutorial.interact.InteractionError] (a
    scene the generator cannot build within its bounded retries) is one.
    """


def sample_seed(seed: int, index: int, attempt: int = 0) -> int:
    """The seed passed to ``make_sample`` for sample ``index`` (``attempt``-th candidate).

    Derived with ``numpy.random.SeedSequence(seed, spawn_key=(index, attempt))``, so it depends
    only on the base seed, the global index and the attempt: not on shards, workers or order.

    Args:
        seed: base seed of the dataset, a non-negative integer.
        index: global sample index, >= 0.
        attempt: candidate number when candidates can be rejected (VR balancing), >= 0.

    Returns:
        A non-negative integer below 2**53 (exact in JSON and JavaScript).
    """
    for name, v in (("seed", seed), ("index", index), ("attempt", attempt)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ValueError(f"{name} must be a non-negative integer, got {v!r}")
    ss = np.random.SeedSequence(entropy=int(seed), spawn_key=(int(index), int(attempt)))
    return int(ss.generate_state(1, dtype=np.uint64)[0] >> np.uint64(11))


def probe_seed(seed: int, k: int) -> int:
    """The seed of the ``k``-th candidate of the VR probe of a balanced set (see
    [`generate_dataset`][handmesh_tutorial.dataset.generate_dataset]):
    ``SeedSequence(seed, spawn_key=(k, 0, 1))``, independent of every sample seed (whose spawn keys
    have two entries).
    """
    sample_seed(seed, k)  # validates
    ss = np.random.SeedSequence(entropy=int(seed), spawn_key=(int(k), 0, 1))
    return int(ss.generate_state(1, dtype=np.uint64)[0] >> np.uint64(11))


def shard_range(num: int, shard_index: int, num_shards: int) -> range:
    """Global indices of one shard: ``num`` samples cut into ``num_shards`` contiguous ranges.

    Args:
        num: total number of samples planned.
        shard_index: which shard, ``0 <= shard_index < num_shards``.
        num_shards: number of shards (machines), >= 1.

    Returns:
        ``range(num * k // n, num * (k + 1) // n)``; the ranges of all shards are disjoint and
        cover ``range(num)``.
    """
    if num_shards < 1 or not 0 <= shard_index < num_shards:
        raise ValueError(f"shard must satisfy 0 <= shard_index < num_shards, got "
                         f"({shard_index}, {num_shards})")
    return range(num * shard_index // num_shards, num * (shard_index + 1) // num_shards)


def index_width(num: int) -> int:
    """Digits of the zero-padded sample folder names (at least 6: ``000123``)."""
    return max(MIN_INDEX_WIDTH, len(str(max(num - 1, 0))))


def vr_bins(bins: Sequence | None = None) -> tuple[tuple[float, float], ...]:
    """VR bins as ``((lo, hi), ...)``: ``bins`` if given, else the paper's ``visibility.VR_BINS``.

    Accepts pairs ``[(lo, hi), ...]`` or bin edges ``[e0, e1, ..., en]``.
    """
    seq = list(VR_BINS if bins is None else bins)
    if seq and all(np.ndim(b) == 0 for b in seq):  # edges
        seq = list(zip(seq[:-1], seq[1:], strict=True))
    out = tuple((float(lo), float(hi)) for lo, hi in seq)
    if not out or any(not 0.0 <= lo < hi <= 1.0 for lo, hi in out):
        raise ValueError(f"VR bins must be non-empty pairs 0 <= lo < hi <= 1, got {bins!r}")
    return out


def vr_histogram(values: Sequence[float], bins: Sequence[tuple[float, float]]) -> list[int]:
    """Counts of ``values`` per bin (a value in no bin is not counted)."""
    idx = [vr_bin(v, bins) for v in values]
    return [idx.count(k) for k in range(len(bins))]


# --------------------------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------------------------
def _fail(where: str, what: str) -> ValueError:
    return ValueError(f"{where}: {what}")


def _label(key: Any, where: str) -> int:
    if isinstance(key, str) and key.isdigit():
        key = int(key)
    if isinstance(key, bool) or not isinstance(key, (int, np.integer)) or not 1 <= key <= MAX_LABEL:
        raise _fail(where, f"label {key!r} is not an integer in 1..{MAX_LABEL}")
    return int(key)


def _array(a: Any, where: str, shape: tuple, kind: str, dtype: Any) -> np.ndarray:
    """Check ndim/fixed dims (``None`` = any) and dtype kind ('f', 'i', 'b', 'u8'); cast."""

    def _fail(where: str, what: str) -> ValueError:  # "<where> has shape ..." (no colon)
        return ValueError(f"{where} {what}")

    a = np.asarray(a)
    if a.ndim != len(shape) or any(s is not None and s != g for s, g in zip(shape, a.shape,
                                                                            strict=True)):
        exp = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise _fail(where, f"has shape {a.shape}, expected {exp}")
    if kind == "u8" and a.dtype != np.uint8:
        raise _fail(where, f"has dtype {a.dtype}, expected uint8")
    if kind == "f" and a.dtype.kind not in "fiu":
        raise _fail(where, f"has dtype {a.dtype}, expected floating point")
    if kind == "i" and a.dtype.kind not in "iu":
        raise _fail(where, f"has dtype {a.dtype}, expected integer")
    if kind == "b" and a.dtype.kind not in "biu":
        raise _fail(where, f"has dtype {a.dtype}, expected bool")
    if kind == "b" and a.dtype != bool and a.size and not np.isin(a, (0, 1)).all():
        raise _fail(where, "has values other than 0/1, expected a boolean mask")
    out = np.ascontiguousarray(a, dtype=dtype)
    if kind == "f" and not np.isfinite(out).all():
        raise _fail(where, "has non-finite values")
    return out


def _canonical(sample: Mapping, loc: Callable[[str], str]) -> dict:
    """Validate a sample and return it with the documented dtypes.

    ``loc(field)`` names where a field came from (``sample['joints'][1]`` when writing,
    ``.../annotation.npz: key 'joints_1'`` when reading) so that errors name the culprit.
    """
    for key in ("image", "scene_mask", "alone_masks", "meshes", "joints", "K", "vr", "kind",
                "target", "sides"):
        if key not in sample:
            raise ValueError(f"{loc(key)} missing (required key of an INTER-SH sample)")
    s: dict[str, Any] = {}
    image = _array(sample["image"], loc("image"), (None, None, 3), "u8", np.uint8)
    hw = image.shape[:2]
    s["image"] = image
    mask = _array(sample["scene_mask"], loc("scene_mask"), hw, "i", np.int64)
    if mask.size and (mask.min() < 0 or mask.max() > MAX_LABEL):
        raise _fail(loc("scene_mask"), f"labels must be in 0..{MAX_LABEL}, got "
                                       f"{mask.min()}..{mask.max()}")
    s["scene_mask"] = mask.astype(np.int32)

    meshes = {}
    for key, mesh in dict(sample["meshes"]).items():
        lab = _label(key, loc("meshes"))
        if not isinstance(mesh, (tuple, list)) or len(mesh) != 2:
            raise _fail(loc("meshes"), f"entry {lab} must be (vertices, faces)")
        v = _array(mesh[0], loc(f"vertices_{lab}"), (None, 3), "f", np.float32)
        f = _array(mesh[1], loc(f"faces_{lab}"), (None, 3), "i", np.int64)
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise _fail(loc(f"faces_{lab}"), f"indices must be in 0..{len(v) - 1}, got "
                                             f"{f.min()}..{f.max()}")
        meshes[lab] = (v, f.astype(np.int32))
    labels = sorted(meshes)
    if not labels:
        raise _fail(loc("meshes"), "no bodies: a sample needs at least one mesh")
    s["meshes"] = {lab: meshes[lab] for lab in labels}
    stray = sorted(set(np.unique(s["scene_mask"]).tolist()) - {0} - set(labels))
    if stray:
        raise _fail(loc("scene_mask"), f"labels {stray} have no mesh (bodies: {labels})")

    def per_label(name: str, keys_required: Sequence[int] | None) -> dict:
        d = {_label(k, loc(name)): v for k, v in dict(sample.get(name) or {}).items()}
        if keys_required is not None and sorted(d) != sorted(keys_required):
            raise _fail(loc(name), f"labels {sorted(d)}, expected {sorted(keys_required)}")
        return d

    s["alone_masks"] = {lab: _array(m, loc(f"alone_{lab}"), hw, "b", bool)
                        for lab, m in sorted(per_label("alone_masks", labels).items())}
    alone_rgb = per_label("alone_images", None)
    if not set(alone_rgb) <= set(labels):
        raise _fail(loc("alone_images"), f"labels {sorted(alone_rgb)} not all in {labels}")
    s["alone_images"] = {lab: _array(m, loc(f"alone_rgb_{lab}"), (*hw, 3), "u8", np.uint8)
                         for lab, m in sorted(alone_rgb.items())}
    vr = {}
    for lab, x in sorted(per_label("vr", labels).items()):
        if isinstance(x, bool) or not isinstance(x, (int, float, np.number)) \
                or not 0.0 <= float(x) <= 1.0:
            raise _fail(loc("vr"), f"vr of label {lab} is {x!r}, expected a number in [0, 1]")
        vr[lab] = float(x)
    s["vr"] = vr

    sides = per_label("sides", None)
    if not sides or not set(sides) <= set(labels):
        raise _fail(loc("sides"), f"hand labels {sorted(sides)} must be a non-empty subset of "
                                  f"the bodies {labels}")
    if any(v not in ("left", "right") for v in sides.values()):
        raise _fail(loc("sides"), f"sides must be 'left' or 'right', got {sides}")
    hands = sorted(sides)
    s["sides"] = {lab: str(sides[lab]) for lab in hands}
    s["joints"] = {lab: _array(j, loc(f"joints_{lab}"), (21, 3), "f", np.float32)
                   for lab, j in sorted(per_label("joints", hands).items())}
    pose = per_label("pose", None)
    if not set(pose) <= set(hands):
        raise _fail(loc("pose"), f"labels {sorted(pose)} are not all hands {hands}")
    s["pose"] = {lab: _array(p, loc(f"pose_{lab}"), (15, 3), "f", np.float32)
                 for lab, p in sorted(pose.items())}
    s["K"] = _array(sample["K"], loc("K"), (3, 3), "f", np.float64)
    if sample["kind"] not in KINDS:
        raise _fail(loc("kind"), f"{sample['kind']!r} is not one of {KINDS}")
    s["kind"] = str(sample["kind"])
    target = _label(sample["target"], loc("target"))
    if target not in hands:
        raise _fail(loc("target"), f"{target} is not a hand label {hands}")
    s["target"] = target
    names = per_label("names", None)
    if names and sorted(names) != labels:
        raise _fail(loc("names"), f"labels {sorted(names)}, expected {labels}")
    s["names"] = {lab: str(names.get(lab, f"{s['sides'][lab]}_hand" if lab in sides else "object"))
                  for lab in labels}
    s["stats"] = json_safe(dict(sample.get("stats") or {}), loc("stats"))
    for key in ("index", "seed", "attempt"):
        v = sample.get(key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer))
                              or v < 0):
            raise _fail(loc(key), f"{v!r} is not a non-negative integer")
        s[key] = None if v is None else int(v)
    for key, v in sample.items():  # optional extras: arrays to the npz, the rest to the json
        if key in _KNOWN_KEYS:
            continue
        if not isinstance(key, str) or not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", key):
            raise _fail(loc("extra"), f"extra key {key!r} must be an identifier")
        s[key] = np.asarray(v) if isinstance(v, np.ndarray) else json_safe(v, loc(key))
        if isinstance(s[key], np.ndarray) and s[key].dtype.kind not in "biuf":
            raise _fail(loc(key), f"extra array of dtype {s[key].dtype} cannot be stored")
    return s


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
        sample: a sample dict (see [`InterSHDataset`][handmesh_tutorial.dataset.InterSHDataset]);
            ``index``, ``seed``, ``attempt``, ``names``, ``pose``, ``alone_images``, ``stats`` are
            optional. Extra keys are kept: numpy arrays go to ``annotation.npz`` as ``extra_<key>``,
            other values (JSON-able) to ``annotation.json`` under ``extra``.

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
    return path.with_name(f"{TMP_PREFIX}{path.name}-{os.getpid()}-{uuid.uuid4().hex[:8]}")


def _write_atomic(path: Path, data: bytes, durable: bool = True) -> None:
    """Write a file atomically with a temporary name `_is_own_temporary` recognises."""
    atomic_write_bytes(path, data, durable, tmp_path=_temporary(path))


def _write_folder(directory: Path, files: Mapping[str, bytes], durable: bool) -> None:
    """Write files into a hidden sibling folder, then rename it to ``directory`` in one step."""
    parent = directory.parent
    tmp = _temporary(directory)
    tmp.mkdir()
    try:
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
        sample: the sample dict (see [`encode_sample`][handmesh_tutorial.dataset.encode_sample] and
            [`InterSHDataset`][handmesh_tutorial.dataset.InterSHDataset]).
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
def _read_json(path: Path) -> Any:
    if not path.is_file():
        raise FileNotFoundError(f"{path} missing")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not valid JSON ({e})") from e


def _read_png(path: Path, modes: Sequence[str]) -> np.ndarray:
    from PIL import Image

    if not path.is_file():
        raise FileNotFoundError(f"{path} missing")
    try:
        with Image.open(path) as im:
            im.load()
            mode, arr = im.mode, np.array(im)
    except Exception as e:  # PIL raises OSError, SyntaxError, zlib.error, ... on bad files
        raise ValueError(f"{path}: not a readable PNG ({type(e).__name__}: {e})") from e
    if mode not in modes:
        raise ValueError(f"{path}: PNG mode {mode}, expected one of {list(modes)}")
    return arr


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
    ann["target"] = _label(ann["target"], f"{where}: 'target'")
    if ann["target"] not in ann["hands"] or ann["target"] not in ann["vr"]:
        raise ValueError(f"{path}: 'target' {ann['target']} is not a hand label with a VR "
                         f"(hands {ann['hands']}, vr labels {sorted(ann['vr'])})")
    return ann


def read_sample(directory: str | os.PathLike) -> dict:
    """Read and validate one sample folder.

    Args:
        directory: a folder written by [`write_sample`][handmesh_tutorial.dataset.write_sample].

    Returns:
        The sample dict (see [`InterSHDataset`][handmesh_tutorial.dataset.InterSHDataset]), numpy
        arrays with the documented dtypes.

    Raises:
        FileNotFoundError: a file is missing (the message names it).
        ValueError: a file is corrupt or inconsistent (the message names the file and key).
    """
    d = Path(directory)
    ann = read_annotation(d)
    npz_path = d / "annotation.npz"
    if not npz_path.is_file():
        raise FileNotFoundError(f"{npz_path} missing")
    try:
        with np.load(npz_path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as e:  # BadZipFile, ValueError (pickled arrays), OSError, ...
        raise ValueError(f"{npz_path}: not a readable npz ({type(e).__name__}: {e})") from e
    labels, hands = ann["labels"], ann["hands"]
    need = ["K", *(f"{p}_{lab}" for lab in labels for p in ("vertices", "faces")),
            *(f"joints_{lab}" for lab in hands), *(f"pose_{lab}" for lab in ann["pose_labels"]),
            *(f"extra_{k}" for k in ann.get("extra_arrays", []))]
    for key in need:
        if key not in arrays:
            raise ValueError(f"{npz_path}: missing key '{key}' (annotation.json lists it)")

    mask_modes = ("L",) if ann.get("scene_mask_bits", 8) == 8 else ("I;16", "I")
    sample: dict[str, Any] = {
        "image": _read_png(d / "image.png", ("RGB",)),
        "scene_mask": _read_png(d / "scene_mask.png", mask_modes),
        "alone_masks": {lab: _read_png(d / f"alone_{lab}.png", ("1", "L")) != 0
                        for lab in labels},
        "alone_images": {lab: _read_png(d / f"alone_rgb_{lab}.png", ("RGB",))
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
    for k, v in (ann.get("extra") or {}).items():
        s[k] = v
    for k in ann.get("extra_arrays", []):
        s[k] = arrays[f"extra_{k}"]
    return s


def read_meta(root: str | os.PathLike) -> dict:
    """Read ``root/meta.json`` (raises FileNotFoundError / ValueError naming the file)."""
    path = Path(root) / META_FILE
    meta = _read_json(path)
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise ValueError(f"{path}: not an {FORMAT_NAME} meta file")
    if meta.get("format_version") not in READABLE_FORMAT_VERSIONS:
        raise ValueError(f"{path}: format_version {meta.get('format_version')}, this library "
                         f"reads {list(READABLE_FORMAT_VERSIONS)}")
    width = meta.get("index_width", MIN_INDEX_WIDTH)
    if isinstance(width, bool) or not isinstance(width, int) or not 1 <= width <= 18:
        raise ValueError(f"{path}: 'index_width' must be an integer in [1, 18], got {width!r}")
    num = meta.get("num_samples")
    if isinstance(num, bool) or not isinstance(num, int) or not 1 <= num <= MAX_SAMPLES:
        raise ValueError(f"{path}: 'num_samples' must be an integer in [1, {MAX_SAMPLES:,}], "
                         f"got {num!r}")
    ranges = meta.get("ranges")
    if not isinstance(ranges, list) or not all(
            isinstance(r, list) and len(r) == 2 and all(type(x) is int for x in r)
            and 0 <= r[0] <= r[1] <= num for r in ranges):
        raise ValueError(f"{path}: 'ranges' must be [[start, stop], ...] integer pairs within "
                         f"[0, num_samples={num}], got {str(ranges)[:80]}")
    return meta


def _present(samples_dir: Path) -> list[int]:
    if not samples_dir.is_dir():
        return []
    return sorted(int(p.name) for p in samples_dir.iterdir() if p.name.isdigit() and p.is_dir())


def _planned(meta: Mapping) -> list[int]:
    return [i for a, b in meta["ranges"] for i in range(a, b)]


class InterSHDataset:
    """An INTER-SH root read lazily: ``len(ds)``, ``ds[i]`` -> sample dict (numpy).

    A map-style dataset (``__len__``/``__getitem__``): ``torch.utils.data.DataLoader`` accepts it
    directly, with a ``transform`` turning the dict into tensors. Position ``i`` is the i-th sample
    folder present in sorted order; ``ds.indices[i]`` is its global index.

    ``ds[i]`` returns a dict with:

    * ``image`` (H, W, 3) uint8 RGB;
    * ``scene_mask`` (H, W) int32 labels, 0 = background;
    * ``alone_masks`` {label: (H, W) bool} each body rendered alone;
    * ``meshes`` {label: (vertices (V, 3) float32 metres camera frame, faces (F, 3) int32)};
    * ``joints`` {hand label: (21, 3) float32 metres camera frame, FreiHAND order};
    * ``pose`` {hand label: (15, 3) float32 axis-angle} (may be empty);
    * ``K`` (3, 3) float64 intrinsics (OpenCV, pixels);
    * ``vr`` {label: float in [0, 1]} visibility ratio;
    * ``kind`` "hand-hand" | "hand-object" | "hand-chain";
    * ``target`` the hand label to predict;
    * ``sides`` {hand label: "left" | "right"};
    * ``names`` {label: body name};
    * ``stats`` {str: generator numbers};
    * ``index``, ``seed``, ``attempt`` (ints; ``None`` for samples written without them);
    * ``alone_images`` {label: (H, W, 3) uint8} only if stored;
    * extra keys as written.

    Args:
        root: the dataset folder (with ``meta.json``).
        transform: optional callable applied to each sample dict.

    Raises:
        FileNotFoundError: ``meta.json`` is missing.
    """

    def __init__(self, root: str | os.PathLike, transform: Callable[[dict], Any] | None = None):
        self.root = Path(root)
        self.meta = read_meta(self.root)
        self.transform = transform
        self.indices = np.asarray(_present(self.root / SAMPLES_DIR), dtype=np.int64)
        self._vr: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.indices)

    def __repr__(self) -> str:
        planned = sum(b - a for a, b in self.meta["ranges"])  # no list of every index
        present = sum(int(((self.indices >= a) & (self.indices < b)).sum())
                      for a, b in self.meta["ranges"])
        return (f"InterSHDataset({str(self.root)!r}: {len(self)} samples, kinds "
                f"{self.meta['kinds']}, {planned - present} missing)")

    @property
    def missing(self) -> list[int]:
        """Global indices planned by ``meta.json`` (its ranges) but not on disk."""
        present = set(self.indices.tolist())
        return [i for i in _planned(self.meta) if i not in present]

    def sample_dir(self, i: int) -> Path:
        """Folder of the sample at position ``i`` (negative positions count from the end)."""
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"sample position {i} out of range for {n} samples in {self.root}")
        width = self.meta.get("index_width", MIN_INDEX_WIDTH)
        return self.root / SAMPLES_DIR / f"{int(self.indices[i]):0{width}d}"

    def annotation(self, i: int) -> dict:
        """Only ``annotation.json`` of sample ``i`` (kind, target, vr, seed, stats...): fast."""
        return read_annotation(self.sample_dir(i))

    def __getitem__(self, i: int) -> Any:
        d = self.sample_dir(i)
        s = read_sample(d)
        if s["index"] is not None and s["index"] != int(self.indices[i]):
            raise ValueError(f"{d / 'annotation.json'}: index {s['index']} but folder is {d.name}")
        if s["kind"] not in self.meta["kinds"]:
            raise ValueError(f"{d / 'annotation.json'}: kind {s['kind']!r} not in meta.json "
                             f"kinds {self.meta['kinds']}")
        size = self.meta.get("image_size")
        if size is not None and list(s["image"].shape[:2]) != list(size):
            raise ValueError(f"{d / 'image.png'}: size {list(s['image'].shape[:2])}, meta.json "
                             f"image_size {size}")
        return self.transform(s) if self.transform is not None else s

    def vr_table(self) -> np.ndarray:
        """VR of the target hand of every sample, (N,) float64 (reads only the JSON files)."""
        if self._vr is None:
            anns = (self.annotation(i) for i in range(len(self)))
            self._vr = np.array([a["vr"][a["target"]] for a in anns], dtype=np.float64)
        return self._vr


@dataclass
class VerifyReport:
    """Outcome of [`verify_dataset`][handmesh_tutorial.dataset.verify_dataset].

    Attributes:
        root: the dataset folder.
        checked: sample entries read.
        bad: ``[(folder name, reason)]`` of the samples that failed, sorted by name.
        removed: the bad entries deleted (``remove=True``); rerunning the same ``generate``
            call then writes exactly these again, with the same bytes as before.
    """

    root: Path
    checked: int
    bad: list[tuple[str, str]]
    removed: list[str]

    def __str__(self) -> str:
        lines = [f"{self.root}: {self.checked} samples read, {len(self.bad)} bad"
                 + (f", {len(self.removed)} removed" if self.removed else "")]
        lines += [f"  {name}: {why}" for name, why in self.bad]
        return "\n".join(lines)


def verify_dataset(root: str | os.PathLike, *, remove: bool = False,
                   progress: bool = True) -> VerifyReport:
    """Re-read every sample of an INTER-SH root and list the ones that are unreadable or foreign.

    Each sample folder must read back ([`read_sample`][handmesh_tutorial.dataset.read_sample]: every
    file, key, shape, dtype) and agree with ``meta.json`` (kind, image size) and with its own name
    (index; the seed of the sample-seed rule,
    [`sample_seed`][handmesh_tutorial.dataset.sample_seed]). A file where a sample folder belongs is
    bad too.

    Args:
        root: the dataset folder (with ``meta.json``).
        remove: delete the bad entries, so that rerunning the same ``generate`` regenerates them.
        progress: tqdm progress bar.

    Returns:
        A [`VerifyReport`][handmesh_tutorial.dataset.VerifyReport].
    """
    from ._progress import progress_bar

    root = Path(root)
    ds = InterSHDataset(root)
    samples = root / SAMPLES_DIR
    bad: list[tuple[str, str]] = []
    entries = sorted(p for p in samples.iterdir() if p.name.isdigit()) if samples.is_dir() \
        else []
    position = {int(i): k for k, i in enumerate(ds.indices.tolist())}
    for p in progress_bar(entries, disable=not progress, desc="verify", unit="sample"):
        if not p.is_dir() or p.is_symlink():
            bad.append((p.name, "not a sample folder (a file or link)"))
            continue
        try:
            s = ds[position[int(p.name)]]
            if s["seed"] is not None and s["attempt"] is not None and "seed" in ds.meta:
                want = sample_seed(ds.meta["seed"], int(p.name), int(s["attempt"]))
                if int(s["seed"]) != want:
                    raise ValueError(f"{p / 'annotation.json'}: seed {s['seed']}, the seed rule "
                                     f"of meta.json gives {want} (a sample of another run?)")
        except (ValueError, KeyError, OSError, TypeError) as err:
            bad.append((p.name, str(err).splitlines()[0] if str(err) else type(err).__name__))
    removed = []
    if remove:
        for name, _ in bad:
            target = samples / name
            shutil.rmtree(target) if target.is_dir() and not target.is_symlink() \
                else target.unlink()
            removed.append(name)
    return VerifyReport(root=root, checked=len(entries), bad=bad, removed=removed)


# --------------------------------------------------------------------------------------------
# generation driver
# --------------------------------------------------------------------------------------------
def _callable_name(fn: Callable | None) -> str | None:
    if fn is None:
        return None
    base = getattr(fn, "func", fn)  # functools.partial: its function (put its args in params)
    name = getattr(base, "__qualname__", type(base).__name__)
    return f"{getattr(base, '__module__', '?')}.{name}"


def _coalesce(ranges: Sequence[Sequence[int]]) -> list[list[int]]:
    out: list[list[int]] = []
    for a, b in sorted((int(a), int(b)) for a, b in ranges if b > a):
        if out and a < out[-1][1]:
            raise ValueError(f"index ranges overlap: [{out[-1][0]}, {out[-1][1]}) and [{a}, {b})")
        if out and a == out[-1][1]:
            out[-1][1] = b
        else:
            out.append([a, b])
    return out


def _diff(a: Any, b: Any, prefix: str = "") -> list[str]:
    """Dotted names of the keys where two JSON values differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            out += _diff(a.get(k, "<absent>"), b.get(k, "<absent>"), f"{prefix}{k}.")
        return out
    return [] if a == b else [prefix.rstrip(".")]


def _diff_message(path: Path, old: dict, new: dict, keys: Sequence[str]) -> str:
    def get(d: Any, dotted: str) -> Any:
        for part in dotted.split("."):
            d = d.get(part, "<absent>") if isinstance(d, dict) else "<absent>"
        return d

    lines = [f"  {k}: {get(old, k)!r} on disk, {get(new, k)!r} now" for k in keys]
    return (f"{path} was written with different parameters; differing keys: {', '.join(keys)}\n"
            + "\n".join(lines))


@contextlib.contextmanager
def _lock(root: Path) -> Iterator[None]:
    """One writer per root (an flock the OS drops if the process dies, even on SIGKILL)."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no protection against two writers
        yield
        return
    with open(root / LOCK_FILE, "a+b") as fh:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise RuntimeError(f"{root} is being written by another process "
                               f"({root / LOCK_FILE} is locked)") from None
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


_TMP_NAME = re.compile(rf"^{re.escape(TMP_PREFIX)}(?P<name>.+)-\d+-[0-9a-f]{{8}}$")
"""Names of this module's temporaries: ``.tmp-<final name>-<pid>-<8 hex digits>``."""
_SAMPLE_FILE = re.compile(r"^(image|scene_mask|alone_\d+|alone_rgb_\d+)\.png$"
                          r"|^annotation\.(npz|json)$")
"""Files a sample folder can hold (``_encode``): what a half-written sample may contain."""


def _is_own_temporary(p: Path) -> bool:
    """Whether ``p`` is a temporary that a writer of this module made (and may be removed).

    The name must be `_temporary`'s ``.tmp-<name>-<pid>-<8 hex>``; a folder may hold only sample
    files, a file must stand for ``meta.json`` or a sample file. Anything else, e.g. a user's
    ``.tmp-my-notes/``, is left alone.
    """
    m = _TMP_NAME.match(p.name)
    if m is None or p.is_symlink():
        return False
    if p.is_dir():
        return all(c.is_file() and not c.is_symlink() and _SAMPLE_FILE.match(c.name)
                   for c in p.iterdir())
    return p.is_file() and (m["name"] == META_FILE or _SAMPLE_FILE.match(m["name"]) is not None)


def _clean_stale(folder: Path) -> int:
    """Remove the temporaries a killed writer left in ``folder``; returns how many.

    Only this module's own temporaries (`_is_own_temporary`) are removed.
    """
    n = 0
    if folder.is_dir():
        for p in folder.iterdir():
            if p.name.startswith(TMP_PREFIX) and _is_own_temporary(p):
                shutil.rmtree(p) if p.is_dir() else p.unlink()
                n += 1
    return n


def _open_root(root: Path, meta: dict) -> int:
    """Create or check ``root/meta.json``; clean stale temporaries. Returns their count."""
    path = root / META_FILE
    if path.exists():
        old = read_meta(root)
        keys = _diff(old, meta)
        if keys:
            raise ValueError(_diff_message(path, old, meta, keys))
    else:
        _write_atomic(path, (json.dumps(meta, indent=2, sort_keys=True) + "\n").encode())
    (root / SAMPLES_DIR).mkdir(exist_ok=True)
    return _clean_stale(root / SAMPLES_DIR) + _clean_stale(root)


@dataclass
class _Task:
    """What a worker needs to make and write samples (pickled once per worker)."""

    make_sample: Callable[[int], Mapping]
    accept: Callable[[dict], bool] | None
    seed: int
    kinds: tuple[str, ...]
    bins: tuple[tuple[float, float], ...] | None
    image_size: tuple[int, int] | None
    max_attempts: int
    samples_dir: str
    width: int
    durable: bool
    filled: tuple[int, ...] | None = None  # bins that balancing fills (None: all of them)


_WORKER_TASK: _Task | None = None


def _die_with_parent(parent_pid: int) -> None:
    """Make this worker process exit when the process that started it dies.

    Without it, ``kill -9`` of ``generate``'s main process leaves its workers running (and
    writing queued samples) for seconds. On Linux the kernel delivers ``SIGKILL`` to the worker
    when its parent dies (``prctl(PR_SET_PDEATHSIG)``); elsewhere a daemon thread polls the
    parent's pid once a second.
    """
    import signal
    import threading

    if sys.platform.startswith("linux"):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig = 1
        if libc.prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0) == 0:
            if os.getppid() != parent_pid:  # the parent died before prctl took effect
                os._exit(1)
            return

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="die-with-parent").start()


def _init_worker(task: _Task, worker_init: Callable[[], Any] | None,
                 parent_pid: int | None = None) -> None:
    global _WORKER_TASK
    if parent_pid is not None:
        _die_with_parent(parent_pid)
    _WORKER_TASK = task
    if worker_init is not None:
        worker_init()  # e.g. one OffscreenRenderer per process, kept in a module global


def _worker_make(index: int) -> dict:
    assert _WORKER_TASK is not None, "worker not initialised"
    return _make_and_write(_WORKER_TASK, index)


def _bin_distance(vr: float, b: tuple[float, float]) -> float:
    """How far ``vr`` lies outside bin ``b`` (0 inside)."""
    return max(b[0] - vr, vr - b[1], 0.0)


def _candidate(task: _Task, index: int | None, attempt: int, s_seed: int) -> dict | None:
    """``make_sample(s_seed)`` checked and canonicalised; ``None`` when it rejects its seed.

    ``index`` is the sample's global index, or ``None`` for a candidate of the VR probe.
    """
    what = f"sample {index}" if index is not None else f"VR probe candidate {attempt}"
    try:
        raw = task.make_sample(s_seed)
    except SampleRejected:
        return None  # e.g. a scene the generator cannot build: the next seed replaces it
    except Exception as e:
        if hasattr(e, "add_note"):  # Python >= 3.11
            e.add_note(f"while making {what} (attempt {attempt}, seed {s_seed})")
        raise
    if not isinstance(raw, Mapping):
        raise TypeError(f"make_sample({s_seed}) returned {type(raw).__name__}, expected a "
                        f"dict ({what})")
    sample = {**raw, "index": index, "seed": s_seed, "attempt": attempt}
    canon = _canonical(sample, lambda f: f"{what}: {f!r}")
    if canon["kind"] not in task.kinds:
        raise ValueError(f"{what}: kind {canon['kind']!r} is not one of the "
                         f"dataset's kinds {list(task.kinds)}")
    hw = canon["image"].shape[:2]
    if task.image_size is not None and tuple(hw) != tuple(task.image_size):
        raise ValueError(f"{what}: image size {tuple(hw)}, expected "
                         f"{tuple(task.image_size)}")
    return canon


def _make_and_write(task: _Task, index: int) -> dict:
    """Try seeds (seed, index, attempt) until a candidate is accepted; write it; summarise.

    With VR balancing, sample ``index`` wants bin ``filled[index % len(filled)]``; when no
    candidate of ``max_attempts`` falls in it, the accepted candidate whose target VR is nearest
    to the bin is written instead (``off_bin``), so balancing never stops a run.
    """
    want = None
    if task.bins:
        filled = task.filled if task.filled is not None else tuple(range(len(task.bins)))
        want = filled[index % len(filled)] if filled else None
    best = None  # (distance to the wanted bin, attempt, canonical sample)
    for attempt in range(task.max_attempts):
        s_seed = sample_seed(task.seed, index, attempt)
        canon = _candidate(task, index, attempt, s_seed)
        if canon is None:
            continue
        vr = canon["vr"][canon["target"]]
        if want is not None and vr_bin(vr, task.bins) != want:
            dist = _bin_distance(vr, task.bins[want])
            if (best is None or dist < best[0]) and (task.accept is None or task.accept(canon)):
                best = (dist, attempt, canon)
            continue
        if task.accept is not None and not task.accept(canon):
            continue
        _write_folder(Path(task.samples_dir) / f"{index:0{task.width}d}", _encode(canon),
                      task.durable)
        return {"index": index, "attempts": attempt + 1, "target_vr": vr, "off_bin": False}
    if best is not None:  # balancing missed its bin: the nearest accepted candidate
        canon = best[2]
        _write_folder(Path(task.samples_dir) / f"{index:0{task.width}d}", _encode(canon),
                      task.durable)
        return {"index": index, "attempts": task.max_attempts,
                "target_vr": canon["vr"][canon["target"]], "off_bin": True}
    raise RuntimeError(f"sample {index}: no candidate accepted in {task.max_attempts} attempts "
                       f"(seeds {_SEED_RULE} with attempt 0..{task.max_attempts - 1}); "
                       f"raise max_attempts or relax accept")


def _probe(task: _Task, num: int) -> dict:
    """VR probe of a balanced set: ``num`` candidates (seeds
    [`probe_seed`][handmesh_tutorial.dataset.probe_seed]), their target-VR counts per bin, and the
    bins balancing fills (those with at least
    [`PROBE_MIN_HITS`][handmesh_tutorial.dataset.PROBE_MIN_HITS] hits)."""
    hits = [0] * len(task.bins)
    rejected = outside = 0
    for k in range(num):
        canon = _candidate(task, None, k, probe_seed(task.seed, k))
        if canon is None or (task.accept is not None and not task.accept(canon)):
            rejected += 1
            continue
        b = vr_bin(canon["vr"][canon["target"]], task.bins)
        if b < 0:
            outside += 1
        else:
            hits[b] += 1
    return {"candidates": int(num), "hits": hits, "outside": outside, "rejected": rejected,
            "min_hits": PROBE_MIN_HITS,
            "filled": [b for b, h in enumerate(hits) if h >= PROBE_MIN_HITS]}


def _fmt_bin(b: Sequence[float]) -> str:
    return f"[{b[0]:.2f}, {b[1]:.2f}{']' if b[1] >= 1 else ')'}"


@dataclass
class GenerationSummary:
    """What [`generate_dataset`][handmesh_tutorial.dataset.generate_dataset] did (``str(summary)``
    is a short report).

    Attributes:
        root: dataset folder.
        indices: (start, stop) global index ranges of this run's shard.
        written: samples written by this call.
        skipped: samples already on disk (a resumed run).
        attempts: ``make_sample`` calls of this call (> written when candidates were rejected).
        stale_removed: temporary folders of a killed run that were removed.
        seconds: wall time of this call.
        vr_bins: the VR bins of the histogram.
        vr_histogram: target-hand VR counts per bin over all samples of the shard on disk.
        vr_outside: samples whose target VR is in no bin.
        vr_probe: with VR balancing, the probe (``candidates``, ``hits`` per bin, ``outside``,
            ``rejected``, ``filled``: the bin indices balancing fills), else ``None``.
        off_bin: balanced samples of this call written outside their bin (no candidate of
            ``max_attempts`` reached it: the nearest one was kept).
        probe_attempts: ``make_sample`` calls of the probe in this call (0 when reused from
            ``meta.json``).
    """

    root: str
    indices: list[list[int]]
    written: int
    skipped: int
    attempts: int
    stale_removed: int
    seconds: float
    vr_bins: list[tuple[float, float]]
    vr_histogram: list[int]
    vr_outside: int
    vr_probe: dict | None = None
    off_bin: int = 0
    probe_attempts: int = 0

    @property
    def vr_unreachable(self) -> list[tuple[float, float]]:
        """Bins that VR balancing left out because its probe (almost) never reached them."""
        if not self.vr_probe:
            return []
        return [b for k, b in enumerate(self.vr_bins) if k not in self.vr_probe["filled"]]

    @property
    def samples_per_second(self) -> float:
        """Samples written per second of wall time in this call."""
        return self.written / self.seconds if self.seconds > 0 else float("nan")

    def __str__(self) -> str:
        hist = ", ".join(f"[{lo:.2f}, {hi:.2f}{']' if hi >= 1 else ')'}: {n}" for (lo, hi), n
                         in zip(self.vr_bins, self.vr_histogram, strict=True))
        text = (f"{self.root}: wrote {self.written}, skipped {self.skipped} already present "
                f"(indices {self.indices}), {self.attempts} make_sample calls, "
                f"{self.samples_per_second:.2f} samples/s, {self.stale_removed} stale temp "
                f"removed\ntarget VR histogram: {hist}; outside bins: {self.vr_outside}")
        if self.vr_probe:
            gone = ", ".join(_fmt_bin(b) for b in self.vr_unreachable) or "none"
            text += (f"\nVR balancing: bins left out (reached by fewer than "
                     f"{self.vr_probe['min_hits']} of {self.vr_probe['candidates']} probe "
                     f"candidates): {gone}; samples written outside their bin: {self.off_bin}")
        return text


def generate_dataset(
    root: str | os.PathLike,
    make_sample: Callable[[int], Mapping],
    num: int,
    seed: int,
    kind: str | Sequence[str],
    *,
    shard: tuple[int, int] | None = None,
    workers: int = 1,
    progress: bool = True,
    params: Mapping | None = None,
    image_size: int | tuple[int, int] | None = None,
    accept: Callable[[dict], bool] | None = None,
    balance_vr: bool | Sequence = False,
    max_attempts: int = 100,
    vr_probe: int = 64,
    worker_init: Callable[[], Any] | None = None,
    durable: bool = True,
    mp_context: str = "spawn",
) -> GenerationSummary:
    """Generate (or resume generating) an INTER-SH root.

    Sample ``i`` is ``make_sample(sample_seed(seed, i, attempt))`` for the first ``attempt`` whose
    candidate is accepted, written to ``root/samples/<i>/`` atomically. Its bytes depend only on
    ``(seed, i)``: not on ``workers``, ``shard``, order, or interruptions. Re-running the same call
    after a crash or Ctrl-C skips the samples on disk and removes stale temporary folders.

    Args:
        root: output folder (created).
        make_sample: ``make_sample(sample_seed) -> dict``, a sample as described in
            [`InterSHDataset`][handmesh_tutorial.dataset.InterSHDataset] (without
            ``index``/``seed``). Must be deterministic in its seed and, for ``workers > 1``,
            importable by the worker processes (a function of a module, or a ``functools.partial``
            of one; not one defined in a notebook cell).
        num: number of samples of the whole dataset (all shards).
        seed: base seed, non-negative.
        kind: the kind(s) of scene ``make_sample`` produces (see ``KINDS``).
        shard: ``(shard_index, num_shards)``: make only
            [`shard_range`][handmesh_tutorial.dataset.shard_range] of it (one machine's part; join
            parts with [`merge_shards`][handmesh_tutorial.dataset.merge_shards]). ``None`` = all.
        workers: processes; each makes and writes its own samples.
        progress: show a tqdm bar.
        params: free-form JSON-able creation parameters (renderer, light, object set...),
            stored in ``meta.json`` and compared on resume.
        image_size: expected image size (int side or (H, W)); checked per sample if given.
        accept: optional filter ``accept(sample) -> bool``; a rejected candidate is replaced by the
            next attempt's seed. A ``make_sample`` that raises
            [`SampleRejected`][handmesh_tutorial.dataset.SampleRejected] rejects its seed the same
            way.
        balance_vr: ``True`` (bins from [`vr_bins`][handmesh_tutorial.dataset.vr_bins]) or a list of
            bins: the target VRs are spread evenly over the bins that ``make_sample`` can reach.
            First a *probe* makes ``vr_probe`` candidates (seeds
            [`probe_seed`][handmesh_tutorial.dataset.probe_seed], not samples) and counts their
            target VRs per bin; bins it hits fewer than
            [`PROBE_MIN_HITS`][handmesh_tutorial.dataset.PROBE_MIN_HITS] times (e.g. [0.40, 0.60)
            for hand-chain scenes, whose thin rings rarely hide half a hand) are reported at once (a
            ``UserWarning``) and left out. Sample ``i`` then wants bin ``filled[i % len(filled)]``;
            if none of its ``max_attempts`` candidates lands there, the accepted candidate nearest
            to the bin is written (counted in ``off_bin``): balancing never stops a run. The probe
            is stored in ``meta.json`` (``vr_probe``) and reused on resume; it is deterministic in
            ``seed``, so shards agree.
        max_attempts: candidates per sample; RuntimeError when none is accepted (every seed
            rejected by ``make_sample`` or ``accept``).
        vr_probe: candidates of the VR probe (only with ``balance_vr``), >= 1.
        worker_init: called once in each worker process (and once in-process when
            ``workers == 1``) before any ``make_sample``, e.g. to create a renderer.
        durable: fsync every file and folder (safe against power cuts, slower).
        mp_context: multiprocessing start method of the worker pool ("spawn" is safe with
            OpenGL and torch).

    Returns:
        A [`GenerationSummary`][handmesh_tutorial.dataset.GenerationSummary].

    Raises:
        ValueError: bad arguments, or ``root`` holds a dataset made with different parameters
            (the message lists the differing ``meta.json`` keys).
        RuntimeError: no candidate accepted within ``max_attempts``, or another process is
            writing into ``root``.
    """
    from . import __version__

    t0 = time.perf_counter()
    kinds = (kind,) if isinstance(kind, str) else tuple(kind)
    if not kinds or any(k not in KINDS for k in kinds):
        raise ValueError(f"kind must be one of {KINDS} (or a list of them), got {kind!r}")
    if isinstance(num, bool) or not isinstance(num, int) or num < 1:
        raise ValueError(f"num must be a positive integer, got {num!r}")
    sample_seed(seed, 0)  # validates seed
    if workers < 1 or max_attempts < 1 or vr_probe < 1:
        raise ValueError(f"workers, max_attempts and vr_probe must be >= 1, got {workers}, "
                         f"{max_attempts}, {vr_probe}")
    k, n = shard if shard is not None else (0, 1)
    indices = shard_range(num, k, n)
    if isinstance(image_size, int):
        image_size = (image_size, image_size)
    bins = vr_bins(None if balance_vr is True or balance_vr is False else balance_vr)
    try:
        params = json.loads(json.dumps(dict(params or {}), allow_nan=False, sort_keys=True))
    except (TypeError, ValueError) as e:
        raise ValueError(f"params must be JSON-serialisable: {e}") from e
    if workers > 1:
        _check_for_workers((make_sample, accept, worker_init), mp_context)
    width = index_width(num)
    meta = {
        "format": FORMAT_NAME, "format_version": FORMAT_VERSION, "generator_version": __version__,
        "kinds": sorted(kinds), "seed": int(seed), "num_samples": num,
        "image_size": list(image_size) if image_size is not None else None,
        "camera": {"convention": "OpenCV", "axes": "x right, y down, z forward",
                   "units": "metres", "intrinsics": "K per sample in annotation.npz, pixels"},
        "labels": {"background": 0, "bodies": f"1..{MAX_LABEL}, per sample; names, sides, "
                   "target in annotation.json", "scene_mask_png": "8-bit if all labels <= 255, "
                   "else 16-bit", "alone_png": "1-bit"},
        "vr_bins": [list(b) for b in bins], "balance_vr": bool(balance_vr),
        "make_sample": _callable_name(make_sample), "accept": _callable_name(accept),
        "seed_rule": _SEED_RULE, "index_width": width, "params": params,
        "shards": [[k, n]], "ranges": _coalesce([[indices.start, indices.stop]]),
    }
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    task = _Task(make_sample, accept, int(seed), kinds, bins if balance_vr else None,
                 tuple(image_size) if image_size else None, int(max_attempts),
                 str(root / SAMPLES_DIR), width, durable)
    probe, probe_calls = None, 0
    with _lock(root):
        if balance_vr:
            old = read_meta(root) if (root / META_FILE).exists() else {}
            probe = old.get("vr_probe")
            if not (isinstance(probe, dict) and probe.get("candidates") == vr_probe):
                if worker_init is not None:
                    worker_init()  # the probe runs in this process
                probe = _probe(task, vr_probe)
                probe_calls = vr_probe
            task.filled = tuple(probe["filled"])
            meta["vr_probe"] = probe
            gone = [bins[b] for b in range(len(bins)) if b not in probe["filled"]]
            if gone:
                how = ("no bin is reachable: the samples are not balanced" if not probe["filled"]
                       else "the other bins share the samples evenly")
                warnings.warn(f"VR balancing: {len(gone)} of {len(bins)} bins reached by fewer "
                              f"than {probe['min_hits']} of {vr_probe} probe candidates (hits "
                              f"per bin {probe['hits']}, "
                              f"outside all bins {probe['outside']}, rejected "
                              f"{probe['rejected']}): {', '.join(_fmt_bin(b) for b in gone)} "
                              f"left out; {how}", UserWarning, stacklevel=2)
        stale = _open_root(root, meta)
        samples_dir = root / SAMPLES_DIR
        done_vr: dict[int, float] = {}
        for i in _present(samples_dir):
            if i not in indices:
                continue
            d = samples_dir / f"{i:0{width}d}"
            ann = read_annotation(d)
            if ann.get("index") != i or ann.get("seed") != sample_seed(seed, i,
                                                                        ann.get("attempt") or 0):
                raise ValueError(f"{d / 'annotation.json'}: index/seed {ann.get('index')}/"
                                 f"{ann.get('seed')} do not match this dataset (seed {seed}); "
                                 f"remove the folder or use another root")
            done_vr[i] = float(ann["vr"][ann["target"]])
        skipped = len(done_vr)
        todo = [i for i in indices if i not in done_vr]
        results = _run(task, todo, workers, worker_init, progress, len(indices), skipped,
                       mp_context, f"INTER-SH {'/'.join(kinds)}", initialised=probe_calls > 0)
    for r in results:
        done_vr[r["index"]] = r["target_vr"]
    hist = vr_histogram(list(done_vr.values()), bins)
    outside = len(done_vr) - sum(hist)
    return GenerationSummary(str(root), meta["ranges"], len(results), skipped,
                             sum(r["attempts"] for r in results), stale,
                             time.perf_counter() - t0, list(bins), hist, outside, probe,
                             sum(r["off_bin"] for r in results), probe_calls)


def _check_for_workers(fns: Sequence[Callable | None], mp_context: str) -> None:
    """Fail early, with a hint, on callables that worker processes could not receive."""
    try:
        pickle.dumps(tuple(fns))
    except Exception as e:
        raise ValueError("make_sample, accept and worker_init must be picklable for workers > 1 "
                         f"(module-level functions or functools.partial of them): {e}") from e
    main = sys.modules.get("__main__")
    interactive = main is not None and not getattr(main, "__file__", None)
    for fn in fns:
        base = getattr(fn, "func", fn)
        if fn is not None and interactive and mp_context != "fork" \
                and getattr(base, "__module__", None) == "__main__":
            raise ValueError(f"{_callable_name(fn)} is defined in an interactive session "
                             f"(notebook/REPL); {mp_context!r} worker processes cannot import it. "
                             "Move it to a module, or use workers=1")


def _run(task: _Task, todo: list[int], workers: int, worker_init: Callable | None,
         progress: bool, total: int, initial: int, mp_context: str, desc: str,
         initialised: bool = False) -> list[dict]:
    from ._progress import progress_bar

    results: list[dict] = []
    bar = progress_bar(total=total, initial=initial, disable=not progress, desc=desc,
                       unit="sample")
    try:
        if workers == 1 or len(todo) <= 1:
            if worker_init is not None and todo and not initialised:
                worker_init()
            for i in todo:
                results.append(_make_and_write(task, i))
                bar.update(1)
            return results
        import multiprocessing
        from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
        from concurrent.futures.process import BrokenProcessPool

        ex = ProcessPoolExecutor(max_workers=min(workers, len(todo)),
                                 mp_context=multiprocessing.get_context(mp_context),
                                 initializer=_init_worker,
                                 initargs=(task, worker_init, os.getpid()))
        it, pending = iter(todo), set()
        try:
            # A bounded window of submissions keeps Ctrl-C responsive and memory flat.
            for i in it:
                pending.add(ex.submit(_worker_make, i))
                if len(pending) >= 2 * workers:
                    break
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for fut in finished:
                    try:
                        results.append(fut.result())  # re-raises a worker's error here
                    except BrokenProcessPool as e:
                        note = getattr(e, "add_note", lambda _: None)  # Python >= 3.11
                        note("a worker process died: out of memory, killed, or it could not "
                             "start (a script using workers needs an "
                             "`if __name__ == '__main__':` guard)")
                        raise
                    bar.update(1)
                    nxt = next(it, None)
                    if nxt is not None:
                        pending.add(ex.submit(_worker_make, nxt))
        except BaseException:
            ex.shutdown(wait=False, cancel_futures=True)
            raise
        ex.shutdown(wait=True)
        return results
    finally:
        bar.close()


def merge_shards(shard_roots: Sequence[str | os.PathLike], out_root: str | os.PathLike, *,
                 link: bool = False, progress: bool = True, durable: bool = True) -> dict:
    """Merge shard roots (made with ``generate_dataset(..., shard=(k, n))``) into one root.

    Samples keep their global indices, so merging all shards gives the same files as one
    unsharded run (``meta.json`` included). Resumable: samples already in ``out_root`` are kept.

    Args:
        shard_roots: the shard folders; their ``meta.json`` must agree on everything except the
            shards, and their index ranges must not overlap.
        out_root: the merged dataset folder (created).
        link: hard-link files instead of copying (same filesystem only).
        progress: show a tqdm bar.
        durable: fsync copied files and folders.

    Returns:
        ``{"copied": int, "skipped": int, "ranges": [[start, stop], ...], "complete": bool}``.

    Raises:
        ValueError: incompatible metas (differing keys named), overlapping shards, a shard with
            missing samples, or an ``out_root`` made from other shards.
    """
    from ._progress import progress_bar

    if not shard_roots:
        raise ValueError("merge_shards needs at least one shard root")
    roots = [Path(r) for r in shard_roots]
    metas = [read_meta(r) for r in roots]
    ignore = ("shards", "ranges")
    base = {k: v for k, v in metas[0].items() if k not in ignore}
    for r, m in zip(roots[1:], metas[1:], strict=True):
        keys = _diff(base, {k: v for k, v in m.items() if k not in ignore})
        if keys:
            raise ValueError(f"cannot merge {roots[0]} and {r}: " +
                             _diff_message(r / META_FILE, base, m, keys))
    for r, m in zip(roots, metas, strict=True):
        present = set(_present(r / SAMPLES_DIR))
        absent = [i for i in _planned(m) if i not in present]
        if absent:
            raise ValueError(f"shard {r} is incomplete: {len(absent)} samples missing (first "
                             f"{absent[:5]}); finish it by re-running its generate command")
    ranges = _coalesce([rg for m in metas for rg in m["ranges"]])
    complete = ranges == [[0, base["num_samples"]]]
    # A root holding every index is recorded as shard 0 of 1: identical to an unsharded run.
    shards = [[0, 1]] if complete else sorted({tuple(s) for m in metas for s in m["shards"]})
    meta = {**base, "shards": [list(s) for s in shards], "ranges": ranges}
    out = Path(out_root)
    out.mkdir(parents=True, exist_ok=True)
    width = base["index_width"]
    copied = skipped = 0
    with _lock(out):
        _open_root(out, meta)
        jobs = [(r, i) for r, m in zip(roots, metas, strict=True) for i in _planned(m)]
        for r, i in progress_bar(jobs, disable=not progress, desc="merge", unit="sample"):
            name = f"{i:0{width}d}"
            dst = out / SAMPLES_DIR / name
            if dst.exists():
                skipped += 1
                continue
            tmp = _temporary(dst)
            try:
                shutil.copytree(r / SAMPLES_DIR / name, tmp,
                                copy_function=os.link if link else shutil.copyfile)
                if durable and not link:
                    for p in tmp.iterdir():
                        with open(p, "rb+") as fh:
                            os.fsync(fh.fileno())
                os.replace(tmp, dst)
            except BaseException:
                shutil.rmtree(tmp, ignore_errors=True)
                raise
            copied += 1
        if durable:
            fsync_dir(out / SAMPLES_DIR)
    return {"copied": copied, "skipped": skipped, "ranges": ranges, "complete": complete}
