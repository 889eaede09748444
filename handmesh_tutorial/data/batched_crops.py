"""Hand crops for fast training on a GPU: cut once with a wide margin, then viewed in batches.

[`crop_cache`][handmesh_tutorial.data.batched_crops.crop_cache] cuts one wide crop per target
hand; [`augment_crops`][handmesh_tutorial.data.batched_crops.augment_crops] makes randomly
rotated, zoomed, shifted and colour-jittered views of a batch of them in one warp on the training
device. The geometry is [`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset]'s
([`augment`][handmesh_tutorial.data.augment]): an in-plane rotation is the 3D rotation
``R_z`` about the crop camera's optical axis (the image moves by ``K R_z K^-1``), zoom and
shift move pixels only, and the view is re-centred on the hand's box; the 3D targets turn with
``R_z`` and the 2D targets are the turned joints projected with the new intrinsics. Why: with
per-item augmentation a GPU waits for the data-loader processes (docs page "The pretrained model");
one batched warp costs milliseconds. Used by the encoder pretraining (docs page "Why the paper
starts from pretrained weights").
"""

from __future__ import annotations

import math
import os

import torch
import torch.nn.functional as F  # noqa: N812 - the usual torch alias

from .._progress import progress_bar

__all__ = ["BOX_SCALE", "crop_cache", "check_crop_cache", "augment_crops"]

CACHE_SIZE = 192
"""Side of the cached crops, pixels (a 128-px training crop then samples them about 1:1)."""
CACHE_BOX = 2.25
"""Margin of the cached crops: 1.5 x the training crop's, room for rotation, zoom and shift."""
BOX_SCALE = 1.5
"""Margin of the training and evaluation crops (that of ``HandCropDataset``)."""


def crop_cache(root, *, size: int = CACHE_SIZE, box_scale: float = CACHE_BOX,
               workers: int = 0, progress: bool = True) -> dict[str, torch.Tensor]:
    """One wide crop per target hand of an INTER-SH set (left hands mirrored to the right).

    Args:
        root: INTER-SH root, reader, or sequence of sample dicts.
        size: crop side ``P``, pixels.
        box_scale: margin around the target's projected mesh box.
        workers: data-loader processes.
        progress: tqdm bar.

    Returns:
        ``image`` ``(N, 3, P, P)`` uint8, ``joints`` ``(N, 21, 3)`` root-relative metres,
        ``root`` ``(N, 3)`` and ``K`` ``(N, 3, 3)`` (crop camera frame, pixels), ``box``
        ``(N,)`` float32: the side of the target's ``BOX_SCALE`` crop in cache pixels.
    """
    from .torch_views import InterSHTorchDataset

    if isinstance(root, str | os.PathLike):
        root = str(root)
    ds = InterSHTorchDataset(root, image_size=size, train=False, augment=False,
                             box_scale=box_scale)
    loader = torch.utils.data.DataLoader(ds, batch_size=64, num_workers=workers)
    parts: dict[str, list] = {k: [] for k in ("image", "joints", "root", "K")}
    for b in progress_bar(loader, desc="cropping", disable=not progress, leave=False):
        parts["image"].append(((b["image"] + 0.5) * 255).round().clamp(0, 255).to(torch.uint8))
        for k in ("joints", "root", "K"):
            parts[k].append(b[k].float())
    out = {k: torch.cat(v) for k, v in parts.items()}
    out["box"] = torch.full((len(out["image"]),), size * BOX_SCALE / box_scale)
    return out


def check_crop_cache(cache, where: str, size: int = CACHE_SIZE) -> dict[str, torch.Tensor]:
    """Check a crop cache read from a file (another run's ``crops_<split>.pt``) as any
    untrusted input: `crop_cache`'s keys, dtypes and shapes, crops of side ``size``, finite
    values and plausible joints.

    Args:
        cache: what the file held.
        where: the file, for messages.
        size: the crop side the cache must have, pixels.

    Returns:
        ``cache``.

    Raises:
        ValueError: the first thing wrong, naming ``where`` and the key.
    """
    if not isinstance(cache, dict):
        raise ValueError(f"{where}: not a crop cache (a {type(cache).__name__}, expected a dict "
                         "of tensors as crop_cache writes)")
    want = {"image": (3, size, size), "joints": (21, 3), "root": (3,), "K": (3, 3), "box": ()}
    missing = [k for k in want if not isinstance(cache.get(k), torch.Tensor)]
    if missing:
        raise ValueError(f"{where}: not a crop cache (no tensor {missing[0]!r})")
    n = len(cache["image"]) if cache["image"].dim() else -1
    for key, tail in want.items():
        t = cache[key]
        if tuple(t.shape) != (n, *tail):
            raise ValueError(f"{where}: '{key}' has shape {tuple(t.shape)}, expected "
                             f"{(max(n, 0), *tail)} (crops of {size} px)")
        if key == "image":
            if t.dtype != torch.uint8:
                raise ValueError(f"{where}: 'image' has dtype {t.dtype}, expected torch.uint8")
        elif not t.is_floating_point() or not torch.isfinite(t).all():
            raise ValueError(f"{where}: '{key}' holds NaN, infinity or no floats")
    if n and float(cache["joints"].abs().max()) > 0.5:  # root-relative metres: a hand is small
        raise ValueError(f"{where}: 'joints' holds values up to "
                         f"{float(cache['joints'].abs().max()):.3g} m from the root: not a hand")
    if n and not bool((cache["box"] > 0).all()):
        raise ValueError(f"{where}: 'box' holds sides <= 0")
    return cache


def _rotation_z(angle: torch.Tensor) -> torch.Tensor:
    c, s = angle.cos(), angle.sin()
    z, o = torch.zeros_like(c), torch.ones_like(c)
    return torch.stack([c, -s, z, s, c, z, z, z, o], -1).view(-1, 3, 3)


def augment_crops(batch: dict, out_size: int, *, draws: dict | None = None,
                  colour: bool = True) -> dict[str, torch.Tensor]:
    """Random views of cached crops, in one batched warp (the geometry of ``HandCropDataset``).

    Args:
        batch: ``image`` ``(B, 3, P, P)`` uint8, ``joints`` ``(B, 21, 3)``, ``root`` ``(B, 3)``,
            ``K`` ``(B, 3, 3)``, ``box`` ``(B,)`` as
            [`crop_cache`][handmesh_tutorial.data.batched_crops.crop_cache] returns, on one
            device.
        out_size: output side ``S``, pixels.
        draws: per-sample ``angle`` (radians), ``zoom`` (side factor), ``shift`` ``(B, 2)``
            (share of the side), ``brightness``, ``contrast``, ``saturation`` (factors);
            ``None``: no augmentation (the evaluation crop of the target's box).
        colour: apply the colour draws.

    Returns:
        ``image`` ``(B, 3, S, S)`` float32 normalised ``x / 255 - 0.5``, ``joints``, ``root``
        (turned by ``R_z``), ``K`` ``(B, 3, 3)`` of the new crop.

    Shapes:
        see Args and Returns; all tensors stay on the batch's device.
    """
    img, joints, root, K = batch["image"], batch["joints"], batch["root"], batch["K"]
    b, _, p, _ = img.shape
    dev, dt = joints.device, torch.float64
    K64 = K.to(dt)
    if draws is None:
        draws = {"angle": torch.zeros(b, device=dev), "zoom": torch.ones(b, device=dev),
                 "shift": torch.zeros(b, 2, device=dev)}
        colour = False
    rot = _rotation_z(draws["angle"].to(dev, dt))
    motion = K64 @ rot @ torch.linalg.inv(K64)  # image motion of R_z: affine for these K
    motion[:, 2] = torch.tensor([0.0, 0.0, 1.0], dtype=dt, device=dev)
    centre = torch.full((b, 3), (p - 1) / 2.0, dtype=dt, device=dev)
    centre[:, 2] = 1.0
    centre = (motion @ centre[..., None])[:, :2, 0]
    side = batch["box"].to(dev, dt) * draws["zoom"].to(dev, dt)
    centre = centre + draws["shift"].to(dev, dt) * side[:, None]
    # crop_transform, batched: the box of side `side` around `centre` onto [-0.5, S - 0.5]
    # shrinking by more than ~1.2x: render f times larger and box-filter (no aliasing)
    f = int(min(4, max(1, math.ceil(float(side.median()) / out_size - 0.2))))
    n = out_size * f
    s = n / side
    A = torch.zeros(b, 3, 3, dtype=dt, device=dev)
    A[:, 0, 0] = A[:, 1, 1] = s
    A[:, :2, 2] = s[:, None] * (side[:, None] / 2 - centre) - 0.5
    A[:, 2, 2] = 1.0
    inv = torch.linalg.inv(A @ motion)  # output pixel -> cache pixel
    # grid_sample (align_corners=False) wants normalised source coordinates per output pixel
    q = torch.arange(n, dtype=dt, device=dev)
    qv, qu = torch.meshgrid(q, q, indexing="ij")
    pts = torch.stack([qu, qv, torch.ones_like(qu)], -1).view(1, -1, 3)  # (1, n*n, 3)
    src = (pts @ inv.transpose(1, 2))[..., :2]  # (B, n*n, 2) cache pixels
    grid = ((2 * src + 1) / p - 1).view(b, n, n, 2).float()
    pix = img.float() / 255.0
    out = F.grid_sample(pix, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    if f > 1:
        out = F.avg_pool2d(out, f)
    if colour:
        bsz = (b, 1, 1, 1)
        out = out * draws["brightness"].view(bsz)
        luma = torch.tensor([0.299, 0.587, 0.114], device=dev).view(1, 3, 1, 1)
        mean = (out * luma).sum(1, keepdim=True).mean((2, 3), keepdim=True)
        out = (out - mean) * draws["contrast"].view(bsz) + mean
        grey = (out * luma).sum(1, keepdim=True)
        out = ((out - grey) * draws["saturation"].view(bsz) + grey).clamp(0, 1)
    crop = A.clone()
    # the S-pixel crop's map: output pixel i averages pixels f i ... f i + f - 1 of the render
    crop[:, :2] /= f
    crop[:, :2, 2] -= (f - 1) / (2.0 * f)
    rt = rot.float().transpose(1, 2)
    return {"image": out - 0.5, "joints": joints @ rt, "root": (root[:, None] @ rt)[:, 0],
            "K": (crop @ K64).float()}
