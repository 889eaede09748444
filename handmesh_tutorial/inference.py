"""One's own RGB image in, a hand mesh out: the pretrained MSMR-Net on a photo's hand box.

[`predict_hand`][handmesh_tutorial.inference.predict_hand] (one hand) and
[`predict_hands`][handmesh_tutorial.inference.predict_hands] (several hands of one image, one
forward pass) prepare the image exactly as the evaluation crops of
[`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset] are prepared, with
the transforms of [`augment`][handmesh_tutorial.data.augment]: a square crop of ``box_scale`` (1.5)
times the longer side of the hand's box, resized to the network's side (128 px for the shipped
network), left hands mirrored to right ones, ``x / 255 - 0.5``. They run the network and undo
the mirror. Given the camera intrinsics ``K``, they also place the hand in the camera frame: the
network predicts root-relative 3D joints and, with its 2D keypoint head, where they are in the
crop; the root is the translation that projects the one onto the other (a linear least-squares
fit, [`root_from_keypoints`][handmesh_tutorial.inference.root_from_keypoints]), and
[`to_camera`][handmesh_tutorial.data.augment.to_camera] maps the points back as in the evaluation.

Inputs it cannot interpret are refused with a message that says what to do
([`check_image`][handmesh_tutorial.inference.check_image]): these mistakes run without error
otherwise and only give worse hands. Measured errors with right and wrong inputs: docs page
"Your own image".

Why one file: every check of a user's image, box, side and camera sits beside the one call
that uses it, so that a refusal and what it protects read together.
"""

from __future__ import annotations

import functools
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from .budget import check_image_size, check_pixels
from .data.augment import (
    IMAGE_MEAN,
    IMAGE_STD,
    crop_transform,
    flip_intrinsics,
    to_camera,
    warp_image,
)
from .export import OnnxNetwork
from .metrics import ROOT_INDEX
from .render.camera import check_intrinsics

__all__ = ["HandCrop", "HandPrediction", "crop_hand", "root_from_keypoints", "predict_hands",
           "predict_hand"]

_SIDES = ("left", "right")


@dataclass
class HandCrop:
    """The network input made from one hand box.

    Attributes:
        image: ``(3, S, S)`` float32 tensor, ``x / 255 - 0.5`` (mirrored for a left hand).
        transform: ``(3, 3)`` affine map from pixels of the given image to crop pixels, the
            left-hand flip included (pixel centres at integers).
        K: ``(3, 3)`` intrinsics of the crop (of the mirrored image for a left hand), or
            ``None`` when no ``K`` was given.
        mirrored: the crop is the mirror image (a left hand turned into a right one).
    """

    image: torch.Tensor
    transform: np.ndarray
    K: np.ndarray | None
    mirrored: bool


@dataclass
class HandPrediction:
    """One hand predicted from an image.

    Attributes:
        vertices: ``(V, 3)`` float64, metres.
        joints: ``(21, 3)`` float64, metres, FreiHAND order.
        frame: ``"camera"`` (the image's OpenCV camera frame, with ``K``) or
            ``"root-relative"`` (no ``K``: the camera's axes, origin at the network's root,
            so ``joints[9]`` is near the origin, as in ``handmesh evaluate``).
        side: ``"left"`` or ``"right"``.
        root: ``(3,)`` joint 9 in the camera frame, metres (``None`` when root-relative).
        keypoints_2d: ``(21, 2)`` the network's 2D joints in the image's pixels (``None``
            without a keypoint head).
        faces: ``(F, 3)`` faces with outward normals for this side (``None`` when the
            network has none).
        crop: the [`HandCrop`][handmesh_tutorial.inference.HandCrop] the network saw.
    """

    vertices: np.ndarray
    joints: np.ndarray
    frame: str
    side: str
    root: np.ndarray | None
    keypoints_2d: np.ndarray | None
    faces: np.ndarray | None
    crop: HandCrop


_FILE_MODES = ("RGB", "RGBA", "RGBX", "L", "LA", "P", "PA", "CMYK", "YCbCr")


def _read_file(path: Path) -> np.ndarray:
    from PIL import Image, ImageOps

    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such image file")
    try:
        with warnings.catch_warnings():  # Pillow's bomb warning: MAX_INPUT_PIXELS is lower
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            im = Image.open(path)
        with im:
            check_pixels(im.height, im.width, str(path))  # from the header: nothing decoded
            im.load()
            mode = im.mode
            if mode not in _FILE_MODES:
                raise ValueError(f"{path}: image mode {mode!r} (16-bit or float); save it as an "
                                 "8-bit RGB image (e.g. PNG or JPEG) first")
            im = ImageOps.exif_transpose(im)  # the upright image, as a viewer shows it
            return np.array(im.convert("RGB"))
    except ValueError:
        raise
    except Exception as e:  # PIL raises OSError, SyntaxError, ... on unreadable files
        raise ValueError(f"{path}: not a readable image ({type(e).__name__}: {e})") from e


def check_image(image) -> np.ndarray:
    """An RGB image as ``(H, W, 3)``, or a message saying why it cannot be read as one.

    A path is read with Pillow: turned upright by its EXIF orientation, converted to RGB from
    its mode (grey, palette, RGBA: alpha dropped, CMYK). An array (numpy or torch) must be
    ``(H, W, 3)`` RGB, channels last: ``uint8``, or float with values in ``[0, 255]``.

    The channel order cannot be checked: a BGR array (OpenCV's ``cv2.imread``) passes and
    gives a worse hand. Convert it with ``image[..., ::-1]`` or ``cv2.cvtColor``.

    Args:
        image: a path (``str`` / ``os.PathLike``), or an ``(H, W, 3)`` array.

    Returns:
        ``(H, W, 3)`` array, ``uint8`` or float32 in ``[0, 255]``.

    Raises:
        FileNotFoundError: no such file.
        ValueError: a grey ``(H, W)`` or ``(H, W, 1)`` array, 4 channels (drop alpha),
            channels first ``(3, H, W)``, another dtype than uint8 or float (the message says
            how to convert it: ``(image // 257).astype(np.uint8)`` for 16-bit values,
            ``image.astype(np.uint8)`` for integers already in 0-255), float values in
            ``[0, 1]`` (multiply by 255), negative or above 255 (already normalised?), NaN,
            an image smaller than 2 x 2 or larger than
            [`MAX_INPUT_PIXELS`][handmesh_tutorial.budget.MAX_INPUT_PIXELS] (a file's size read
            from its header, before decoding), an unreadable file or a 16-bit/float file.
    """
    if isinstance(image, str | os.PathLike):
        return _read_file(Path(image))
    if isinstance(image, torch.Tensor):
        image = image.detach().cpu().numpy()
    arr = np.asarray(image)
    shape = tuple(arr.shape)
    if arr.ndim == 2 or (arr.ndim == 3 and shape[2] == 1):
        raise ValueError(f"image {shape} is grey; the network reads RGB: give the colour image, "
                         "or repeat the grey channel (np.repeat(grey[..., None], 3, -1))")
    if arr.ndim != 3:
        raise ValueError(f"image must be (H, W, 3) RGB, got shape {shape}")
    if shape[2] != 3 and shape[0] in (1, 3, 4):
        raise ValueError(f"image {shape} looks channels-first (C, H, W); give (H, W, 3): "
                         "image.transpose(1, 2, 0) (numpy) or image.permute(1, 2, 0) (torch)")
    if shape[2] == 4:
        raise ValueError(f"image {shape} has 4 channels (RGBA?); drop alpha: image[..., :3]")
    if shape[2] != 3:
        raise ValueError(f"image must be (H, W, 3) RGB, got shape {shape}")
    if min(shape[:2]) < 2:
        raise ValueError(f"image {shape} is too small (at least 2 x 2 pixels)")
    check_pixels(shape[0], shape[1], "image")
    if arr.dtype == np.uint8:
        return arr
    if not np.issubdtype(arr.dtype, np.floating):
        raise ValueError(f"image dtype {arr.dtype}: give uint8 RGB (0-255) or float in "
                         f"[0, 255]; {_integer_advice(arr)}")
    if not np.isfinite(arr).all():
        raise ValueError("image has NaN or infinite values")
    lo, hi = float(arr.min()), float(arr.max())
    if lo < 0.0:
        raise ValueError(f"image values go down to {lo:.3g}: it looks normalised already; give "
                         "the raw RGB image (0-255), the normalisation x / 255 - 0.5 is done here")
    if hi > 255.0:
        raise ValueError(f"image values go up to {hi:.4g}: give RGB in [0, 255]")
    if hi <= 1.0:
        raise ValueError(f"float image with values in [0, 1] (max {hi:.3g}): multiply by 255 "
                         "(the network expects 0-255 RGB, normalised here as x / 255 - 0.5)")
    return arr.astype(np.float32, copy=False)


def _integer_advice(arr: np.ndarray) -> str:
    """What to do with an image of another dtype than uint8 or float, from its values."""
    if not np.issubdtype(arr.dtype, np.integer):
        return "convert it with image.astype(np.float32) if its values are 0-255 RGB"
    lo, hi = int(arr.min()), int(arr.max())
    if lo >= 0 and hi <= 255:
        return f"its values are {lo}-{hi}, already 8-bit: image.astype(np.uint8)"
    if lo >= 0 and hi <= 65535:
        return (f"its values go up to {hi}, a 16-bit image (0-65535): "
                "(image // 257).astype(np.uint8)")
    return f"its values are {lo}-{hi}, outside 0-65535: not an RGB image"


# Share of a hand box's area that must lie inside the image (a box mostly outside it gives a
# crop of black pixels; a box far larger than the image has almost none of its area inside).
_MIN_BOX_INSIDE = 0.25
# Accepted box_scale (crop side / box side): below 1 the crop cuts the hand, above 4 the hand
# shrinks to a few pixels of the crop.
_BOX_SCALE_RANGE = (1.0, 4.0)
# Accepted focal lengths of K as multiples of the image's longer side: a field of view of about
# 169 to 0.6 degrees across it (fisheye to long telephoto).
_FOCAL_RANGE = (0.05, 100.0)


def _check_box(box, width: int, height: int) -> np.ndarray:
    b = np.asarray(box, dtype=np.float64)
    if b.shape != (4,) or not np.isfinite(b).all():
        raise ValueError(f"box must be 4 finite numbers (x0, y0, x1, y1) in pixels, got "
                         f"{np.asarray(box).tolist()}")
    x0, y0, x1, y1 = b
    if x1 <= x0 or y1 <= y0:
        raise ValueError(f"box {b.tolist()} has a non-positive size ({x1 - x0:g} x {y1 - y0:g}); "
                         "give (x0, y0, x1, y1) with x1 > x0 and y1 > y0 (corners, not a size)")
    # the image covers [-0.5, W - 0.5] x [-0.5, H - 0.5] (pixel centres at integers)
    ix = max(0.0, min(x1, width - 0.5) - max(x0, -0.5))
    iy = max(0.0, min(y1, height - 0.5) - max(y0, -0.5))
    inside = (ix / (x1 - x0)) * (iy / (y1 - y0))
    if not inside >= _MIN_BOX_INSIDE:
        raise ValueError(f"box {b.tolist()} lies outside the {width} x {height} image "
                         f"({100 * inside:.3g} % of its area inside, at least "
                         f"{100 * _MIN_BOX_INSIDE:g} % must be; pixel coordinates: x = column, "
                         "y = row, from the top left)")
    return b


def _check_box_scale(box_scale) -> float:
    lo, hi = _BOX_SCALE_RANGE
    if isinstance(box_scale, bool) or not isinstance(box_scale, int | float | np.number) \
            or not lo <= float(box_scale) <= hi:
        raise ValueError(f"box_scale must be a number in [{lo:g}, {hi:g}] (crop side / box "
                         f"side; the training crops use 1.5), got {box_scale!r}")
    return float(box_scale)


def _check_camera(K, width: int, height: int) -> np.ndarray:
    """``K`` checked as a pinhole matrix whose focal lengths fit an image of this size."""
    k = check_intrinsics(K)
    side = max(width, height)
    lo, hi = _FOCAL_RANGE
    for name, f in (("fx", k[0, 0]), ("fy", k[1, 1])):
        if not (np.isfinite(f) and lo * side <= f <= hi * side):
            raise ValueError(f"K's {name} = {f:.6g} px does not fit the {width} x {height} image "
                             f"(accepted: {lo:g} to {hi:g} times its longer side, "
                             f"{lo * side:g}-{hi * side:g} px); is K the intrinsics of this "
                             "image, in pixels (not millimetres, not of a resized copy)?")
    if not np.isfinite(k).all():
        raise ValueError(f"K must be finite, got {k.tolist()}")
    return k


def _check_side(side) -> str:
    if side not in _SIDES:
        raise ValueError(f"side must be 'left' or 'right' (the person's hand), got {side!r}")
    return side


def crop_hand(image, box, side: str, *, image_size: int = 128, box_scale: float = 1.5,
              K=None) -> HandCrop:
    """The network input for one hand box: the evaluation crop of the training pipeline.

    A square of ``box_scale`` times the box's longer side around its centre, mirrored for a left
    hand, resized to ``image_size`` (bilinear, box-filtered when shrinking), ``x / 255 - 0.5``;
    parts outside the image are black. The same arithmetic as
    [`HandCropDataset.make_item`][handmesh_tutorial.data.torch_views.HandCropDataset.make_item]
    without augmentation, whose box is that of the projected hand mesh.

    Args:
        image: see [`check_image`][handmesh_tutorial.inference.check_image].
        box: ``(x0, y0, x1, y1)`` the hand's box in pixels (x = column, y = row, pixel
            centres at integers).
        side: ``"left"`` or ``"right"``.
        image_size: crop side ``S``, pixels (the network's training crops), an integer in
            [``budget.MIN_IMAGE_SIZE``, ``budget.MAX_IMAGE_SIZE``] = [32, 4096].
        box_scale: margin of the crop around the box (the training crops' 1.5), a number in
            [1, 4].
        K: ``(3, 3)`` intrinsics of ``image`` (optional: gives the crop's); ``fx`` and ``fy``
            within 0.05 to 100 times the image's longer side (a field of
            view of about 169 to 0.6 degrees).

    Returns:
        The [`HandCrop`][handmesh_tutorial.inference.HandCrop].

    Raises:
        ValueError: an image [`check_image`][handmesh_tutorial.inference.check_image]
            refuses, a box that is not 4 numbers, has a non-positive size or lies mostly
            outside the image (less than a quarter of
            its area inside: also a box far larger than the image), a side other than
            ``"left"``/``"right"``, an ``image_size`` or ``box_scale`` outside its range, a
            ``K`` that is not a pinhole matrix or whose focal lengths do not fit the image.
    """
    img = check_image(image)
    h, w = img.shape[:2]
    x0, y0, x1, y1 = _check_box(box, w, h)
    mirrored = _check_side(side) == "left"
    image_size = check_image_size(image_size)
    box_scale = _check_box_scale(box_scale)
    k = None if K is None else _check_camera(K, w, h)
    pix = torch.from_numpy(np.array(img)).permute(2, 0, 1).float() / 255.0
    flip = np.eye(3)
    if mirrored:  # u' = W - 1 - u, as the training crops
        pix = pix.flip(-1)
        flip = np.array([[-1.0, 0.0, w - 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        x0, x1 = w - 1.0 - x1, w - 1.0 - x0
        k = None if k is None else flip_intrinsics(k, w)
    centre = np.array([(x0 + x1) / 2.0, (y0 + y1) / 2.0])
    side_px = max(x1 - x0, y1 - y0, 1.0) * float(box_scale)
    crop = crop_transform(centre, side_px, int(image_size))
    out = warp_image(pix, crop, int(image_size))
    return HandCrop(image=((out - IMAGE_MEAN) / IMAGE_STD).float(), transform=crop @ flip,
                    K=None if k is None else crop @ k, mirrored=mirrored)


def root_from_keypoints(joints, keypoints_2d, K) -> np.ndarray:
    """The translation that puts root-relative 3D joints onto their 2D positions.

    Least squares over the joints of the linear equations ``(X + t) - x (Z + t_z) = 0`` and
    ``(Y + t_y) - y (Z + t_z) = 0``, with ``(x, y, 1) = K^-1 (u, v, 1)``: exact when the 2D
    joints are the projection of ``joints + t``.

    Args:
        joints: ``(B, J, 3)`` or ``(J, 3)`` root-relative joints, metres.
        keypoints_2d: ``(B, J, 2)`` or ``(J, 2)`` their pixel positions.
        K: ``(B, 3, 3)`` or ``(3, 3)`` intrinsics of those pixels.

    Returns:
        ``(B, 3)`` or ``(3,)`` float64 translations ``t``, metres (the root in that camera's
        frame).

    Raises:
        ValueError: shapes that do not match, or NaN or infinite values (lstsq's "SVD did not
            converge" named nothing).
    """
    j = np.asarray(joints, dtype=np.float64)
    single = j.ndim == 2
    j = j[None] if single else j
    uv = np.asarray(keypoints_2d, dtype=np.float64).reshape(j.shape[0], -1, 2)
    k = np.broadcast_to(np.asarray(K, dtype=np.float64), (j.shape[0], 3, 3))
    if uv.shape[1] != j.shape[1] or j.shape[-1] != 3:
        raise ValueError(f"joints {j.shape} and keypoints_2d {uv.shape} do not match")
    for name, a in (("joints", j), ("keypoints_2d", uv), ("K", k)):
        if not np.isfinite(a).all():
            raise ValueError(f"{name} contains NaN or inf")
    ray = np.concatenate([uv, np.ones_like(uv[..., :1])], -1) @ np.linalg.inv(k).transpose(0, 2, 1)
    out = []
    for p, r in zip(j, ray, strict=True):
        a = np.zeros((2 * len(p), 3))
        a[0::2, 0] = a[1::2, 1] = 1.0
        a[0::2, 2], a[1::2, 2] = -r[:, 0], -r[:, 1]
        rhs = np.stack([r[:, 0] * p[:, 2] - p[:, 0], r[:, 1] * p[:, 2] - p[:, 1]], 1).reshape(-1)
        out.append(np.linalg.lstsq(a, rhs, rcond=None)[0])
    t = np.stack(out)
    return t[0] if single else t


@functools.lru_cache(maxsize=2)
def _shipped(device: str) -> tuple[nn.Module, dict]:
    from .pretrained import pretrained_path
    from .train import load_checkpoint

    net, ck = load_checkpoint(pretrained_path(), device=device)
    return net, ck["config"]


def _network(model, image_size, box_scale, device) -> tuple[nn.Module, int, float]:
    """``(network, crop side, box scale)`` of ``model``: the shipped network (``None`` or
    ``"pretrained"``), a checkpoint path, or a module (then ``image_size`` is needed)."""
    if isinstance(model, str | os.PathLike) and str(model).endswith(".onnx"):
        model = OnnxNetwork(model)
    if isinstance(model, OnnxNetwork):  # the fast path (hmt.export), run by onnxruntime
        size = model.image_size if image_size is None else check_image_size(image_size)
        if size is None:
            raise ValueError("give image_size: this ONNX file records no crop side")
        if model.image_size is not None and size != model.image_size:
            raise ValueError(f"image_size={image_size}, but the ONNX file was exported for "
                             f"{model.image_size}-px crops; leave image_size out")
        return model, int(size), _check_box_scale(model.box_scale if box_scale is None
                                                  else box_scale)
    if model is None or isinstance(model, str | os.PathLike):
        from .train import load_checkpoint

        device = "cpu" if device is None else device
        if model is None or str(model) == "pretrained":
            net, cfg = _shipped(str(device))
        else:
            net, ck = load_checkpoint(model, device=device)
            cfg = ck["config"]
        size = int(cfg["image_size"])
        if image_size is not None and check_image_size(image_size) != size:
            raise ValueError(f"image_size={image_size}, but the network was trained on "
                             f"{size}-px crops; leave image_size out")
        return net, size, _check_box_scale(cfg.get("box_scale", 1.5) if box_scale is None
                                           else box_scale)
    if not isinstance(model, nn.Module):
        raise ValueError(f"model must be None, 'pretrained', a checkpoint path or a network, "
                         f"got {type(model).__name__}")
    if image_size is None:
        raise ValueError("give image_size, the crop side this network was trained on (a "
                         "checkpoint's config['image_size']); a wrong size runs but predicts "
                         "worse")
    return (model if device is None else model.to(device)), check_image_size(image_size), \
        _check_box_scale(1.5 if box_scale is None else box_scale)


def predict_hands(image, boxes, sides, K=None, model=None, *, image_size: int | None = None,
                  box_scale: float | None = None, device: str | None = None,
                  batch_size: int = 32) -> list[HandPrediction]:
    """Predict every hand of one image, given its boxes and sides (one forward pass per batch).

    Args:
        image: a path or an ``(H, W, 3)`` RGB array
            ([`check_image`][handmesh_tutorial.inference.check_image]).
        boxes: ``(N, 4)`` boxes ``(x0, y0, x1, y1)``, pixels, e.g. a hand detector's.
        sides: ``N`` sides (``"left"`` / ``"right"``), or one for all.
        K: ``(3, 3)`` intrinsics of ``image`` (pixels): outputs in its camera frame; ``None``:
            root-relative outputs.
        model: ``None`` or ``"pretrained"`` (the shipped network, loaded once per device), a
            checkpoint path, or a network (then give ``image_size``); or the fast path, the
            network exported and run by onnxruntime: an
            [`OnnxNetwork`][handmesh_tutorial.export.OnnxNetwork]
            (``hmt.export.onnx_network()``) or a path ending in ``.onnx`` (opened on each
            call: keep the ``OnnxNetwork`` for repeated calls); it runs on the CPU.
        image_size: crop side, an integer in [32, 4096]; default: the checkpoint's.
        box_scale: crop margin, a number in [1, 4] (``None``: the checkpoint's, 1.5; 0 is
            refused, not read as the default).
        device: where the network runs (``None``: a network object stays where it is, a
            loaded one goes to the CPU).
        batch_size: crops per forward pass, an integer >= 1.

    Returns:
        One [`HandPrediction`][handmesh_tutorial.inference.HandPrediction] per box, in order.

    Raises:
        ValueError: see [`crop_hand`][handmesh_tutorial.inference.crop_hand]; also ``K`` with a
            network that has no 2D keypoint head (it cannot place the hand), a root that comes
            out behind the camera (a ``K`` of another image?), a missing ``image_size``, a
            ``batch_size`` below 1.
    """
    img = check_image(image)
    if isinstance(batch_size, bool) or not isinstance(batch_size, int | np.integer) \
            or batch_size < 1:
        raise ValueError(f"batch_size must be an integer >= 1 (crops per forward pass), got "
                         f"{batch_size!r}")
    net, size, scale = _network(model, image_size, box_scale, device)
    b = np.asarray(boxes, dtype=np.float64) if len(boxes) else np.zeros((0, 4))
    if b.ndim != 2 or b.shape[1] != 4:
        raise ValueError(f"boxes must be (N, 4), got {b.shape}")
    side_list = [sides] * len(b) if isinstance(sides, str) else list(sides)
    if len(side_list) != len(b):
        raise ValueError(f"{len(b)} boxes but {len(side_list)} sides")
    crops = [crop_hand(img, bb, sd, image_size=size, box_scale=scale, K=K)
             for bb, sd in zip(b, side_list, strict=True)]
    if not crops:
        return []
    outs: dict[str, list] = {"vertices": [], "joints": [], "uv": []}
    is_module = not isinstance(net, OnnxNetwork)  # the fast path runs in onnxruntime
    was_training = net.training if is_module else False
    dev = next(net.parameters()).device if is_module else "cpu"
    if is_module:
        net.eval()
    try:
        with torch.no_grad():
            for s in range(0, len(crops), batch_size):
                o = net(torch.stack([c.image for c in crops[s:s + batch_size]]).to(dev))
                for k in outs:
                    if k in o:
                        outs[k].append(o[k].double().cpu())
    finally:
        if is_module:
            net.train(was_training)
    verts, joints = torch.cat(outs["vertices"]), torch.cat(outs["joints"])
    uv_crop = (torch.cat(outs["uv"]).numpy() + 1.0) * size / 2.0 - 0.5 if outs["uv"] else None
    mirrored = torch.tensor([c.mirrored for c in crops])
    if K is not None:
        if uv_crop is None:
            raise ValueError("this network has no 2D keypoint head, so it cannot place the hand "
                             "in the camera frame; call with K=None (root-relative output)")
        root = root_from_keypoints(joints.numpy(), uv_crop, np.stack([c.K for c in crops]))
        behind = np.flatnonzero(root[:, 2] <= 0)
        if len(behind):
            raise ValueError(f"hand {int(behind[0])}: its root came out behind the camera "
                             f"(z = {root[behind[0], 2]:.3g} m); is K the intrinsics of this "
                             f"{img.shape[1]} x {img.shape[0]} image?")
        root_t = torch.as_tensor(root)
    else:
        root_t = torch.zeros(len(crops), 3, dtype=torch.float64)
    batch = {"root": root_t, "R": torch.eye(3, dtype=torch.float64).expand(len(crops), 3, 3),
             "mirrored": mirrored}
    verts, joints = to_camera(verts, batch).numpy(), to_camera(joints, batch).numpy()
    cam_root = joints[:, ROOT_INDEX]
    faces = getattr(net, "faces", None)
    preds = []
    for i, c in enumerate(crops):
        kp = None
        if uv_crop is not None:
            back = np.linalg.inv(c.transform)
            kp = uv_crop[i] @ back[:2, :2].T + back[:2, 2]
        f = None if faces is None else np.asarray(faces)[:, ::-1] if c.mirrored else faces
        preds.append(HandPrediction(
            vertices=verts[i], joints=joints[i], frame="root-relative" if K is None else "camera",
            side=side_list[i], root=None if K is None else cam_root[i].copy(), keypoints_2d=kp,
            faces=None if f is None else np.array(f), crop=c))
    return preds


def predict_hand(image, box, side: str, K=None, model=None, *, image_size: int | None = None,
                 box_scale: float | None = None, device: str | None = None) -> HandPrediction:
    """Predict one hand's mesh and joints from an RGB image, its box and its side.

    ``hmt.inference.predict_hand("photo.jpg", (x0, y0, x1, y1), "left", K=K)``. Without ``K``
    the output is root-relative (the network's root near the origin, the camera's axes).

    Args:
        image: a path or an ``(H, W, 3)`` RGB array
            ([`check_image`][handmesh_tutorial.inference.check_image]).
        box: ``(x0, y0, x1, y1)``, pixels.
        side: ``"left"`` or ``"right"``, the person's hand.
        K: ``(3, 3)`` intrinsics of ``image``, or ``None``.
        model: see [`predict_hands`][handmesh_tutorial.inference.predict_hands].
        image_size: see ``predict_hands``.
        box_scale: see ``predict_hands``.
        device: see ``predict_hands``.

    Raises:
        ValueError: see [`predict_hands`][handmesh_tutorial.inference.predict_hands].

    Returns:
        The [`HandPrediction`][handmesh_tutorial.inference.HandPrediction]: ``vertices``
        ``(V, 3)``, ``joints`` ``(21, 3)``, metres, in ``frame``.
    """
    return predict_hands(image, [box], [side], K, model, image_size=image_size,
                         box_scale=box_scale, device=device)[0]
