"""Training crops: torch Datasets for INTER-SH and FreiHAND, augmentation, left -> right mirroring.

Paper, Sec. "Training": images are normalised with mean 0.5 and standard deviation 1.0
(``x / 255 - 0.5``), augmented "with random image crops and transformations", and the ground-truth
vertices are translated so that the middle MCP joint (FreiHAND keypoint 9) is at the origin.

One network serves both hands: the model always predicts a *right* hand. A left target is mirrored
on the way in and back on the way out ([`unmirror`][handmesh_tutorial.augment.unmirror],
[`to_camera`][handmesh_tutorial.augment.to_camera]):

* the image is flipped horizontally, ``u' = W - 1 - u`` (pixel centres at integer coordinates,
  as everywhere in this library);
* the 3D points get their camera-frame ``x`` negated, ``M = diag(-1, 1, 1)`` (a left hand seen in
  a mirror is a right hand; the hand model's left mesh is the vertex-by-vertex mirror of the right
  one, so the vertex order is kept);
* the intrinsics become ``K' = F K M`` with ``F`` the pixel flip: ``fx, fy, cy`` unchanged,
  ``cx' = W - 1 - cx`` and the skew negated
  ([`flip_intrinsics`][handmesh_tutorial.augment.flip_intrinsics]).

Geometric augmentation keeps the 3D ground truth exactly consistent with the image:

* an in-plane rotation by ``a`` is the 3D rotation ``R_z(a)`` about the camera's optical axis;
  the image moves by the homography ``K R_z K^-1``, which is affine (its last row is
  ``[0, 0, 1]``; a rotation about the principal point when ``fx = fy`` and there is no skew);
* a crop, shift or zoom is an affine map ``A`` of the pixels only (scale + translation): the 3D
  points do not change and the new intrinsics are ``A K`` (still upper triangular).

The crop is one affine warp ``A K R_z K^-1`` of the (possibly flipped) image, sampled with
``torch.nn.functional.grid_sample`` (bilinear; supersampled and box-filtered when shrinking, so
small crops of large images do not alias). Colour jitter (brightness, contrast, saturation, a
small hue rotation) follows. All randomness of item ``i`` in epoch ``e`` comes from
``numpy.random.default_rng([seed, e, i])``: same seed, epoch and index -> same bytes, whatever the
worker process or the order of loading.

Every item is a dict of tensors (see
[`HandCropDataset`][handmesh_tutorial.augment.HandCropDataset]), so the default ``collate_fn`` of
``torch.utils.data.DataLoader`` batches it.
"""

from __future__ import annotations

import copy
import math
import os
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass

import numpy as np
import torch
import torch.nn.functional as F  # noqa: N812 - the usual torch alias

from .camera import project
from .metrics import ROOT_INDEX

__all__ = [
    "IMAGE_MEAN", "IMAGE_STD", "AugmentConfig", "HandCropDataset",
    "InterSHTorchDataset", "FreiHANDTorchDataset", "normalize_image", "denormalize_image",
    "flip_intrinsics", "rotation_z", "crop_transform", "warp_image", "color_jitter",
    "mirror_matrix", "unmirror", "to_camera", "BadSampleError", "BAD_SAMPLE_ERRORS",
    "find_bad_items", "without_items", "drop_bad_items",
]

IMAGE_MEAN = 0.5
"""Image normalisation of the paper: ``(x / 255 - IMAGE_MEAN) / IMAGE_STD``."""
IMAGE_STD = 1.0
"""See [`IMAGE_MEAN`][handmesh_tutorial.augment.IMAGE_MEAN]."""


# --------------------------------------------------------------------------------------------
# image normalisation


def normalize_image(image) -> torch.Tensor:
    """Paper normalisation of an RGB image: ``x / 255 - 0.5`` (mean 0.5, std 1.0).

    Args:
        image: ``(H, W, 3)`` or ``(B, H, W, 3)`` uint8 array/tensor, channels last.

    Returns:
        ``(3, H, W)`` or ``(B, 3, H, W)`` float32 tensor in ``[-0.5, 0.5]``.
    """
    t = torch.as_tensor(np.asarray(image) if not isinstance(image, torch.Tensor) else image)
    if t.dim() not in (3, 4) or t.shape[-1] != 3:
        raise ValueError(f"image must be (H, W, 3) or (B, H, W, 3), got {tuple(t.shape)}")
    t = t.float().div(255.0).sub(IMAGE_MEAN).div(IMAGE_STD)
    return t.movedim(-1, -3).contiguous()


def denormalize_image(image: torch.Tensor) -> np.ndarray:
    """Undo [`normalize_image`][handmesh_tutorial.augment.normalize_image] for display.

    Args:
        image: ``(3, H, W)`` or ``(B, 3, H, W)`` normalised float tensor.

    Returns:
        ``(H, W, 3)`` or ``(B, H, W, 3)`` uint8 numpy array.
    """
    t = image.detach().cpu().float().mul(IMAGE_STD).add(IMAGE_MEAN).mul(255.0)
    return t.round().clamp(0, 255).to(torch.uint8).movedim(-3, -1).numpy()


# --------------------------------------------------------------------------------------------
# geometry of the crop


def mirror_matrix() -> np.ndarray:
    """``M = diag(-1, 1, 1)``: the camera-frame mirror that turns a left hand into a right one."""
    return np.diag([-1.0, 1.0, 1.0])


def flip_intrinsics(K, width: int) -> np.ndarray:
    """Intrinsics after a horizontal image flip with 3D points mirrored by ``x -> -x``.

    ``u' = W - 1 - u`` (pixel centres at integers) and ``p' = M p`` give ``K' = F K M`` with
    ``F = [[-1, 0, W - 1], [0, 1, 0], [0, 0, 1]]``: ``fx``, ``fy``, ``cy`` unchanged,
    ``cx' = W - 1 - cx``, skew ``s' = -s``. Its own inverse.

    Args:
        K: ``(3, 3)`` intrinsics, pixels.
        width: image width ``W``, pixels.

    Returns:
        ``(3, 3)`` float64 intrinsics of the flipped image.
    """
    k = np.asarray(K, dtype=np.float64)
    if k.shape != (3, 3):
        raise ValueError(f"K must be (3, 3), got {k.shape}")
    flip = np.array([[-1.0, 0.0, width - 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    return flip @ k @ mirror_matrix()


def rotation_z(angle: float) -> np.ndarray:
    """``(3, 3)`` rotation by ``angle`` radians about the camera z axis (x towards y).

    In the OpenCV frame (y down) a positive angle turns the image content clockwise on screen.
    """
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def crop_transform(center, size: float, out_size: int) -> np.ndarray:
    """Affine pixel map taking the square box of side ``size`` around ``center`` to the crop.

    Pixel centres are at integer coordinates, so pixel ``i`` covers ``[i - 0.5, i + 0.5]``; the
    box ``[c - size / 2, c + size / 2]`` maps onto ``[-0.5, out_size - 0.5]``.

    Args:
        center: ``(2,)`` box centre ``(u, v)`` in source pixels.
        size: box side in source pixels (> 0).
        out_size: crop side ``S`` in pixels.

    Returns:
        ``(3, 3)`` float64 ``A`` with ``[u', v', 1] = A [u, v, 1]``; the crop's intrinsics are
        ``A K``.
    """
    if not size > 0:
        raise ValueError(f"crop size must be positive, got {size}")
    s = out_size / float(size)
    cu, cv = (float(x) for x in center)
    return np.array([[s, 0.0, s * (size / 2 - cu) - 0.5],
                     [0.0, s, s * (size / 2 - cv) - 0.5],
                     [0.0, 0.0, 1.0]])


def warp_image(image: torch.Tensor, transform, out_size: int, supersample: int | None = None,
               fill: float = 0.0) -> torch.Tensor:
    """Warp an image by an affine pixel map (bilinear), output ``out_size`` x ``out_size``.

    Output pixel ``q`` takes the source value at ``transform^-1 q`` (pixel centres at integer
    coordinates; ``grid_sample`` with ``align_corners=True`` uses the same convention). When the
    map shrinks the image by more than 2x, it renders ``f`` times larger and averages ``f x f``
    blocks (a box pre-filter against aliasing); the block edges coincide with output pixel
    edges, so positions do not move.

    Args:
        image: ``(C, H, W)`` float tensor.
        transform: ``(3, 3)`` affine map source pixels -> output pixels (last row ``0 0 1``).
        out_size: output side ``S``.
        supersample: ``f``; default ``ceil(1 / scale)`` clipped to ``[1, 4]``.
        fill: value outside the source image.

    Returns:
        ``(C, S, S)`` float tensor.
    """
    m = np.asarray(transform, dtype=np.float64)
    if m.shape != (3, 3) or not np.allclose(m[2], [0.0, 0.0, 1.0], atol=1e-9):
        raise ValueError(f"transform must be a (3, 3) affine matrix with last row [0, 0, 1], "
                         f"got\n{m}")
    if image.dim() != 3:
        raise ValueError(f"image must be (C, H, W), got {tuple(image.shape)}")
    _, h, w = image.shape
    if supersample is None:
        scale = math.sqrt(abs(np.linalg.det(m[:2, :2])))
        supersample = int(min(4, max(1, math.ceil(1.0 / max(scale, 1e-6) - 1e-9))))
    f = int(supersample)
    up = np.array([[f, 0.0, (f - 1) / 2.0], [0.0, f, (f - 1) / 2.0], [0.0, 0.0, 1.0]])
    inv = np.linalg.inv(up @ m)
    n = out_size * f
    q = np.arange(n, dtype=np.float64)
    qu, qv = np.meshgrid(q, q)  # (n, n): column index u, row index v
    src_u = inv[0, 0] * qu + inv[0, 1] * qv + inv[0, 2]
    src_v = inv[1, 0] * qu + inv[1, 1] * qv + inv[1, 2]
    grid = np.stack([2.0 * src_u / max(w - 1, 1) - 1.0, 2.0 * src_v / max(h - 1, 1) - 1.0], -1)
    grid_t = torch.as_tensor(grid, dtype=image.dtype, device=image.device)[None]
    src = image[None]
    if fill != 0.0:  # grid_sample pads with zeros: shift so the padding equals `fill`
        src = src - fill
    out = F.grid_sample(src, grid_t, mode="bilinear", padding_mode="zeros", align_corners=True)
    if fill != 0.0:
        out = out + fill
    if f > 1:
        out = F.avg_pool2d(out, f)
    return out[0]


# --------------------------------------------------------------------------------------------
# colour


_RGB_TO_YIQ = np.array([[0.299, 0.587, 0.114], [0.596, -0.274, -0.322], [0.211, -0.523, 0.312]])


def color_jitter(image: torch.Tensor, brightness: float = 1.0, contrast: float = 1.0,
                 saturation: float = 1.0, hue: float = 0.0) -> torch.Tensor:
    """Photometric jitter of an RGB image in ``[0, 1]`` (all factors 1 / hue 0 = identity).

    Applied in this order: brightness (scale), contrast (blend with the mean grey level),
    saturation (blend with the per-pixel luma), hue (rotation of the chroma plane in YIQ by
    ``hue`` turns); the result is clipped to ``[0, 1]``.

    Args:
        image: ``(3, H, W)`` float tensor in ``[0, 1]``.
        brightness: multiplicative factor.
        contrast: factor on the deviation from the mean luma.
        saturation: factor on the deviation from the per-pixel luma.
        hue: rotation of the chroma, in turns (0.05 = 18 degrees).

    Returns:
        ``(3, H, W)`` float tensor in ``[0, 1]``.
    """
    x = image * brightness
    luma_w = torch.tensor([0.299, 0.587, 0.114], dtype=x.dtype, device=x.device)[:, None, None]
    if contrast != 1.0:
        mean = (x * luma_w).sum(0).mean()
        x = (x - mean) * contrast + mean
    if saturation != 1.0:
        grey = (x * luma_w).sum(0, keepdim=True)
        x = (x - grey) * saturation + grey
    if hue != 0.0:
        a = 2.0 * math.pi * hue
        rot = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)],
                        [0.0, math.sin(a), math.cos(a)]])
        m = np.linalg.inv(_RGB_TO_YIQ) @ rot @ _RGB_TO_YIQ
        x = torch.einsum("ij,jhw->ihw", torch.as_tensor(m, dtype=x.dtype, device=x.device), x)
    return x.clamp(0.0, 1.0)


# --------------------------------------------------------------------------------------------
# undoing the network frame


def unmirror(points, mirrored):
    """Negate camera-frame ``x`` where ``mirrored`` (undo or apply the left -> right mirror).

    Args:
        points: ``(..., P, 3)`` or ``(B, P, 3)`` tensor or array.
        mirrored: a bool, or ``(B,)`` bools (one per sample of a batch).

    Returns:
        Same type and shape; mirrored samples have ``x`` negated. Its own inverse.
    """
    is_t = isinstance(points, torch.Tensor)
    p = points if is_t else np.asarray(points, dtype=np.float64)
    m = torch.as_tensor(mirrored, device=p.device) if is_t else np.asarray(mirrored)
    if m.ndim == 0:
        if not bool(m):
            return p
        return p * (p.new_tensor([-1.0, 1.0, 1.0]) if is_t else np.array([-1.0, 1.0, 1.0]))
    if m.shape[0] != p.shape[0]:
        raise ValueError(f"mirrored has {m.shape[0]} flags but points has {p.shape[0]} samples")
    if is_t:
        sign = torch.ones(p.shape[0], *([1] * (p.dim() - 2)), 3, dtype=p.dtype, device=p.device)
        sign[m.bool(), ..., 0] = -1.0
    else:
        sign = np.ones((p.shape[0], *([1] * (p.ndim - 2)), 3))
        sign[m.astype(bool), ..., 0] = -1.0
    return p * sign


def to_camera(points, batch: Mapping) -> torch.Tensor:
    """Network-frame points (root-centred, rotated, right-hand) back to the original camera frame.

    Inverts what [`HandCropDataset`][handmesh_tutorial.augment.HandCropDataset] did to the ground
    truth: ``p_cam = M^m R^T (p + root)``, with the batch's ``root`` (3,), rotation ``R`` (3, 3) and
    ``mirrored`` flag (``M = diag(-1, 1, 1)``).

    Args:
        points: ``(B, P, 3)`` tensor (predictions or targets), metres.
        batch: a batch (or a single item) from the dataset, with ``root``, ``R``, ``mirrored``.

    Returns:
        ``(B, P, 3)`` tensor in the camera frame of the source image, metres.
    """
    p = torch.as_tensor(points)
    root = torch.as_tensor(batch["root"], dtype=p.dtype, device=p.device)
    rot = torch.as_tensor(batch["R"], dtype=p.dtype, device=p.device)
    single = p.dim() == 2
    if single:
        p, root, rot = p[None], root[None], rot[None]
    cam = torch.einsum("bpi,bij->bpj", p + root[:, None, :], rot)  # (R^T x) = x R row-wise
    cam = unmirror(cam, torch.as_tensor(batch["mirrored"]).reshape(-1))
    return cam[0] if single else cam


# --------------------------------------------------------------------------------------------
# datasets


@dataclass(frozen=True)
class AugmentConfig:
    """Ranges of the training augmentation (all applied only when ``train=True``).

    Attributes:
        rotation: maximum in-plane rotation, degrees (uniform in ``[-rotation, rotation]``).
        scale: crop side multiplied by ``2 ** U(-scale, scale)`` (zoom in / out).
        shift: crop centre moved by ``U(-shift, shift) * side`` along u and v.
        brightness: brightness factor in ``[1 - brightness, 1 + brightness]``.
        contrast: contrast factor in ``[1 - contrast, 1 + contrast]``.
        saturation: saturation factor in ``[1 - saturation, 1 + saturation]``.
        hue: hue rotation in ``[-hue, hue]`` turns.
    """

    rotation: float = 45.0
    scale: float = 0.25
    shift: float = 0.1
    brightness: float = 0.3
    contrast: float = 0.3
    saturation: float = 0.3
    hue: float = 0.05

    @classmethod
    def none(cls) -> AugmentConfig:
        """No augmentation at all (the deterministic evaluation crop)."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    @classmethod
    def geometric(cls) -> AugmentConfig:
        """Default geometry, no colour jitter (for checks of the geometry)."""
        return cls(brightness=0.0, contrast=0.0, saturation=0.0, hue=0.0)

    def as_dict(self) -> dict:
        """The ranges as a plain dict."""
        return asdict(self)


class HandCropDataset(torch.utils.data.Dataset):
    """Base class: one target hand per item, cropped, mirrored to the right, augmented.

    Subclasses implement [`load`][handmesh_tutorial.augment.HandCropDataset.load] (raw sample ->
    image, K, vertices, joints, side, VR).

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

    [`to_camera`][handmesh_tutorial.augment.to_camera] maps network-frame points back to the source
    camera frame.

    Args:
        image_size: crop side ``S``, pixels.
        train: random augmentation on (``False``: the deterministic crop of the target's box).
        seed: base seed of the augmentation (item ``i`` of epoch ``e`` uses
            ``default_rng([seed, e, i])``).
        augment: ranges ([`AugmentConfig`][handmesh_tutorial.augment.AugmentConfig]); ``None`` =
            defaults; ``False`` = none even when training.
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
        except BAD_SAMPLE_ERRORS as e:
            raise BadSampleError(f"sample {index}: {e} (leave such samples out with "
                                 "skip_bad=True / --skip-bad; list them with handmesh verify)",
                                 index=index, reason=str(e)) from e
        rng = np.random.default_rng([self.seed, self.epoch, index]) if self.train else None
        return self.make_item(image, K, verts, joints, side, vr, rng, index)

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


BAD_SAMPLE_ERRORS = (ValueError, KeyError, OSError, EOFError, zipfile.BadZipFile)
"""What the readers raise for a sample whose files are missing, unreadable or inconsistent."""


class BadSampleError(ValueError):
    """A sample of a dataset cannot be read; the message names the sample and its file.

    Attributes:
        index: the sample's position in the underlying reader (``None`` when unknown).
        reason: what is wrong with it (the reader's message, naming the file).
    """

    def __init__(self, message: str, index: int | None = None, reason: str | None = None):
        super().__init__(message)
        self.index = index
        self.reason = message if reason is None else reason


def find_bad_items(dataset, progress: bool = False, desc: str = "checking samples") -> list:
    """Items of ``dataset`` that cannot be loaded, with the reason.

    Loads every item once (all of ``dataset[i]``: files, checks, crop), so that a run over
    the remaining items cannot stop on a bad sample. Costs one pass over the data.

    Args:
        dataset: any map-style dataset (a ``HandCropDataset``, a ``torch.utils.data.Subset``...).
        progress: tqdm bar.
        desc: the bar's label.

    Returns:
        ``[{"position": i, "index": reader index or i, "error": message}, ...]`` in item order;
        ``position`` is the item's position in ``dataset``, ``index`` the sample's position in
        the underlying reader (what ``handmesh verify`` and the sample folders number).
    """
    from ._progress import progress_bar

    bad = []
    for i in progress_bar(range(len(dataset)), desc=desc, disable=not progress, leave=False):
        try:
            dataset[i]
        except BAD_SAMPLE_ERRORS as e:
            index = getattr(e, "index", None)
            bad.append({"position": i, "index": i if index is None else int(index),
                        "error": getattr(e, "reason", str(e))})
    return bad


def drop_bad_items(dataset, progress: bool = False, name: str = "dataset", *,
                   allow_empty: bool = False):
    """``(dataset without its bad items, the bad items)``.

    [`find_bad_items`][handmesh_tutorial.augment.find_bad_items], then
    [`without_items`][handmesh_tutorial.augment.without_items].

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
    [`find_bad_items`][handmesh_tutorial.augment.find_bad_items].

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
    [`HandCropDataset`][handmesh_tutorial.augment.HandCropDataset]).

    Args:
        root_or_dataset: an INTER-SH root folder, an
            [`InterSHDataset`][handmesh_tutorial.dataset.InterSHDataset], or any sequence of
            INTER-SH sample dicts (e.g. a list of
            [`synthetic_sample`][handmesh_tutorial.testing.synthetic_sample] outputs, for in-memory
            experiments).
        image_size: crop side, pixels.
        train: augmentation on.
        seed: augmentation seed.
        augment: see [`HandCropDataset`][handmesh_tutorial.augment.HandCropDataset].
        **kwargs: ``crop``, ``box_scale``, ``mirror_left``, ``indices``, ``cache``.

    Raises:
        FileNotFoundError: the root has no ``meta.json``.
    """

    def __init__(self, root_or_dataset, image_size: int = 128, train: bool = True,
                 seed: int = 0, augment: AugmentConfig | bool | None = None, **kwargs):
        if isinstance(root_or_dataset, str | os.PathLike):
            from .dataset import InterSHDataset

            root_or_dataset = InterSHDataset(root_or_dataset)
        self.source = root_or_dataset
        super().__init__(image_size, train, seed, augment, **kwargs)

    def num_raw(self) -> int:
        return len(self.source)

    def load(self, index: int) -> tuple:
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
        [`HandCropDataset.target_shape`][handmesh_tutorial.augment.HandCropDataset.target_shape];
        reads only the annotation of an on-disk
        root (no image)."""
        if not hasattr(self.source, "sample_dir"):
            return super().target_shape(i)
        index = self.indices[i]
        ann = self.source.annotation(index)
        t = ann["target"]
        path = self.source.sample_dir(index) / "annotation.npz"
        with np.load(path, allow_pickle=False) as z:
            key = f"vertices_{t}"
            if key not in z.files:
                raise ValueError(f"{path}: no {key!r} (keys {sorted(z.files)})")
            v = z[key].astype(np.float64)
        if ann["sides"][t] == "left" and self.mirror_left:
            v = v * np.array([-1.0, 1.0, 1.0])
        return v

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
        root_or_reader: FreiHAND root folder or a [`FreiHAND`][handmesh_tutorial.freihand.FreiHAND].
        split: ``"training"`` or ``"evaluation"`` (when a root is given).
        image_size: crop side, pixels.
        train: augmentation on.
        seed: augmentation seed.
        augment: see [`HandCropDataset`][handmesh_tutorial.augment.HandCropDataset].
        versions: training sample versions (see ``FreiHAND``).
        **kwargs: ``crop`` (default ``"full"``), ``box_scale``, ``indices``, ``cache``.

    Raises:
        ValueError: the split has no vertex or keypoint annotations.
    """

    def __init__(self, root_or_reader, split: str = "training", image_size: int = 128,
                 train: bool = True, seed: int = 0, augment: AugmentConfig | bool | None = None,
                 versions=None, **kwargs):
        from .freihand import FreiHAND

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

    def load(self, index: int) -> tuple:
        s = self.source[index]
        return s["image"], s["K"], s["vertices"], s["joints"], "right", float("nan")
