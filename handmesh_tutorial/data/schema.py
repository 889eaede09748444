"""The INTER-SH format: its names, versions and limits, and the validation of a sample dict.

A *root* holds ``meta.json`` and one folder per sample under ``samples/``; a sample is a dict of
numpy arrays and plain values (keys and dtypes in
[`InterSHDataset`][handmesh_tutorial.data.reader.InterSHDataset]). `_canonical` checks a
sample, names the culprit of every error, and returns it with the documented dtypes (float32
vertices and joints in metres, camera frame; int32 faces and labels; float64 ``K`` in pixels).
Writing and reading both go through it. See ``docs/concepts/dataset_format.md`` for the format in
full. Taught in notebook 05 ("Rendering and the visibility ratio").
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from .._io import json_safe
from ..budget import MAX_IMAGE_SIZE as _MAX_IMAGE_SIZE

__all__ = [
    "FORMAT_VERSION", "KINDS", "META_FILE", "SAMPLES_DIR", "MAX_SAMPLES", "MAX_LABEL",
    "MAX_IMAGE_SIZE", "MAX_DISTANCE_M", "MIN_DEPTH_M", "FOCAL_RANGE", "PRINCIPAL_POINT_MARGIN",
]

FORMAT_NAME = "INTER-SH"
FORMAT_VERSION = 2
"""Version written by this library. 2: FreiHAND-like framing, photo backgrounds, anatomical
limits by default, and the VR probe of balanced sets in ``meta.json`` (``vr_probe``). The sample
files are laid out as in version 1.
"""
SAME_SAMPLES_SINCE = "0.3.0"
"""The oldest library version whose scene generator makes, from the same seeds and parameters,
the samples this version makes: a root written by it or a later version (up to this one)
resumes, although its ``meta.json`` names another ``generator_version``. Set it to the current
version in any change that alters a sample (``tests/test_dataset.py`` holds a fingerprint of a
few samples that fails until then), so that a release without such a change keeps the sets
users spent hours generating.
"""
READABLE_FORMAT_VERSIONS = (1, 2)
"""Versions this library reads (version 1 roots read the same; resuming one with this version
is refused, as any change of parameters is).
"""
KINDS: tuple[str, ...] = ("hand-hand", "hand-object", "hand-chain")
"""Scene kinds of INTER-SH (``"mixed"`` in
[`make_sample`][handmesh_tutorial.scenes.make_sample] draws one per sample)."""
META_FILE = "meta.json"
SAMPLES_DIR = "samples"
_TMP_PREFIX = ".tmp-"
_LOCK_FILE = ".generate.lock"
MIN_INDEX_WIDTH = 6
MAX_SAMPLES = 100_000_000
"""Largest ``num_samples`` a ``meta.json`` may declare (the paper's set is 40,000; a corrupt
or hostile file must not make the reader build a list of 1e11 indices).
"""
MAX_LABEL = 65535
MAX_IMAGE_SIZE = _MAX_IMAGE_SIZE
"""Largest image side (pixels) of a sample, written or read: the library's one image-size bound,
[`budget.MAX_IMAGE_SIZE`][handmesh_tutorial.budget.MAX_IMAGE_SIZE]. A reader checks a PNG's size
before decoding it, so a crafted file cannot make it decode gigapixels (a decompression bomb).
"""

# Plausibility ranges: finite but absurd values (a damaged or hostile file) are refused by the
# reader, so that `verify_dataset` and ``--skip-bad`` find them. Generous on purpose.
MAX_DISTANCE_M = 10.0
"""Largest ``|x|``, ``|y|`` or ``|z|`` (metres, camera frame) of a vertex or joint: the bodies of
an image are within metres of its camera (the generator's are within about 1 m)."""
MIN_DEPTH_M = 0.001
"""Smallest ``z`` (metres) of a hand's vertex or joint: a hand in the image is in front of the
camera (the projection divides by ``z``)."""
FOCAL_RANGE = (0.1, 100.0)
"""``fx`` and ``fy`` of ``K`` as multiples of the image's larger side: fields of view from about
157 degrees down to 0.6 (the generator's are about 1.6, FreiHAND's about 2)."""
PRINCIPAL_POINT_MARGIN = 5.0
"""``cx`` (``cy``) of ``K`` may lie up to this many image widths (heights) outside the image (a
crop of a larger photo moves it off-centre)."""

_ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # fixed zip entry date: np.savez would store the wall clock
_PNG_LEVEL = 6
_JSON_KW = {"indent": 1, "sort_keys": True, "ensure_ascii": False, "allow_nan": False}
_KNOWN_KEYS = frozenset({
    "image", "scene_mask", "alone_masks", "alone_images", "meshes", "joints", "K", "vr", "kind",
    "target", "sides", "names", "pose", "stats", "index", "seed", "attempt",
})


def _fail(where: str, what: str) -> ValueError:
    return ValueError(f"{where}: {what}")


_ASCII_NUMBER = re.compile(r"[0-9]{1,18}")
"""A label or a sample folder's name: ASCII digits only (``str.isdigit`` also takes ``"²"``,
``"٣"`` or ``"５"``, which would name one sample twice or fail in ``int``)."""


def _sample_index(name: str, width: int | None = None) -> int | None:
    """The index a sample folder's name stands for, or ``None`` when the name is not a sample
    number: ASCII digits only, and exactly ``width`` of them when given (``meta.json``'s
    ``index_width``: ``"3"`` and ``"000003"`` cannot both be sample 3)."""
    if _ASCII_NUMBER.fullmatch(name) is None or (width is not None and len(name) != width):
        return None
    return int(name)


def _label(key: Any, where: str) -> int:
    if isinstance(key, str) and _ASCII_NUMBER.fullmatch(key):
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


def _check_points(p: np.ndarray, where: str, hand: bool) -> None:
    """Refuse coordinates beyond `MAX_DISTANCE_M` and, for a hand, depths below `MIN_DEPTH_M`."""
    far = float(np.abs(p).max(initial=0.0))
    if far > MAX_DISTANCE_M:
        raise _fail(where, f"holds a coordinate of {far:.3g} m, beyond +-{MAX_DISTANCE_M:g} m of "
                           "the camera (MAX_DISTANCE_M): a damaged or foreign file")
    if hand and p.size and float(p[:, 2].min()) < MIN_DEPTH_M:
        raise _fail(where, f"has a hand point at z = {float(p[:, 2].min()):.3g} m, not in front "
                           f"of the camera (z >= {MIN_DEPTH_M:g} m, MIN_DEPTH_M)")


def _check_camera(K: np.ndarray, hw: Sequence[int], where: str) -> None:
    """Refuse a ``K`` that is not an OpenCV pinhole matrix of plausible focal lengths
    (`FOCAL_RANGE`) and principal point (`PRINCIPAL_POINT_MARGIN`) for an image of ``hw``."""
    h, w = (int(x) for x in hw)
    if K[0, 1] != 0 or K[1, 0] != 0 or tuple(K[2]) != (0.0, 0.0, 1.0):
        raise _fail(where, f"is not a pinhole matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]: "
                           f"{np.round(K, 6).tolist()}")
    side, (lo, hi) = max(h, w), FOCAL_RANGE
    fx, fy, cx, cy = (float(K[i, j]) for i, j in ((0, 0), (1, 1), (0, 2), (1, 2)))
    if not (lo * side <= fx <= hi * side and lo * side <= fy <= hi * side):
        raise _fail(where, f"focal lengths fx={fx:.6g}, fy={fy:.6g} px are outside [{lo:g}, "
                           f"{hi:g}] x the image's larger side {side} px (FOCAL_RANGE): a "
                           "singular or absurd camera")
    m = PRINCIPAL_POINT_MARGIN
    if not (-m * w <= cx <= (1 + m) * w and -m * h <= cy <= (1 + m) * h):
        raise _fail(where, f"principal point ({cx:.6g}, {cy:.6g}) px lies more than {m:g} image "
                           f"sizes outside the {w} x {h} image (PRINCIPAL_POINT_MARGIN)")


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
    if max(hw) > MAX_IMAGE_SIZE:
        raise _fail(loc("image"), f"size {hw} exceeds MAX_IMAGE_SIZE {MAX_IMAGE_SIZE} pixels")
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
    for lab, (v, _) in s["meshes"].items():
        _check_points(v, loc(f"vertices_{lab}"), hand=lab in sides)
    for lab, j in s["joints"].items():
        _check_points(j, loc(f"joints_{lab}"), hand=True)
    s["K"] = _array(sample["K"], loc("K"), (3, 3), "f", np.float64)
    _check_camera(s["K"], hw, loc("K"))
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
