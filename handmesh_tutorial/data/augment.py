"""Training-crop transforms: normalisation, left -> right mirroring, the crop warp, colour jitter.

Paper, Sec. "Training": images are normalised with mean 0.5 and standard deviation 1.0
(``x / 255 - 0.5``), augmented "with random image crops and transformations", and the ground-truth
vertices are translated so that the middle MCP joint (FreiHAND keypoint 9) is at the origin.

One network serves both hands: the model always predicts a *right* hand. A left target is mirrored
on the way in and back on the way out ([`unmirror`][handmesh_tutorial.data.augment.unmirror],
[`to_camera`][handmesh_tutorial.data.augment.to_camera]):

* the image is flipped horizontally, ``u' = W - 1 - u`` (pixel centres at integer coordinates,
  as everywhere in this library);
* the 3D points get their camera-frame ``x`` negated, ``M = diag(-1, 1, 1)`` (a left hand seen in
  a mirror is a right hand; the hand model's left mesh is the vertex-by-vertex mirror of the right
  one, so the vertex order is kept);
* the intrinsics become ``K' = F K M`` with ``F`` the pixel flip: ``fx, fy, cy`` unchanged,
  ``cx' = W - 1 - cx`` and the skew negated
  ([`flip_intrinsics`][handmesh_tutorial.data.augment.flip_intrinsics]).

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

The torch Datasets that apply these transforms to INTER-SH and FreiHAND samples
([`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset],
``InterSHTorchDataset``, ``FreiHANDTorchDataset``) and the bad-item helpers (``find_bad_items``,
``drop_bad_items``, ``without_items``, ``BadSampleError``, ``BAD_SAMPLE_ERRORS``) live in
``handmesh_tutorial.data.torch_views``; ``hmt.data.augment.InterSHTorchDataset`` etc. still work
(loaded on first access, which keeps the import graph free of cycles). Taught in notebook 08
("Training").
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np
import torch
import torch.nn.functional as F  # noqa: N812 - the usual torch alias

_TORCH_VIEWS = ("HandCropDataset", "InterSHTorchDataset", "FreiHANDTorchDataset",
                "BadSampleError", "BAD_SAMPLE_ERRORS", "find_bad_items", "without_items",
                "drop_bad_items")
"""Names that moved to ``data.torch_views``, still reachable here (module ``__getattr__``)."""

__all__ = [
    "IMAGE_MEAN", "IMAGE_STD", "AugmentConfig", "normalize_image", "denormalize_image",
    "flip_intrinsics", "crop_transform", "warp_image", "color_jitter", "unmirror", "to_camera",
    *_TORCH_VIEWS,
]

IMAGE_MEAN = 0.5
"""Image normalisation of the paper: ``(x / 255 - IMAGE_MEAN) / IMAGE_STD``."""
IMAGE_STD = 1.0
"""See [`IMAGE_MEAN`][handmesh_tutorial.data.augment.IMAGE_MEAN]."""


# --------------------------------------------------------------------------------------------
# image normalisation


def normalize_image(image) -> torch.Tensor:
    """Paper normalisation of an RGB image: ``x / 255 - 0.5`` (mean 0.5, std 1.0).

    Args:
        image: ``(H, W, 3)`` or ``(B, H, W, 3)`` uint8 array/tensor, channels last.

    Returns:
        ``(3, H, W)`` or ``(B, 3, H, W)`` float32 tensor in ``[-0.5, 0.5]``.

    Shapes:
        ``image (H, W, 3)`` -> ``(3, H, W)``; ``(B, H, W, 3)`` -> ``(B, 3, H, W)``.
    """
    t = torch.as_tensor(np.asarray(image) if not isinstance(image, torch.Tensor) else image)
    if t.dim() not in (3, 4) or t.shape[-1] != 3:
        raise ValueError(f"image must be (H, W, 3) or (B, H, W, 3), got {tuple(t.shape)}")
    t = t.float().div(255.0).sub(IMAGE_MEAN).div(IMAGE_STD)
    return t.movedim(-1, -3).contiguous()


def denormalize_image(image: torch.Tensor) -> np.ndarray:
    """Undo [`normalize_image`][handmesh_tutorial.data.augment.normalize_image] for display.

    Args:
        image: ``(3, H, W)`` or ``(B, 3, H, W)`` normalised float tensor.

    Returns:
        ``(H, W, 3)`` or ``(B, H, W, 3)`` uint8 numpy array.

    Shapes:
        ``image (3, H, W)`` -> ``(H, W, 3)``; ``(B, 3, H, W)`` -> ``(B, H, W, 3)``.
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

    Shapes:
        ``K (3, 3)`` -> ``(3, 3)``, pixels.
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

    Shapes:
        ``center (2,)`` pixels -> ``(3, 3)``.
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

    Shapes:
        ``image (C, H, W)``, ``transform (3, 3)`` -> ``(C, S, S)``.
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

    Shapes:
        ``image (3, H, W)`` -> ``(3, H, W)``.
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

    Shapes:
        ``points (..., P, 3)``, ``mirrored ()`` or ``(B,)`` -> same as ``points``.
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

    Inverts what [`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset] did
    to the ground truth: ``p_cam = M^m R^T (p + root)``, with the batch's ``root`` (3,), rotation
    ``R`` (3, 3) and ``mirrored`` flag (``M = diag(-1, 1, 1)``).

    Args:
        points: ``(B, P, 3)`` tensor (predictions or targets), metres.
        batch: a batch (or a single item) from the dataset, with ``root``, ``R``, ``mirrored``.

    Returns:
        ``(B, P, 3)`` tensor in the camera frame of the source image, metres.

    Shapes:
        ``points (B, P, 3)`` (or ``(P, 3)`` with a single item) -> same, metres.
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
# augmentation ranges


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


def __getattr__(name: str):
    # the torch Datasets moved to data.torch_views, which imports this module: load it lazily
    if name in _TORCH_VIEWS:
        import importlib

        return getattr(importlib.import_module(f"{__package__}.torch_views"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
