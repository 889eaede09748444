"""Reading an INTER-SH root: ``meta.json``, the lazy map-style reader, and verification.

[`InterSHDataset`][handmesh_tutorial.data.reader.InterSHDataset] is numpy-only; the torch
training crops built on it are in [`torch_views`][handmesh_tutorial.data.torch_views]. Taught
in notebook 05 ("Rendering and the visibility ratio"), used from notebook 08 ("Training") on.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .files import _read_json, read_annotation, read_sample, read_target
from .schema import (
    FORMAT_NAME,
    KINDS,
    MAX_IMAGE_SIZE,
    MAX_SAMPLES,
    META_FILE,
    MIN_INDEX_WIDTH,
    READABLE_FORMAT_VERSIONS,
    SAMPLES_DIR,
)
from .seeds import sample_seed

__all__ = ["read_meta", "InterSHDataset", "VerifyReport", "verify_dataset"]


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
    kinds = meta.get("kinds")
    if not isinstance(kinds, list) or not kinds or any(k not in KINDS for k in kinds):
        raise ValueError(f"{path}: 'kinds' must be a non-empty list of {list(KINDS)}, got "
                         f"{str(kinds)[:80]}")
    size = meta.get("image_size")
    if size is not None and not (isinstance(size, list) and len(size) == 2 and all(
            type(x) is int and 1 <= x <= MAX_IMAGE_SIZE for x in size)):
        raise ValueError(f"{path}: 'image_size' must be null or [height, width], integers in "
                         f"[1, {MAX_IMAGE_SIZE}], got {str(size)[:80]}")
    seed = meta.get("seed", 0)
    if type(seed) is not int or seed < 0:
        raise ValueError(f"{path}: 'seed' must be a non-negative integer, got {str(seed)[:80]}")
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

    def target(self, i: int) -> tuple:
        """Only what a training crop of sample ``i``'s target hand needs, read without the masks
        and the other bodies ([`read_target`][handmesh_tutorial.data.files.read_target]):
        ``(image, K, vertices, joints, side, vr)``. ``transform`` is not applied."""
        return read_target(self.sample_dir(i))

    def __getitem__(self, i: int) -> Any:
        d = self.sample_dir(i)
        s = read_sample(d)
        for key, why in _disagreements(s, d, self.meta):
            if key in ("index", "kinds", "image_size"):
                raise ValueError(why)
        return self.transform(s) if self.transform is not None else s

    def vr_table(self) -> np.ndarray:
        """VR of the target hand of every sample, (N,) float64 (reads only the JSON files)."""
        if self._vr is None:
            anns = (self.annotation(i) for i in range(len(self)))
            self._vr = np.array([a["vr"][a["target"]] for a in anns], dtype=np.float64)
        return self._vr


def _disagreements(s: Mapping, folder: Path, meta: Mapping) -> list[tuple[str, str]]:
    """Where a sample that reads correctly disagrees with ``meta.json`` or its folder's name.

    Returns:
        ``[(key, message)]``: the ``meta.json`` key (``"index"`` for the folder's name) and a
        message naming the file.
    """
    out = []
    ann, name = folder / "annotation.json", folder.name
    if s["index"] is not None and s["index"] != int(name):
        out.append(("index", f"{ann}: index {s['index']} but folder is {name}"))
    width = meta.get("index_width", MIN_INDEX_WIDTH)
    if len(name) != width:
        out.append(("index_width", f"{folder}: a {len(name)}-digit folder name, meta.json "
                                   f"index_width {width}"))
    if not any(a <= int(name) < b for a, b in meta["ranges"]):
        out.append(("ranges", f"{folder}: index {int(name)} outside meta.json ranges "
                              f"{str(meta['ranges'])[:80]}"))
    if s["kind"] not in meta["kinds"]:
        out.append(("kinds", f"{ann}: kind {s['kind']!r} not in meta.json kinds "
                             f"{meta['kinds']}"))
    size = meta.get("image_size")
    if size is not None and list(s["image"].shape[:2]) != list(size):
        out.append(("image_size", f"{folder / 'image.png'}: size {list(s['image'].shape[:2])}, "
                                  f"meta.json image_size {size}"))
    if s["seed"] is not None and s["attempt"] is not None and "seed" in meta:
        want = sample_seed(meta["seed"], int(name), int(s["attempt"]))
        if int(s["seed"]) != want:
            out.append(("seed", f"{ann}: seed {s['seed']}, the seed rule of meta.json (seed "
                                f"{meta['seed']}) gives {want}"))
    return out


@dataclass
class VerifyReport:
    """Outcome of [`verify_dataset`][handmesh_tutorial.data.reader.verify_dataset].

    Attributes:
        root: the dataset folder.
        checked: sample entries read.
        bad: ``[(folder name, reason)]`` of the samples that cannot be read on their own
            (missing, damaged or implausible files), sorted by name.
        removed: the bad entries deleted (``remove=True``); rerunning the same ``generate``
            call then writes exactly these again, with the same bytes as before.
        disagree: ``[(folder name, meta.json key, reason)]`` of the samples that read correctly
            but disagree with ``meta.json`` (``seed``, ``image_size``, ``kinds``, ``ranges``,
            ``index_width``) or with their folder's name (``index``). Never removed: either
            ``meta.json`` or the samples are wrong, and only the user knows which.
    """

    root: Path
    checked: int
    bad: list[tuple[str, str]]
    removed: list[str]
    disagree: list[tuple[str, str, str]] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Nothing left to fix: no disagreement, and every bad sample removed."""
        return not self.disagree and len(self.removed) == len(self.bad)

    def disagreements(self) -> dict[str, list[str]]:
        """``{meta.json key: [folder names]}`` of the disagreements, keys in order of
        appearance."""
        out: dict[str, list[str]] = {}
        for name, key, _ in self.disagree:
            out.setdefault(key, []).append(name)
        return out

    def advice(self) -> str:
        """What to do about the disagreements (one paragraph; empty when there are none)."""
        if not self.disagree:
            return ""
        keys = ", ".join(f"'{k}'" for k in self.disagreements())
        return (f"{self.root / META_FILE} disagrees with samples that read correctly "
                f"({keys}); none of them was removed. If meta.json was edited, restore those "
                f"keys; if the samples come from another run, move them out of "
                f"{self.root / SAMPLES_DIR}. Then run `handmesh verify` again.")

    def __str__(self) -> str:
        lines = [f"{self.root}: {self.checked} samples read, {len(self.bad)} bad"
                 + (f", {len(self.removed)} removed" if self.removed else "")
                 + (f", {len({n for n, _, _ in self.disagree})} disagree with meta.json"
                    if self.disagree else "")]
        lines += [f"  {name}: {why}" for name, why in self.bad]
        first = {}
        for _, key, why in self.disagree:
            first.setdefault(key, why)
        for key, names in self.disagreements().items():
            shown = ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8
                                            else "")
            lines.append(f"  meta.json '{key}' disagrees with {len(names)} sample(s) ({shown}); "
                         f"first: {first[key]}")
        return "\n".join(lines)


def verify_dataset(root: str | os.PathLike, *, remove: bool = False,
                   progress: bool = True) -> VerifyReport:
    """Re-read every sample of an INTER-SH root; list the unreadable ones and those that disagree
    with ``meta.json``.

    A sample folder is *bad* when it does not read back on its own
    ([`read_sample`][handmesh_tutorial.data.files.read_sample]: every file, key, shape, dtype
    and the plausibility ranges of [`schema`][handmesh_tutorial.data.schema]), or is a file
    where a folder belongs. A sample that reads correctly but disagrees with ``meta.json`` (kind,
    image size, the seed of the sample-seed rule,
    [`sample_seed`][handmesh_tutorial.data.seeds.sample_seed], index width and ranges) or
    with its folder's name is listed in ``disagree``, by key: one edited field of ``meta.json``
    makes every sample disagree, so such samples are never removed.

    Args:
        root: the dataset folder (with ``meta.json``).
        remove: delete the bad entries, so that rerunning the same ``generate`` regenerates them
            (not those that a permission error kept from being read, nor any in ``disagree``).
        progress: tqdm progress bar.

    Returns:
        A [`VerifyReport`][handmesh_tutorial.data.reader.VerifyReport]; ``report.ok`` tells
        whether anything is left to fix.

    Raises:
        ValueError: ``meta.json`` itself is unreadable (nothing is removed).
    """
    from .._progress import progress_bar

    root = Path(root)
    meta = read_meta(root)
    samples = root / SAMPLES_DIR
    bad: list[tuple[str, str]] = []
    disagree: list[tuple[str, str, str]] = []
    keep: set[str] = set()  # bad, but not to be removed
    entries = sorted(p for p in samples.iterdir() if p.name.isdigit()) if samples.is_dir() \
        else []
    for p in progress_bar(entries, disable=not progress, desc="verify", unit="sample"):
        if not p.is_dir() or p.is_symlink():
            bad.append((p.name, "not a sample folder (a file or link)"))
            continue
        try:
            s = read_sample(p)
        except (ValueError, OSError) as err:  # read_sample raises no other (files._named_errors)
            bad.append((p.name, str(err).splitlines()[0] if str(err) else type(err).__name__))
            if isinstance(err, PermissionError):
                keep.add(p.name)
            continue
        disagree += [(p.name, key, why) for key, why in _disagreements(s, p, meta)]
    removed = []
    if remove:
        for name, _ in bad:
            if name in keep:
                continue
            target = samples / name
            shutil.rmtree(target) if target.is_dir() and not target.is_symlink() \
                else target.unlink()
            removed.append(name)
    return VerifyReport(root=root, checked=len(entries), bad=bad, removed=removed,
                        disagree=disagree)
