"""Pose-aware image features: a 2D keypoint head and features pooled at the predicted joints.

Not in the MSMR-Net paper (its encoder ends in global average pooling); borrowed from MobRecon
(Chen et al., CVPR 2022), whose encoder predicts 2D joint heat-maps and samples its feature map
at the joints ("pose pooling"). Why the tutorial needs it: trained **from scratch on a CPU**,
an encoder that ends in global average pooling learns the hand's position and 3D orientation
first and sits for thousands of steps on a plateau where it predicts one mean hand for every
image; finger articulation, a few pixels per finger in a 64-px crop, is lost in the pooled
vector. A 2D keypoint loss tells the encoder *where* each joint is, and features taken *at*
the joints carry what the fingers look like there, which is what leaves the plateau (docs page
"Why the paper starts from pretrained weights", "What training from random weights learns").

[`KeypointEncoder`][handmesh_tutorial.nn.keypoints.KeypointEncoder] wraps a
[`ResNet`][handmesh_tutorial.nn.encoder.ResNet]:

1. a small feature pyramid (1x1 lateral convs, nearest up-sampling, sum) brings stages 2-4 to
   stride 8 (an 8x8 map for a 64-px crop) with ``width`` channels;
2. a 1x1 conv gives one heat-map per joint; a spatial soft-argmax (integral regression, Sun et
   al. 2018) turns each into a sub-pixel position ``uv`` in normalised crop coordinates;
3. the pyramid map is sampled bilinearly at the ``J`` positions, concatenated with the global
   average of stage 4 and mapped by a linear layer + ReLU to ``out_features`` (the decoder's
   input, as the plain encoder's pooled vector).

Coordinates: ``uv`` in ``[-1, 1]`` with ``-1`` the left/top edge of the crop and ``+1`` the
right/bottom edge (``grid_sample`` with ``align_corners=False``); a pixel position ``u`` (pixel
centres at integers, as [`crop_transform`][handmesh_tutorial.data.augment.crop_transform]) is
``(2 u + 1) / S - 1``
([`normalised_keypoints`][handmesh_tutorial.nn.keypoints.normalised_keypoints]).

Taught in notebook 08 ("Training"); notebook 07 ("Multi-path mesh decoder", section 4) opens it
on one image of the shipped network: the shapes of every step, its 2D joints and a heat-map.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from ..render.camera import project
from .encoder import ResNet

__all__ = ["KeypointEncoder", "soft_argmax", "normalised_keypoints", "keypoint_loss"]


def soft_argmax(heatmaps: torch.Tensor) -> torch.Tensor:
    """Expected position of each heat-map's softmax distribution (integral regression).

    Args:
        heatmaps: ``(B, J, H, W)`` logits.

    Returns:
        ``(B, J, 2)`` positions ``(x, y)`` in ``[-1, 1]`` (cell centres at ``(2 i + 1) / W - 1``).
    """
    b, j, h, w = heatmaps.shape
    prob = heatmaps.flatten(2).softmax(-1).view(b, j, h, w)
    xs = (2 * torch.arange(w, dtype=prob.dtype, device=prob.device) + 1) / w - 1
    ys = (2 * torch.arange(h, dtype=prob.dtype, device=prob.device) + 1) / h - 1
    return torch.stack([(prob.sum(2) * xs).sum(-1), (prob.sum(3) * ys).sum(-1)], -1)


def normalised_keypoints(joints: torch.Tensor, root: torch.Tensor, K: torch.Tensor,
                         image_size: int) -> torch.Tensor:
    """2D targets of the keypoint head: the joints projected into the crop, normalised.

    Args:
        joints: ``(B, J, 3)`` root-relative joints (a training item's ``joints``), metres.
        root: ``(B, 3)`` the root in the crop's camera frame (the item's ``root``).
        K: ``(B, 3, 3)`` the crop's intrinsics (the item's ``K``).
        image_size: crop side ``S``, pixels.

    Returns:
        ``(B, J, 2)`` positions in ``[-1, 1]`` (outside when a joint leaves the crop).
    """
    uv = project(joints + root[:, None, :], K)
    return (2 * uv + 1) / image_size - 1


def keypoint_loss(pred_uv: torch.Tensor, target_uv: torch.Tensor) -> torch.Tensor:
    """Mean L1 distance of normalised 2D keypoints (1 unit = half the crop side)."""
    if pred_uv.shape != target_uv.shape:
        raise ValueError(f"pred_uv {tuple(pred_uv.shape)} and target_uv "
                         f"{tuple(target_uv.shape)} differ")
    return (pred_uv - target_uv).abs().mean()


class KeypointEncoder(nn.Module):
    """A ResNet with a 2D keypoint head whose features are pooled at the predicted joints.

    Args:
        backbone: a [`ResNet`][handmesh_tutorial.nn.encoder.ResNet] (basic or bottleneck blocks).
        num_joints: ``J``, heat-maps / pooled positions.
        width: channels of the stride-8 pyramid map.
        out_features: ``D``, width of the returned feature vector.

    Attributes:
        out_features: ``D``.

    Shapes:
        ``images (B, 3, H, W)`` -> ``{"features": (B, D), "uv": (B, J, 2)}``.
    """

    def __init__(self, backbone: nn.Module, num_joints: int = 21, width: int = 128,
                 out_features: int = 512):
        super().__init__()
        if not isinstance(backbone, ResNet):
            raise ValueError(f"KeypointEncoder needs a ResNet backbone, got "
                             f"{type(backbone).__name__}")
        self.backbone = backbone
        c4 = backbone.out_features
        c3, c2 = c4 // 2, c4 // 4
        self.lateral = nn.ModuleList([nn.Conv2d(c, width, 1) for c in (c4, c3, c2)])
        self.smooth = nn.Sequential(nn.Conv2d(width, width, 3, 1, 1, bias=False),
                                    nn.BatchNorm2d(width), nn.ReLU(inplace=True))
        self.heatmaps = nn.Conv2d(width, num_joints, 1)
        self.fuse = nn.Sequential(nn.Linear(num_joints * width + c4, out_features),
                                  nn.ReLU(inplace=True))
        self.num_joints = num_joints
        self.out_features = out_features

    def forward(self, images: torch.Tensor) -> dict[str, torch.Tensor]:
        """Args: images ``(B, 3, H, W)``. Returns ``features`` ``(B, D)``, ``uv`` ``(B, J, 2)``."""
        c2, c3, c4 = self.backbone.forward_stages(images)[1:]
        p = self.lateral[0](c4)
        for lat, c in zip(self.lateral[1:], (c3, c2), strict=True):
            p = F.interpolate(p, size=c.shape[-2:], mode="nearest") + lat(c)
        p = self.smooth(p)
        uv = soft_argmax(self.heatmaps(p))
        # bilinear samples of the pyramid at the joints: (B, C, J, 1) -> (B, J * C)
        pooled = F.grid_sample(p, uv.unsqueeze(2), align_corners=False).squeeze(-1)
        glob = c4.mean((2, 3))
        features = self.fuse(torch.cat([pooled.transpose(1, 2).flatten(1), glob], 1))
        return {"features": features, "uv": uv}
