"""Training crops as torch Datasets: one target hand per item, cropped, mirrored, augmented.

[`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset] turns a raw sample
(image, ``K``, target mesh and joints in the camera frame, side, VR) into a dict of tensors with
the transforms of [`augment`][handmesh_tutorial.data.augment] (paper normalisation, left -> right
mirroring, one affine warp ``A K R_z K^-1``, colour jitter); the readers
[`InterSHTorchDataset`][handmesh_tutorial.data.torch_views.InterSHTorchDataset] (INTER-SH
roots or in-memory samples) and
[`FreiHANDTorchDataset`][handmesh_tutorial.data.torch_views.FreiHANDTorchDataset] supply the raw
samples. The bad-item helpers leave unreadable samples out of a run.

This module loads torch; ``handmesh_tutorial.data`` imports it only on first use of one of its
names, and ``handmesh_tutorial.data.augment`` re-exports them the same way. Taught in notebook 08
("Training").

Why one file: the readers are a few lines each over the one crop of `HandCropDataset`, and the
bad-item helpers act on those datasets; together they are the one path from a sample to a batch.
"""

from __future__ import annotations

import copy
import math
import os
import zipfile
from collections.abc import Sequence

import numpy as np
import torch

from .._untrusted import open_npz
from ..metrics import ROOT_INDEX
from ..render.camera import project
from .augment import (
    IMAGE_MEAN,
    IMAGE_STD,
    AugmentConfig,
    color_jitter,
    crop_transform,
    flip_intrinsics,
    rotation_z,
    warp_image,
)
from .files import ANNOTATION_MAX_BYTES
from .freihand import FreiHAND
from .reader import InterSHDataset
from .schema import _check_points

__all__ = [
    "HandCropDataset", "BAD_SAMPLE_ERRORS", "BadSampleError", "find_bad_items", "drop_bad_items",
    "without_items", "InterSHTorchDataset", "FreiHANDTorchDataset",
]


class HandCropDataset(torch.utils.data.Dataset):
    """Base class: one target hand per item, cropped, mirrored to the right, augmented.

    Subclasses implement
    [`load`][handmesh_tutorial.data.torch_views.HandCropDataset.load] (raw sample -> image, K,
    vertices, joints, side, VR).

    Items are dicts of tensors:

    * ``image`` ``(3, S, S)`` float32, normalised ``x / 255 - 0.5``;
    * ``vertices`` ``(V, 3)`` and ``joints`` ``(21, 3)`` float32, metres: the target hand in the
      (mirrored, rotated) camera frame of the crop, minus ``root``;
    * ``root`` ``(3,)`` the target's joint 9 in that frame (add it back to un-centre);
    * ``R`` ``(3, 3)`` the augmentation rotation (identity when not training);
    * ``K`` ``(3, 3)`` intrinsics of the crop (``uv = project(vertices + root, K)`` lands on the
      hand in ``image``);
    * ``vr`` float32 scalar, the target's visibility ratio (NaN when unknown);
    * ``mirrored`` bool scalar, the sample was a left hand flipped to the right;
    * ``index`` int64 scalar, position in the underlying reader.

    [`to_camera`][handmesh_tutorial.data.augment.to_camera] maps network-frame points back to the
    source camera frame.

    Args:
        image_size: crop side ``S``, pixels.
        train: random augmentation on (``False``: the deterministic crop of the target's box).
        seed: base seed of the augmentation (item ``i`` of epoch ``e`` uses
            ``default_rng([seed, e, i])``).
        augment: ranges ([`AugmentConfig`][handmesh_tutorial.data.augment.AugmentConfig]);
            ``None`` = defaults; ``False`` = none even when training.
        crop: ``"bbox"`` = square box around the projected target mesh, ``box_scale`` times its
            larger side; ``"full"`` = the whole image (FreiHAND images are hand-centred crops).
        box_scale: margin of the ``"bbox"`` crop.
        mirror_left: flip left targets to the right (``False`` keeps them as they are).
        indices: optional subset (positions in the underlying reader) this dataset exposes.
        cache: keep the decoded raw samples in memory (per process; small data sets only).
    """

    def __init__(self, image_size: int = 128, train: bool = True, seed: int = 0,
                 augment: AugmentConfig | bool | None = None, crop: str = "bbox",
                 box_scale: float = 1.5, mirror_left: bool = True,
                 indices: Sequence[int] | None = None, cache: bool = False):
        if int(image_size) < 2:
            raise ValueError(f"image_size must be >= 2, got {image_size}")
        if crop not in ("bbox", "full"):
            raise ValueError(f"crop must be 'bbox' or 'full', got {crop!r}")
        if augment is None or augment is True:
            augment = AugmentConfig()
        elif augment is False:
            augment = AugmentConfig.none()
        if not isinstance(augment, AugmentConfig):
            raise ValueError(f"augment must be an AugmentConfig, a bool or None, got "
                             f"{type(augment).__name__}")
        self.image_size = int(image_size)
        self.train = bool(train)
        self.seed = int(seed)
        self.augment = augment
        self.crop = crop
        self.box_scale = float(box_scale)
        self.mirror_left = bool(mirror_left)
        self.epoch = 0
        self._indices = None if indices is None else [int(i) for i in indices]
        self._cache: dict[int, tuple] | None = {} if cache else None

    list_bad_hint = "--skip-bad lists each one it leaves out"  # how a user lists bad samples

    # -- subclass interface ------------------------------------------------------------------
    def num_raw(self) -> int:
        """Number of samples of the underlying reader."""
        raise NotImplementedError

    def load(self, index: int) -> tuple:
        """Raw sample ``index`` of the reader.

        Returns:
            ``(image (H, W, 3) uint8, K (3, 3), vertices (V, 3) m, joints (21, 3) m,
            side "left" | "right", vr float)``, camera frame.
        """
        raise NotImplementedError

    def sample_name(self, index: int) -> str:
        """The name of raw sample ``index`` that errors and ``--skip-bad`` lists show: its folder
        or file name where the reader has one (``"000015"``), else ``str(index)``."""
        return str(index)

    # -- torch Dataset -----------------------------------------------------------------------
    def set_epoch(self, epoch: int) -> None:
        """Select the augmentation draws of ``epoch`` (call before iterating each epoch)."""
        self.epoch = int(epoch)

    @property
    def indices(self) -> list[int]:
        """Positions in the underlying reader, in item order."""
        return list(range(self.num_raw())) if self._indices is None else list(self._indices)

    def __len__(self) -> int:
        return self.num_raw() if self._indices is None else len(self._indices)

    def _raw(self, index: int) -> tuple:
        if self._cache is None:
            return self.load(index)
        if index not in self._cache:
            self._cache[index] = self.load(index)
        return self._cache[index]

    def __getitem__(self, i: int) -> dict:
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"item {i} out of range for {n} items")
        index = self.indices[i] if self._indices is not None else int(i) % n
        try:
            image, K, verts, joints, side, vr = self._raw(index)
            rng = np.random.default_rng([self.seed, self.epoch, index]) if self.train else None
            return self.make_item(image, K, verts, joints, side, vr, rng, index)
        except BAD_SAMPLE_ERRORS as e:  # also a crop the sample's values make impossible
            name = self.sample_name(index)
            raise BadSampleError(f"sample {name}: {e} (leave such samples out with "
                                 f"skip_bad=True / --skip-bad; {self.list_bad_hint})",
                                 index=index, reason=str(e), sample=name) from e

    def make_item(self, image, K, vertices, joints, side: str, vr: float,
                  rng: np.random.Generator | None, index: int = -1) -> dict:
        """Crop, mirror and augment one raw sample (the work behind ``ds[i]``).

        Args:
            image: ``(H, W, 3)`` uint8.
            K: ``(3, 3)`` intrinsics of ``image``.
            vertices: ``(V, 3)`` target mesh, camera frame, metres.
            joints: ``(21, 3)`` target keypoints, camera frame, metres (FreiHAND order).
            side: ``"left"`` or ``"right"``.
            vr: the target's visibility ratio (NaN if unknown).
            rng: generator of the augmentation draws; ``None`` = no augmentation.
            index: stored as ``index``.

        Returns:
            The item dict (see the class docstring).

        Shapes:
            ``image (H, W, 3)``, ``K (3, 3)``, ``vertices (V, 3)``, ``joints (21, 3)`` -> item
            ``image (3, S, S)``, ``vertices (V, 3)``, ``joints (21, 3)``, ``K (3, 3)``.
        """
        img = np.asarray(image)
        if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            raise ValueError(f"image must be (H, W, 3) uint8, got {img.shape} {img.dtype}")
        h, w = img.shape[:2]
        k = np.asarray(K, dtype=np.float64)
        v = np.asarray(vertices, dtype=np.float64)
        j = np.asarray(joints, dtype=np.float64)
        if k.shape != (3, 3):
            raise ValueError(f"K must be (3, 3), got {k.shape}")
        if v.ndim != 2 or v.shape[1] != 3 or j.shape != (21, 3):
            raise ValueError(f"vertices must be (V, 3) and joints (21, 3), got {v.shape}, "
                             f"{j.shape}")
        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        pix = torch.from_numpy(np.array(img)).permute(2, 0, 1).float() / 255.0  # copy: writable

        mirrored = side == "left" and self.mirror_left
        if mirrored:
            pix = pix.flip(-1)
            k = flip_intrinsics(k, w)
            v, j = v * [-1.0, 1.0, 1.0], j * [-1.0, 1.0, 1.0]

        a = self.augment
        angle = 0.0
        scale, shift = 1.0, np.zeros(2)
        if rng is not None:  # fixed draw order: geometry, then colour
            angle = math.radians(a.rotation) * rng.uniform(-1.0, 1.0)
            scale = 2.0 ** (a.scale * rng.uniform(-1.0, 1.0))
            shift = a.shift * rng.uniform(-1.0, 1.0, 2)
        rot = rotation_z(angle)
        v, j = v @ rot.T, j @ rot.T
        rot_img = k @ rot @ np.linalg.inv(k)  # image motion of the 3D rotation (affine)
        rot_img[2] = [0.0, 0.0, 1.0]  # exact: K R_z K^-1 has last row 0 0 1 (K upper triangular)

        if self.crop == "bbox":
            uv = project(v, k)
            lo, hi = uv.min(0), uv.max(0)
            center, side_px = (lo + hi) / 2.0, max(float((hi - lo).max()), 1.0) * self.box_scale
        else:
            c = rot_img @ np.array([(w - 1) / 2.0, (h - 1) / 2.0, 1.0])
            center, side_px = c[:2], float(max(w, h))
        side_px *= scale
        center = center + shift * side_px
        crop = crop_transform(center, side_px, self.image_size)
        warp = crop @ rot_img
        k_crop = crop @ k
        out = warp_image(pix, warp, self.image_size)

        if rng is not None and (a.brightness or a.contrast or a.saturation or a.hue):
            out = color_jitter(out, 1.0 + a.brightness * rng.uniform(-1, 1),
                               1.0 + a.contrast * rng.uniform(-1, 1),
                               1.0 + a.saturation * rng.uniform(-1, 1), a.hue * rng.uniform(-1, 1))
        root = j[ROOT_INDEX].copy()
        return {
            "image": ((out - IMAGE_MEAN) / IMAGE_STD).float(),
            "vertices": torch.as_tensor(v - root, dtype=torch.float32),
            "joints": torch.as_tensor(j - root, dtype=torch.float32),
            "root": torch.as_tensor(root, dtype=torch.float32),
            "R": torch.as_tensor(rot, dtype=torch.float32),
            "K": torch.as_tensor(k_crop, dtype=torch.float32),
            "vr": torch.tensor(float("nan") if vr is None else float(vr), dtype=torch.float32),
            "mirrored": torch.tensor(bool(mirrored)),
            "index": torch.tensor(int(index), dtype=torch.int64),
        }

    def target_shape(self, i: int) -> np.ndarray:
        """Item ``i``'s target mesh up to a rotation and translation: ``(V, 3)`` float64 metres,
        mirrored to a right hand like the item (what shape statistics such as
        [`mean_hand`][handmesh_tutorial.train.mean_hand] need; subclasses read it without the
        image)."""
        return self[i]["vertices"].double().numpy()

    def vr_values(self) -> np.ndarray:
        """Target VR of every item, ``(N,)`` float64 (NaN when unknown)."""
        return np.array([self._raw(i)[5] for i in self.indices], dtype=np.float64)


BAD_SAMPLE_ERRORS = (ValueError, KeyError, OSError, EOFError, zipfile.BadZipFile, TypeError,
                     IndexError, AttributeError, RecursionError)
"""What a reader raises for a sample whose files are missing, unreadable, inconsistent or
implausible. The INTER-SH readers raise only ``ValueError`` and ``OSError`` (they convert the
rest); the others cover a custom dataset's ``load``. ``np.linalg.LinAlgError`` is a
``ValueError``."""


class BadSampleError(ValueError):
    """A sample of a dataset cannot be read; the message names the sample and its file.

    Attributes:
        index: the sample's position in the underlying reader (``None`` when unknown).
        reason: what is wrong with it (the reader's message, naming the file).
        sample: the sample's name
            ([`sample_name`][handmesh_tutorial.data.torch_views.HandCropDataset.sample_name]:
            the folder ``"000015"`` of an INTER-SH sample); ``None`` when unknown.
    """

    def __init__(self, message: str, index: int | None = None, reason: str | None = None,
                 sample: str | None = None):
        super().__init__(message)
        self.index = index
        self.reason = message if reason is None else reason
        self.sample = sample


def find_bad_items(dataset, progress: bool = False, desc: str = "checking samples") -> list:
    """Items of ``dataset`` that cannot be loaded, with the reason.

    Loads every item once (all of ``dataset[i]``: files, checks, crop), so that a run over
    the remaining items cannot stop on a bad sample. Costs one pass over the data.

    Args:
        dataset: any map-style dataset (a ``HandCropDataset``, a ``torch.utils.data.Subset``...).
        progress: tqdm bar.
        desc: the bar's label.

    Returns:
        ``[{"position": i, "index": reader index or i, "sample": name, "error": message}, ...]``
        in item order; ``position`` is the item's position in ``dataset``, ``index`` the
        sample's position in the underlying reader, ``sample`` its name (the folder that
        ``handmesh verify`` lists, e.g. ``"000015"``; ``str(index)`` when the reader has none).
    """
    from .._progress import progress_bar

    bad = []
    for i in progress_bar(range(len(dataset)), desc=desc, disable=not progress, leave=False):
        try:
            dataset[i]
        except BAD_SAMPLE_ERRORS as e:
            index = getattr(e, "index", None)
            index = i if index is None else int(index)
            bad.append({"position": i, "index": index,
                        "sample": getattr(e, "sample", None) or str(index),
                        "error": getattr(e, "reason", str(e))})
    return bad


def drop_bad_items(dataset, progress: bool = False, name: str = "dataset", *,
                   allow_empty: bool = False):
    """``(dataset without its bad items, the bad items)``.

    [`find_bad_items`][handmesh_tutorial.data.torch_views.find_bad_items], then
    [`without_items`][handmesh_tutorial.data.torch_views.without_items].

    Args:
        dataset: any map-style dataset.
        progress: tqdm bar.
        name: what the set is, for the bar and the error (``"training"``, ``"evaluation"``...).
        allow_empty: return an empty dataset when every item is bad instead of raising.

    Raises:
        ValueError: every item is bad (unless ``allow_empty``); the message gives the first error.
    """
    bad = find_bad_items(dataset, progress, desc=f"checking {name} samples")
    if not bad:
        return dataset, bad
    kept = without_items(dataset, [b["position"] for b in bad])
    if len(kept) == 0 and not allow_empty:
        raise ValueError(f"every {name} sample is bad ({len(bad)} skipped; first: "
                         f"{bad[0]['error']})")
    return kept, bad


def without_items(dataset, positions):
    """``dataset`` without the items at ``positions``.

    ``positions`` are usually those of
    [`find_bad_items`][handmesh_tutorial.data.torch_views.find_bad_items].

    A ``HandCropDataset`` stays one (a shallow copy with fewer ``indices``: its augmentation
    seeds, ``vr_values`` and ``target_shape`` keep working); any other dataset becomes a
    ``torch.utils.data.Subset``. The input is not changed.
    """
    drop = {int(p) for p in positions}
    keep = [i for i in range(len(dataset)) if i not in drop]
    if isinstance(dataset, HandCropDataset):
        out = copy.copy(dataset)
        idx = dataset.indices
        out._indices = [idx[i] for i in keep]
        return out
    return torch.utils.data.Subset(dataset, keep)


class InterSHTorchDataset(HandCropDataset):
    """INTER-SH scenes as training crops of their target hand (see
    [`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset]).

    Args:
        root_or_dataset: an INTER-SH root folder, an
            [`InterSHDataset`][handmesh_tutorial.data.reader.InterSHDataset], or any sequence of
            INTER-SH sample dicts (e.g. a list of
            [`synthetic_sample`][handmesh_tutorial.testing.synthetic_sample] outputs, for in-memory
            experiments).
        image_size: crop side, pixels.
        train: augmentation on.
        seed: augmentation seed.
        augment: see [`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset].
        **kwargs: ``crop``, ``box_scale``, ``mirror_left``, ``indices``, ``cache``.

    Raises:
        FileNotFoundError: the root has no ``meta.json``.
    """

    def __init__(self, root_or_dataset, image_size: int = 128, train: bool = True,
                 seed: int = 0, augment: AugmentConfig | bool | None = None, **kwargs):
        if isinstance(root_or_dataset, str | os.PathLike):
            root_or_dataset = InterSHDataset(root_or_dataset)
        self.source = root_or_dataset
        super().__init__(image_size, train, seed, augment, **kwargs)

    @property
    def list_bad_hint(self) -> str:  # type: ignore[override]  # verify reads INTER-SH roots
        root = getattr(self.source, "root", None)
        return super().list_bad_hint if root is None else f"list them with handmesh verify {root}"

    def num_raw(self) -> int:
        return len(self.source)

    def sample_name(self, index: int) -> str:
        if hasattr(self.source, "sample_dir"):
            return self.source.sample_dir(index).name
        return super().sample_name(index)

    def load(self, index: int) -> tuple:
        if isinstance(self.source, InterSHDataset) and self.source.transform is None:
            return self.source.target(index)  # lean read: no masks, no other bodies
        s = self.source[index]
        t = s["target"]
        if t not in s["meshes"] or t not in s["joints"]:
            raise ValueError(f"sample {index}: target {t!r} has no mesh or joints "
                             f"(meshes {sorted(s['meshes'])}, joints {sorted(s['joints'])})")
        vr = s.get("vr", {}).get(t, float("nan"))
        return (s["image"], s["K"], s["meshes"][t][0], s["joints"][t], s["sides"][t],
                float("nan") if vr is None else float(vr))

    def target_shape(self, i: int) -> np.ndarray:
        """See
        [`HandCropDataset.target_shape`][handmesh_tutorial.data.torch_views.HandCropDataset.target_shape];
        reads only the annotation of an on-disk
        root (no image)."""
        if not hasattr(self.source, "sample_dir"):
            return super().target_shape(i)
        index = self.indices[i]
        ann = self.source.annotation(index)
        t = ann["target"]
        path = self.source.sample_dir(index) / "annotation.npz"
        with open_npz(path, ANNOTATION_MAX_BYTES) as z:
            key = f"vertices_{t}"
            if key not in z.files:
                raise ValueError(f"{path}: no {key!r} (keys {sorted(z.files)})")
            v = z[key].astype(np.float64)
        if v.ndim != 2 or v.shape[1:] != (3,) or not np.isfinite(v).all():
            raise ValueError(f"{path}: key {key!r} has shape {v.shape} or non-finite values")
        _check_points(v, f"{path}: key {key!r}", hand=True)  # the reader's plausibility range
        if ann["sides"][t] == "left" and self.mirror_left:
            v = v * np.array([-1.0, 1.0, 1.0])
        return v

    @classmethod
    def network_input(cls, sample: dict, image_size: int = 128, **kwargs) -> dict:
        """One sample dict (``make_sample``, ``InterSHDataset(root)[i]``) -> its network input.

        The evaluation crop of its target hand, without augmentation: ``item["image"]``
        ``(3, S, S)`` float32 (``x / 255 - 0.5``, a left hand mirrored), so
        ``net(item["image"][None])`` runs the network on it; ``vertices``, ``joints``
        (root-relative, metres) are its targets in the crop's frame.

        Args:
            sample: an INTER-SH sample dict.
            image_size: crop side (the shipped network's 128).
            **kwargs: ``box_scale``, ``mirror_left``, ``crop`` (see the class).

        Returns:
            The item dict of ``InterSHTorchDataset([sample], image_size, train=False)[0]``.
        """
        return cls([sample], image_size, train=False, **kwargs)[0]

    def vr_values(self) -> np.ndarray:
        """Target VR of every item (reads only ``annotation.json`` for an on-disk root)."""
        if hasattr(self.source, "vr_table"):
            return np.asarray(self.source.vr_table(), dtype=np.float64)[self.indices]
        return super().vr_values()


class FreiHANDTorchDataset(HandCropDataset):
    """FreiHAND images (right hands, MANO topology) as training crops.

    FreiHAND images are already 224 x 224 crops centred on the hand, so the default crop is the
    whole image (``crop="full"``); augmentation rotates, zooms and shifts around it. FreiHAND has
    no visibility ratio (``vr`` is NaN) and no left hands (``mirrored`` is always False).

    Args:
        root_or_reader: a FreiHAND root or [`FreiHAND`][handmesh_tutorial.data.freihand.FreiHAND].
        split: ``"training"`` or ``"evaluation"`` (when a root is given).
        image_size: crop side, pixels.
        train: augmentation on.
        seed: augmentation seed.
        augment: see [`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset].
        versions: training sample versions (see ``FreiHAND``).
        **kwargs: ``crop`` (default ``"full"``), ``box_scale``, ``indices``, ``cache``.

    Raises:
        ValueError: the split has no vertex or keypoint annotations.
    """

    def __init__(self, root_or_reader, split: str = "training", image_size: int = 128,
                 train: bool = True, seed: int = 0, augment: AugmentConfig | bool | None = None,
                 versions=None, **kwargs):
        if isinstance(root_or_reader, str | os.PathLike):
            root_or_reader = FreiHAND(root_or_reader, split, versions)
        self.source = root_or_reader
        for key, what in (("xyz", "keypoints"), ("verts", "vertices")):
            if root_or_reader.annotation(key) is None:
                raise ValueError(f"FreiHAND {root_or_reader.split} split has no {what} "
                                 f"({root_or_reader.annotation_path(key)}); it cannot be used "
                                 "for training or evaluation here")
        kwargs.setdefault("crop", "full")
        super().__init__(image_size, train, seed, augment, **kwargs)

    def num_raw(self) -> int:
        return len(self.source)

    def sample_name(self, index: int) -> str:
        return self.source.image_path(index).stem

    def load(self, index: int) -> tuple:
        s = self.source[index]
        return s["image"], s["K"], s["vertices"], s["joints"], "right", float("nan")
