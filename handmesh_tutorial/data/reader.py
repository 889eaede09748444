"""Reading an INTER-SH root: ``meta.json``, the lazy map-style reader, and verification.

[`InterSHDataset`][handmesh_tutorial.data.reader.InterSHDataset] is numpy-only; the torch
training crops built on it are in [`torch_views`][handmesh_tutorial.data.torch_views]. Taught
in notebook 05 ("Rendering and the visibility ratio"), used from notebook 08 ("Training") on.

Why one file: the lazy reader and `verify` count a root's planned, present and missing samples
with the same functions; apart, the two could disagree on what a root holds.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .files import _own_folder, _read_json, _read_target, read_annotation, read_sample
from .schema import (
    FORMAT_NAME,
    KINDS,
    MAX_IMAGE_SIZE,
    MAX_SAMPLES,
    META_FILE,
    MIN_INDEX_WIDTH,
    READABLE_FORMAT_VERSIONS,
    SAMPLES_DIR,
    _sample_index,
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


def _present(samples_dir: Path, width: int) -> list[int]:
    """Indices of the sample folders in ``samples_dir``: real folders (`files._own_folder`: a
    link is none) named by exactly ``width`` ASCII digits (`schema._sample_index`); anything
    else there is not a sample of the set. Every reader of a root counts samples here."""
    if not samples_dir.is_dir():
        return []
    found = ((_sample_index(p.name, width), p) for p in samples_dir.iterdir())
    return sorted(i for i, p in found if i is not None and _own_folder(p))


def _planned(meta: Mapping) -> list[int]:
    return [i for a, b in meta["ranges"] for i in range(a, b)]


def _missing(meta: Mapping, have: set[int]) -> tuple[int, int, list[str]]:
    """``(planned, missing, first names)``: how many samples ``meta.json`` plans, how many of
    them are not in ``have``, and the folder names of the first five (a walk that stops there:
    bounded by ``len(have)``, not by the plan, which may be 1e8)."""
    width = meta.get("index_width", MIN_INDEX_WIDTH)
    planned = sum(b - a for a, b in meta["ranges"])
    here = sum(1 for i in have if any(a <= i < b for a, b in meta["ranges"]))
    first: list[str] = []
    for i in (i for a, b in meta["ranges"] for i in range(a, b)) if here < planned else ():
        if i not in have:
            first.append(f"{i:0{width}d}")
            if len(first) == 5:
                break
    return planned, planned - here, first


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
        self.indices = np.asarray(_present(self.root / SAMPLES_DIR,
                                           self.meta.get("index_width", MIN_INDEX_WIDTH)),
                                  dtype=np.int64)
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
    def num_planned(self) -> int:
        """How many samples ``meta.json`` plans (its ranges)."""
        return sum(b - a for a, b in self.meta["ranges"])

    def coverage(self) -> str:
        """What a reader of this root must say about it: ``""`` when every planned sample is
        present, else one sentence such as ``"root: 4 of 6 planned samples present (first
        missing 000001, 000003); ..."`` naming why they may be missing (``samples`` is no
        folder, or a ``generate`` is writing the root now). Used by ``evaluate`` (a note, and
        "scored N of M planned") and ``train`` (refused when none is present)."""
        from .._io import is_locked
        from .schema import _LOCK_FILE

        planned, missing, first = _missing(self.meta, set(self.indices.tolist()))
        if not missing:
            return ""
        samples = self.root / SAMPLES_DIR
        why = ("; " + f"{samples} is not a folder" if not _own_folder(samples)
               else "; a `handmesh generate` is writing it now" if is_locked(self.root / _LOCK_FILE)
               else "; rerun the `handmesh generate` command that made it to finish it")
        return (f"{self.root}: {planned - missing} of {planned} planned samples present "
                f"(first missing {', '.join(first)}){why}")

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
        ``(image, K, vertices, joints, side, vr)``. ``transform`` is not applied.

        Raises:
            ValueError: as ``ds[i]``: the sample is damaged, or disagrees with ``meta.json``
                (kind, image size, seed rule, index), so a foreign sample is never trained on.
        """
        d = self.sample_dir(i)
        target, ann = _read_target(d)
        _refuse_disagreements(ann, d, self.meta)  # the same checks as the full read
        return target

    def __getitem__(self, i: int) -> Any:
        d = self.sample_dir(i)
        s = read_sample(d)
        _refuse_disagreements({**s, "image_size": list(s["image"].shape[:2])}, d, self.meta)
        return self.transform(s) if self.transform is not None else s

    def vr_table(self) -> np.ndarray:
        """VR of the target hand of every sample, (N,) float64 (reads only the JSON files)."""
        if self._vr is None:
            anns = (self.annotation(i) for i in range(len(self)))
            self._vr = np.array([a["vr"][a["target"]] for a in anns], dtype=np.float64)
        return self._vr


def _disagreements(fields: Mapping, folder: Path, meta: Mapping) -> list[tuple[str, str]]:
    """Where a sample that reads correctly disagrees with ``meta.json`` or its folder's name.

    One check for every reader of a root (the full read ``ds[i]``, the lean training read
    ``ds.target(i)``, `verify_dataset`, and `generate_dataset` resuming), so that no path takes
    a sample the others refuse.

    Args:
        fields: the sample's ``index``, ``seed``, ``attempt``, ``kind`` and ``image_size``
            ([H, W]): a validated ``annotation.json``
            ([`read_annotation`][handmesh_tutorial.data.files.read_annotation]) or a sample
            dict with ``image_size`` added.
        folder: the sample's folder (its name is its index).
        meta: the root's ``meta.json`` (`read_meta`).

    Returns:
        ``[(key, message)]``: the ``meta.json`` key (``"index"`` for the folder's name) and a
        message naming the file.
    """
    out = []
    ann, name = folder / "annotation.json", folder.name
    index = _sample_index(name)
    if index is None:
        return [("index", f"{folder}: not a sample number (ASCII digits)")]
    if fields.get("index") is not None and fields["index"] != index:
        out.append(("index", f"{ann}: index {fields['index']} but folder is {name}"))
    width = meta.get("index_width", MIN_INDEX_WIDTH)
    if len(name) != width:
        out.append(("index_width", f"{folder}: a {len(name)}-digit folder name, meta.json "
                                   f"index_width {width}"))
    if not any(a <= index < b for a, b in meta["ranges"]):
        out.append(("ranges", f"{folder}: index {index} outside meta.json ranges "
                              f"{str(meta['ranges'])[:80]}"))
    if fields.get("kind") not in meta["kinds"]:
        out.append(("kinds", f"{ann}: kind {fields.get('kind')!r} not in meta.json kinds "
                             f"{meta['kinds']}"))
    size = meta.get("image_size")
    if size is not None and list(fields.get("image_size") or []) != list(size):
        out.append(("image_size", f"{folder / 'image.png'}: size "
                                  f"{list(fields.get('image_size') or [])}, meta.json "
                                  f"image_size {size}"))
    seed, attempt = fields.get("seed"), fields.get("attempt")
    if seed is not None and attempt is not None and "seed" in meta:
        want = sample_seed(meta["seed"], index, int(attempt))
        if int(seed) != want:
            out.append(("seed", f"{ann}: seed {seed}, the seed rule of meta.json (seed "
                                f"{meta['seed']}) gives {want}"))
    return out


def _refuse_disagreements(fields: Mapping, folder: Path, meta: Mapping) -> None:
    """Raise the first of `_disagreements` as a ``ValueError`` naming the file (a foreign or
    mislabelled sample is a bad sample for ``--skip-bad``, never read as one of the set)."""
    found = _disagreements(fields, folder, meta)
    if found:
        raise ValueError(f"{found[0][1]} (a sample of another set, or an edited meta.json: "
                         "`handmesh verify` lists them)")


@dataclass
class VerifyReport:
    """Outcome of [`verify_dataset`][handmesh_tutorial.data.reader.verify_dataset].

    Attributes:
        root: the dataset folder.
        checked: sample entries read (entries of ``samples/`` named by ASCII digits).
        bad: ``[(folder name, reason)]`` of the samples that cannot be read on their own
            (missing, damaged or implausible files), sorted by name.
        removed: the bad sample folders deleted (``remove=True``): only folders named by an
            index that ``meta.json`` plans (its ``ranges``, ``index_width`` digits), so that
            rerunning the ``generate`` command that made the root writes exactly these again,
            with the same bytes as before.
        disagree: ``[(folder name, meta.json key, reason)]`` of the samples that read correctly
            but disagree with ``meta.json`` (``seed``, ``image_size``, ``kinds``, ``ranges``,
            ``index_width``) or with their folder's name (``index``). Never removed: either
            ``meta.json`` or the samples are wrong, and only the user knows which.
        kept: ``[(folder name, why)]`` of the bad entries a repair leaves as they are: a file
            where a folder belongs, a folder of an index the root does not plan, a folder that
            also holds files no sample has, one a permission error hid, or one that could not
            be removed (the error).
        foreign: ``[(entry name, what)]`` of the entries of ``samples/`` that are no sample
            (not named by ASCII digits): listed, never read, never removed.
        error: the first ``OSError`` that kept a bad sample from being removed (a read-only
            root: ``handmesh verify`` prints the report, then exits 6 naming the file), else
            ``None``.
        unplanned: the names in ``kept`` that are no sample ``meta.json`` plans (``2024`` or
            ``99`` beside 6-digit names, ``000007`` of a 7-sample set): ``generate`` neither
            counts them as done nor writes them, so a repair may go on beside them.
        planned: how many samples ``meta.json`` plans (its ``ranges``).
        missing: how many of them have no entry in ``samples/`` (a generation not finished, or
            ``samples`` missing or a file): a check (``remove=False``) is not ``ok`` with any;
            rerunning the ``generate`` command that made the root writes them.
        missing_first: the folder names of the first (at most five) missing samples.
    """

    root: Path
    checked: int
    bad: list[tuple[str, str]]
    removed: list[str]
    disagree: list[tuple[str, str, str]] = field(default_factory=list)
    kept: list[tuple[str, str]] = field(default_factory=list)
    foreign: list[tuple[str, str]] = field(default_factory=list)
    error: OSError | None = field(default=None, repr=False, compare=False)
    unplanned: list[str] = field(default_factory=list)
    planned: int = 0
    missing: int = 0
    missing_first: list[str] = field(default_factory=list)
    repair: bool = field(default=False, repr=False)

    @property
    def ok(self) -> bool:
        """Nothing left to fix: no disagreement, every bad sample removed, and (for a check, not
        a repair, which leaves them to ``generate``) no planned sample missing (entries that are
        no sample, ``foreign``, do not count)."""
        return (not self.disagree and len(self.removed) == len(self.bad)
                and (self.repair or not self.missing))

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
                 + (f", {self.missing} of {self.planned} planned samples missing (first "
                    f"{', '.join(self.missing_first)})" if self.missing else "")
                 + (f", {len({n for n, _, _ in self.disagree})} disagree with meta.json"
                    if self.disagree else "")
                 + (f", {len(self.foreign)} entries that are no sample (left as they are)"
                    if self.foreign else "")]
        lines += [f"  {name}: {why}" for name, why in self.bad]
        lines += [f"  {name}: not removed: {why}" for name, why in self.kept]
        if self.removed or self.missing:  # only planned indices: the generator writes these
            lines.append("  rerun the `handmesh generate` command that made it (same --kind, "
                         "--num, --seed, --image-size, --shard) to write the "
                         + ("removed and missing" if self.removed and self.missing else
                            "removed" if self.removed else "missing") + " samples")
        lines += [f"  {name!r}: {what}, not a sample (left as it is)"
                  for name, what in self.foreign[:20]]
        if len(self.foreign) > 20:
            lines.append(f"  and {len(self.foreign) - 20} more entries that are no sample")
        first = {}
        for _, key, why in self.disagree:
            first.setdefault(key, why)
        for key, names in self.disagreements().items():
            shown = ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8
                                            else "")
            lines.append(f"  meta.json '{key}' disagrees with {len(names)} sample(s) ({shown}); "
                         f"first: {first[key]}")
        return "\n".join(lines)


def _entry_kind(p: Path) -> str:
    """``"folder"``, ``"link"``, ``"file"`` or ``"other"`` of ``p``, links not followed."""
    if p.is_symlink():
        return "link"
    if p.is_dir():
        return "folder"
    return "file" if p.is_file() else "other"


def verify_dataset(root: str | os.PathLike, *, remove: bool = False,
                   progress: bool = True) -> VerifyReport:
    """Re-read every sample of an INTER-SH root; list the unreadable ones and those that disagree
    with ``meta.json``.

    A sample folder is *bad* when it does not read back on its own
    ([`read_sample`][handmesh_tutorial.data.files.read_sample]: every file, key, shape, dtype
    and the plausibility ranges of [`schema`][handmesh_tutorial.data.schema]), or is a file
    or a link where a folder belongs. A sample that reads correctly but disagrees with
    ``meta.json`` (kind, image size, the seed of the sample-seed rule,
    [`sample_seed`][handmesh_tutorial.data.seeds.sample_seed], index width and ranges) or
    with its folder's name is listed in ``disagree``, by key: one edited field of ``meta.json``
    makes every sample disagree, so such samples are never removed. Entries of ``samples/`` not
    named by ASCII digits are no samples: listed in ``foreign``, never read nor removed.

    A repair (``remove=True``) takes the root's writer lock (as ``generate`` does, so it never
    removes a sample under a running ``generate``) and touches only what the generator makes:
    a bad folder named by an index ``meta.json`` plans (its ``ranges``, ``index_width``
    digits), found without following links. In it, it deletes only a sample's files
    (``image.png``, ``annotation.json``...), then the folder if that left it empty; a link at
    such a name is unlinked (its target is never touched). Everything else is left and listed
    in ``kept``: a file where a folder belongs, a folder of an index the root does not plan, a
    folder that also holds other files.

    Args:
        root: the dataset folder (with ``meta.json``).
        remove: delete the bad sample folders, so that rerunning the ``generate`` command that
            made the root writes them again (not those in ``kept``, nor any in ``disagree``).
        progress: tqdm progress bar.

    Returns:
        A [`VerifyReport`][handmesh_tutorial.data.reader.VerifyReport]; ``report.ok`` tells
        whether anything is left to fix; ``report.error`` holds the first ``OSError`` that kept
        a bad sample from being removed (the report is still complete).

    Raises:
        ValueError: ``meta.json`` itself is unreadable, or with ``remove``, ``samples`` is a
            symbolic link (nothing is removed).
        RuntimeError: with ``remove``, another process writes into the root
            (`EnvironmentFailure`).
    """
    from .._io import single_writer
    from .._progress import progress_bar
    from .root import _is_own_temporary, _remove_sample_folder
    from .schema import _LOCK_FILE, _TMP_PREFIX

    root = Path(root)
    meta = read_meta(root)
    samples = root / SAMPLES_DIR
    width = meta.get("index_width", MIN_INDEX_WIDTH)
    if remove and samples.is_symlink():
        raise ValueError(f"{samples} is a symbolic link (to {os.readlink(samples)}): a repair "
                         "never works through a link, so nothing was removed; replace the link "
                         "by the folder itself, or verify without --remove-bad")
    bad: list[tuple[str, str]] = []
    disagree: list[tuple[str, str, str]] = []
    kept: list[tuple[str, str]] = []
    foreign: list[tuple[str, str]] = []
    removable: list[str] = []
    unplanned: list[str] = []
    error: OSError | None = None
    with contextlib.ExitStack() as stack:
        if remove:
            try:
                stack.enter_context(single_writer(root / _LOCK_FILE, str(root)))
            except OSError as err:  # a read-only root: read and report, remove nothing
                error = err
        entries = []
        for p in sorted(samples.iterdir()) if samples.is_dir() else []:
            if _sample_index(p.name) is not None:
                entries.append(p)
            elif not (p.name.startswith(_TMP_PREFIX) and _is_own_temporary(p)):
                foreign.append((p.name, _entry_kind(p)))
        for p in progress_bar(entries, disable=not progress, desc="verify", unit="sample"):
            index, kind = int(p.name), _entry_kind(p)
            planned = (_sample_index(p.name, width) is not None
                       and any(a <= index < b for a, b in meta["ranges"]))
            if kind != "folder":
                bad.append((p.name, f"not a sample folder (a {kind})"))
                if kind == "link" and planned:
                    removable.append(p.name)  # unlinked: its target is never touched
                elif planned:
                    kept.append((p.name, f"a {kind} where a sample folder belongs: it is not the "
                                         "generator's; move it away"))
                else:
                    kept.append((p.name, f"meta.json plans no sample {p.name}"))
                    unplanned.append(p.name)
                continue
            try:
                s = read_sample(p)
            except (ValueError, OSError) as err:  # read_sample raises no other (_named_errors)
                bad.append((p.name, str(err).splitlines()[0] if str(err) else
                            type(err).__name__))
                if isinstance(err, PermissionError):
                    kept.append((p.name, "a permission error kept it from being read"))
                elif not planned:
                    kept.append((p.name, f"meta.json plans no sample {p.name} (index_width "
                                         f"{width}, ranges {str(meta['ranges'])[:60]})"))
                    unplanned.append(p.name)
                else:
                    removable.append(p.name)
                continue
            fields = {**s, "image_size": list(s["image"].shape[:2])}
            disagree += [(p.name, key, why) for key, why in _disagreements(fields, p, meta)]
        removed = []
        for name in removable if remove else []:
            if error is not None:
                kept.append((name, str(error)))
                continue
            try:
                left = _remove_sample_folder(samples / name)
            except OSError as err:
                error = error or err
                kept.append((name, str(err)))
                continue
            if left:
                kept.append((name, f"it also holds {', '.join(map(repr, left[:5]))}, which no "
                                   "sample has: the sample's own files were removed, the rest "
                                   "left as it is"))
            else:
                removed.append(name)
    planned, missing, first = _missing(meta, {int(p.name) for p in entries
                                              if _sample_index(p.name, width) is not None})
    return VerifyReport(root=root, checked=len(entries), bad=bad, removed=removed,
                        disagree=disagree, kept=kept, foreign=foreign, error=error,
                        unplanned=unplanned, planned=planned, missing=missing,
                        missing_first=first, repair=remove)
