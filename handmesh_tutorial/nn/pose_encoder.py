"""The pretrained hand image encoder: the tutorial's stand-in for the paper's ImageNet weights.

The paper starts MSMR-Net's encoder from ImageNet weights and trains the rest. ImageNet weights
cannot be downloaded here, and an encoder trained from random weights on a CPU in minutes learns
the data's mean hand and nothing per image (docs page "Why the paper starts from pretrained
weights"). So the package ships an encoder pretrained on INTER-SH scenes with a **decoder-neutral**
objective: 2D keypoints (heat-maps, soft-argmax) and root-relative 3D joints from the pooled
features; no mesh decoder takes part in it. (The demo's file continues weights that began as an
earlier MSMR-Net's encoder, which its lineage names; that page shows notebook 10's verdict is the
same from an encoder trained from random weights.)

* [`PoseNet`][handmesh_tutorial.nn.pose_encoder.PoseNet]: the network that is pretrained, a
  [`KeypointEncoder`][handmesh_tutorial.nn.keypoints.KeypointEncoder] (the ``encoder`` MSMR-Net
  builds with ``keypoints=True``) plus a linear 3D-joint head that is thrown away afterwards.
* [`pose_loss`][handmesh_tutorial.nn.pose_encoder.pose_loss]: its objective.
* [`pretrained_encoder`][handmesh_tutorial.nn.pose_encoder.pretrained_encoder]: the shipped weights
  as a ready ``KeypointEncoder``;
  [`load_pretrained_encoder`][handmesh_tutorial.nn.pose_encoder.load_pretrained_encoder] copies them
  into a model's encoder.
* [`export_pose_encoder`][handmesh_tutorial.nn.pose_encoder.export_pose_encoder]: the small int8
  file, with what made it.

Preprocessing (recorded in the file as ``preprocessing``): a square crop of ``box_scale`` (1.5)
times the larger side of the target's projected box, left hands mirrored to the right, RGB
``x / 255 - 0.5`` ([`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset]),
any side in ``image_sizes`` (it was trained on all of them).
"""

from __future__ import annotations

import os
from pathlib import Path

import torch
from torch import nn

from .._untrusted import load_torch_file
from .._version import __version__, shipped_file, shipped_version
from .encoder import build_encoder
from .keypoints import KeypointEncoder, keypoint_loss, normalised_keypoints
from .losses import aligned_joint_loss
from .quantize import dequantize_state_dict, quantize_state_dict

__all__ = ["PoseNet", "pose_loss", "build_pose_net", "pretrained_encoder",
           "pretrained_encoder_info", "pretrained_encoder_path", "load_pretrained_encoder",
           "export_pose_encoder", "read_pose_encoder", "encoder_lineage"]

ENCODER_FILE = "hand_encoder_pretrained.pt"
NEUTRAL_ENCODER_FILE = "hand_encoder_neutral.pt"
"""The decoder-neutral encoder (``make pretrained-encoder``): trained from random weights on 2D
keypoints and 3D joints only, so that it favours none of the decoders Table 3 compares."""
SHIPPED_ENCODERS = {"pretrained": ENCODER_FILE, "neutral": NEUTRAL_ENCODER_FILE}
"""Names accepted wherever an encoder source is (``init_encoder="neutral"``...)."""
"""Name of the shipped file in ``handmesh_tutorial/assets/``."""
FORMAT = "handmesh-pose-encoder-1"
"""``format`` entry of the file (checked when reading)."""

_JOINT_SCALE = 0.1  # metres per head output unit: O(1) outputs at hand size


class PoseNet(nn.Module):
    """A keypoint encoder with a 3D-joint head: what the shipped encoder was trained as.

    Args:
        encoder: a [`KeypointEncoder`][handmesh_tutorial.nn.keypoints.KeypointEncoder].
        num_joints: ``J``.

    Shapes:
        ``images (B, 3, S, S)`` -> ``{"features": (B, D), "uv": (B, J, 2), "joints": (B, J, 3)}``;
        ``joints`` root-relative (joint 9 at the origin), metres, crop camera frame.
    """

    def __init__(self, encoder: KeypointEncoder, num_joints: int = 21):
        super().__init__()
        if not isinstance(encoder, KeypointEncoder):
            raise ValueError(f"PoseNet needs a KeypointEncoder, got {type(encoder).__name__}")
        self.encoder = encoder
        self.num_joints = num_joints
        self.joint_head = nn.Linear(encoder.out_features, 3 * num_joints)

    def forward(self, images: torch.Tensor) -> dict[str, torch.Tensor]:
        """Args: images ``(B, 3, S, S)``. Returns features, ``uv`` and ``joints`` (see class)."""
        out = self.encoder(images)
        joints = self.joint_head(out["features"]).view(-1, self.num_joints, 3) * _JOINT_SCALE
        return {**out, "joints": joints - joints[:, 9:10]}


def build_pose_net(backbone: str = "resnet10", num_joints: int = 21) -> PoseNet:
    """A [`PoseNet`][handmesh_tutorial.nn.pose_encoder.PoseNet] from random weights.

    Args:
        backbone: a ResNet name of [`build_encoder`][handmesh_tutorial.nn.encoder.build_encoder].
        num_joints: ``J``.
    """
    return PoseNet(KeypointEncoder(build_encoder(backbone), num_joints=num_joints), num_joints)


def pose_loss(out: dict, joints: torch.Tensor, root: torch.Tensor, K: torch.Tensor,
              image_size: int, keypoint_weight: float = 0.5,
              aligned_weight: float = 1.0) -> tuple[torch.Tensor, dict]:
    """The pretraining objective: L1 of root-relative 3D joints, of Procrustes-aligned joints and
    of normalised 2D keypoints (the weights of the demo's CPU recipe).

    Args:
        out: [`PoseNet`][handmesh_tutorial.nn.pose_encoder.PoseNet]'s output.
        joints: ``(B, J, 3)`` root-relative targets, metres (crop camera frame).
        root: ``(B, 3)`` the root in that frame.
        K: ``(B, 3, 3)`` crop intrinsics.
        image_size: crop side, pixels.
        keypoint_weight: weight of the 2D term (1 unit = half the crop side).
        aligned_weight: weight of the aligned-joint term.

    Returns:
        ``(total, parts)``: the scalar and a dict of floats (``joints``, ``aligned`` in metres,
        ``keypoint`` in normalised units).
    """
    if out["joints"].shape != joints.shape:
        raise ValueError(f"predicted joints {tuple(out['joints'].shape)} and targets "
                         f"{tuple(joints.shape)} differ")
    l3 = (out["joints"] - joints).abs().mean()
    la = aligned_joint_loss(out["joints"], joints)
    lk = keypoint_loss(out["uv"], normalised_keypoints(joints, root, K, image_size))
    total = l3 + aligned_weight * la + keypoint_weight * lk
    return total, {"joints": float(l3.detach()), "aligned": float(la.detach()),
                   "keypoint": float(lk.detach())}


def export_pose_encoder(net: PoseNet, out: str | os.PathLike, *, info: dict | None = None,
                        weights: str = "int8", backbone: str = "resnet10",
                        preprocessing: dict | None = None, history: list | None = None) -> Path:
    """Write ``net`` as a small file (atomically): weights, architecture, preprocessing,
    provenance.

    Args:
        net: the trained [`PoseNet`][handmesh_tutorial.nn.pose_encoder.PoseNet].
        out: the file.
        info: what made it (stored as ``pretrained``: command, data seeds and counts, seconds,
            hardware, commit...).
        weights: ``"int8"`` (per-channel, about a quarter of float32) or ``"float32"``.
        backbone: the ResNet name of ``net.encoder.backbone``.
        preprocessing: how inputs are made (crop, mirroring, normalisation, sizes).
        history: validation rows.

    Returns:
        ``out`` as a ``Path``.
    """
    from .._io import atomic_write_with

    if weights not in ("int8", "float32"):
        raise ValueError(f"weights must be 'int8' or 'float32', got {weights!r}")
    state = {k: v.detach().cpu() for k, v in net.state_dict().items()}
    scales = {}
    if weights == "int8":
        state, scales = quantize_state_dict(state, [n for n, _ in net.named_parameters()])
    blob = {"format": FORMAT, "model": state, "scales": scales, "weights": weights,
            "architecture": {"backbone": backbone, "num_joints": net.num_joints,
                             "width": net.encoder.heatmaps.in_channels,
                             "out_features": net.encoder.out_features},
            "preprocessing": dict(preprocessing or {}), "history": list(history or []),
            "pretrained": dict(info or {}), "torch_version": str(torch.__version__),
            "library_version": __version__}
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_with(out, lambda fh: torch.save(blob, fh))


def read_pose_encoder(path: str | os.PathLike) -> tuple[PoseNet, dict]:
    """Read a file of
    [`export_pose_encoder`][handmesh_tutorial.nn.pose_encoder.export_pose_encoder].

    Returns:
        ``(net, meta)``: the [`PoseNet`][handmesh_tutorial.nn.pose_encoder.PoseNet] (float32, eval
        mode) and the file's other entries (``architecture``, ``preprocessing``, ``history``,
        ``pretrained``, ``weights``, ``torch_version``, ``library_version``: the version that
        wrote the file, or for a shipped file of before 0.2.0 the version that shipped it).

    Raises:
        FileNotFoundError: no such file.
        ValueError: not a pose-encoder file, or its weights do not fit its architecture (the
            message names the file and the keys).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such pose-encoder file")
    try:
        blob = load_torch_file(path)
    except Exception as e:  # a truncated or foreign file: say which
        if isinstance(e, ValueError) and str(e).startswith(f"{path}:"):
            raise  # load_torch_file's refusal names the file and says why
        why = (str(e).strip().splitlines() or [type(e).__name__])[0][:160]
        raise ValueError(f"{path}: not a readable pose-encoder file ({type(e).__name__}: "
                         f"{why})") from e
    if not isinstance(blob, dict) or blob.get("format") != FORMAT:
        got = blob.get("format") if isinstance(blob, dict) else type(blob).__name__
        raise ValueError(f"{path}: format {got!r}, expected {FORMAT!r} (a file of "
                         "export_pose_encoder)")
    arch = blob["architecture"]
    net = build_pose_net(arch["backbone"], int(arch["num_joints"]))
    state = dequantize_state_dict(blob["model"], blob.get("scales") or {})
    missing, unexpected = net.load_state_dict(state, strict=False)
    if missing or unexpected:
        raise ValueError(f"{path}: weights do not fit a {arch['backbone']} PoseNet (missing "
                         f"{sorted(missing)[:5]}, unexpected {sorted(unexpected)[:5]})")
    net.eval()
    meta = {k: blob.get(k) for k in ("architecture", "preprocessing", "history", "pretrained",
                                     "weights", "torch_version")}
    meta["library_version"] = blob.get("library_version") or shipped_version(path)
    return net, meta


def pretrained_encoder_path(name: str = "pretrained") -> Path:
    """Path of a shipped pretrained encoder.

    Args:
        name: ``"pretrained"`` (the demo's encoder, `ENCODER_FILE`) or ``"neutral"`` (the
            decoder-neutral one, `NEUTRAL_ENCODER_FILE`: from random weights, never trained with
            a mesh decoder; the Table 3 ablation starts from it).

    Raises:
        FileNotFoundError: this installation has none (make ``"neutral"`` with ``make
            pretrained-encoder``, ``"pretrained"`` with ``handmesh pretrain-encoder --install``).
        ValueError: another name.
    """
    if name not in SHIPPED_ENCODERS:
        raise ValueError(f"shipped encoders are {sorted(SHIPPED_ENCODERS)}, got {name!r}")
    how = {"neutral": "make pretrained-encoder"}.get(name, "handmesh pretrain-encoder --install")
    return shipped_file(SHIPPED_ENCODERS[name], how)


def encoder_source_path(source: str | os.PathLike) -> Path:
    """``"pretrained"`` / ``"neutral"`` -> the shipped file's path; anything else is a path."""
    return pretrained_encoder_path(str(source)) if str(source) in SHIPPED_ENCODERS \
        else Path(source)


def pretrained_encoder(device: str = "cpu") -> KeypointEncoder:
    """The shipped pretrained hand encoder, in eval mode.

    Returns:
        A [`KeypointEncoder`][handmesh_tutorial.nn.keypoints.KeypointEncoder] (ResNet-10): images
        ``(B, 3, S, S)`` made as ``pretrained_encoder_info()["preprocessing"]`` says ->
        ``{"features": (B, 512), "uv": (B, 21, 2)}``.
    """
    net, _ = read_pose_encoder(pretrained_encoder_path())
    return net.encoder.to(device).eval()


def pretrained_encoder_info() -> dict:
    """What made the shipped encoder and how to feed it: ``architecture``, ``preprocessing``,
    ``history`` (validation rows), ``pretrained`` (command, seeds, scene counts, seconds,
    hardware, commit, date) and ``weights``."""
    return read_pose_encoder(pretrained_encoder_path())[1]


def encoder_lineage(meta: dict) -> dict:
    """Where a pose-encoder file's weights come from, walked back through its recorded runs.

    Args:
        meta: the file's metadata (``read_pose_encoder(path)[1]`` or
            [`pretrained_encoder_info`][handmesh_tutorial.nn.pose_encoder.pretrained_encoder_info]).

    Returns:
        ``{"runs", "origin", "decoder_neutral", "sentence"}``: ``runs`` one dict per training run,
        oldest first (``data_seed``, ``train_scenes``, ``steps`` when recorded, ``lr``);
        ``origin`` ``"random weights"``, ``"an MSMR-Net's encoder"`` (a network trained
        with the multi-path decoder with attention) or ``"unknown"``; ``decoder_neutral`` True
        only when the chain starts from random weights, so that no mesh decoder ever trained
        these weights; ``sentence`` the same in words.
    """
    nodes, origin, network = _encoder_runs((meta or {}).get("pretrained") or {})
    runs = []
    for node in nodes:
        recipe = node.get("recipe") or node.get("config") or {}
        data = node.get("data") or {}
        runs.append({"data_seed": data.get("train_seed", recipe.get("data_seed")),
                     "train_scenes": data.get("train_scenes"), "steps": node.get("steps"),
                     "lr": recipe.get("lr")})
    neutral = origin == "random weights"
    sentence = (f"{len(runs)} run(s) of keypoint and 3D-joint training (no mesh decoder), the "
                f"first from {origin}"
                + _network_words(network)
                + ("" if neutral or origin == "unknown" else
                   ", which was trained end to end with the multi-path decoder with attention")
                + "; scene seeds " + ", ".join(str(r["data_seed"]) for r in runs))
    return {"runs": runs, "origin": origin, "decoder_neutral": neutral, "sentence": sentence}


def _encoder_runs(node: dict) -> tuple[list[dict], str, dict | None]:
    """The run records of an encoder's chain, from ``node`` (its last run's ``pretrained``
    record) back through ``init_from``: ``(records oldest first, origin, network)``, ``origin``
    as `encoder_lineage` names it and ``network`` the record of the MSMR-Net whose encoder
    began the chain (None when not recorded). Shared with ``hmt.pretrained.lineage``."""
    nodes, origin, network = [], "unknown", None
    for _ in range(32):  # a recorded chain, never a cycle; bounded all the same
        nodes.append(node)
        recipe = node.get("recipe") or node.get("config") or {}
        init, parent = recipe.get("init", "unknown"), node.get("init_from")
        if init is None:
            origin = "random weights"
            break
        if init == "network" or (isinstance(parent, dict) and "made_by" in parent):
            origin = "an MSMR-Net's encoder"
            network = parent.get("made_by") if isinstance(parent, dict) else None
            break
        if not isinstance(parent, dict):
            break
        node = parent
    return nodes[::-1], origin, network


def _network_words(made: dict | None) -> str:
    """`` (the network whose last run trained on scene seed S, made DATE)`` or nothing."""
    if not isinstance(made, dict):
        return ""
    seed = (made.get("data") or {}).get("train_seed")
    return (f" (the network whose last run trained on scene seed {seed}, made "
            f"{made.get('date', 'on an unrecorded date')})" if seed is not None else "")


def load_pretrained_encoder(model: nn.Module, source: str | os.PathLike = "pretrained") -> dict:
    """Copy pretrained encoder weights into ``model.encoder``.

    An MSMR-Net built with ``keypoints=True`` (the CPU recipe) gets the whole
    [`KeypointEncoder`][handmesh_tutorial.nn.keypoints.KeypointEncoder]; one with the paper's plain
    ResNet encoder (global pooling) gets the ResNet part only, as ImageNet weights would be loaded.

    Args:
        model: the network whose ``encoder`` (or itself, for a bare encoder) receives the weights.
        source: ``"pretrained"`` or ``"neutral"`` (the shipped files) or the path of an
            [`export_pose_encoder`][handmesh_tutorial.nn.pose_encoder.export_pose_encoder] file.

    Returns:
        The file's metadata (see
        [`read_pose_encoder`][handmesh_tutorial.nn.pose_encoder.read_pose_encoder]).

    Raises:
        ValueError: the model's encoder has other shapes than the file's (e.g. another ResNet).
    """
    from .encoder import ResNet

    path = encoder_source_path(source)
    net, meta = read_pose_encoder(path)
    target = model if isinstance(model, KeypointEncoder | ResNet) else getattr(model, "encoder",
                                                                               None)
    if isinstance(target, KeypointEncoder):
        src = net.encoder
    elif isinstance(target, ResNet):
        src = net.encoder.backbone
    else:
        raise ValueError(f"{path}: the model's encoder is {type(target).__name__}; the file holds "
                         "a ResNet with a keypoint head (KeypointEncoder or its ResNet)")
    mine = {k: tuple(v.shape) for k, v in target.state_dict().items()}
    theirs = {k: tuple(v.shape) for k, v in src.state_dict().items()}
    if mine != theirs:
        diff = sorted(k for k in set(mine) | set(theirs) if mine.get(k) != theirs.get(k))
        raise ValueError(f"{path}: encoder shapes differ from the model's at {diff[:5]} "
                         f"(file backbone {meta['architecture']['backbone']})")
    target.load_state_dict(src.state_dict())
    return meta
