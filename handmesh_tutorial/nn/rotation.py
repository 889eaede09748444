"""A global-rotation head: the hand's 3D orientation predicted apart from its shape.

Not in the MSMR-Net paper, whose decoder writes every vertex in the camera frame. Trained from
scratch on a CPU, that decoder must express each hand's orientation through per-vertex outputs;
small errors in a large rotation then show up as a crumpled surface. With this head the network
predicts one rotation ``R`` from the image features (the continuous 6D representation of Zhou
et al., CVPR 2019: two 3D vectors, Gram-Schmidt orthonormalised) and the decoder's mesh is
rotated by it about the root (joint 9, the origin of the network frame), so the decoder is left
with the hand's articulation; it halves the surface roughness (docs page "Why the paper starts
from pretrained weights").

The head starts at the identity (zero weights, bias = the 6D code of ``I``), so an untrained
model still outputs the template. Taught in notebook 08 ("Training").
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["rotation_6d_to_matrix", "matrix_to_rotation_6d", "GlobalRotationHead"]


def rotation_6d_to_matrix(d6: torch.Tensor) -> torch.Tensor:
    """Rotation matrices from the 6D representation (Zhou et al. 2019).

    Args:
        d6: ``(..., 6)``: two 3D vectors ``a, b`` (any length, not parallel).

    Returns:
        ``(..., 3, 3)`` proper rotations whose **columns** are ``a / |a|``, the part of ``b``
        orthogonal to it, normalised, and their cross product.
    """
    if d6.shape[-1] != 6:
        raise ValueError(f"expected (..., 6), got {tuple(d6.shape)}")
    a = F.normalize(d6[..., :3], dim=-1)
    b = d6[..., 3:]
    b = F.normalize(b - (a * b).sum(-1, keepdim=True) * a, dim=-1)
    return torch.stack([a, b, torch.cross(a, b, dim=-1)], dim=-1)


def matrix_to_rotation_6d(rot: torch.Tensor) -> torch.Tensor:
    """The inverse of [`rotation_6d_to_matrix`][handmesh_tutorial.nn.rotation.rotation_6d_to_matrix]
    for rotations: the first two columns.

    Args:
        rot: ``(..., 3, 3)`` rotation matrices.

    Returns:
        ``(..., 6)``.
    """
    return torch.cat([rot[..., :, 0], rot[..., :, 1]], dim=-1)


class GlobalRotationHead(nn.Module):
    """Linear map from image features to a rotation, initialised to the identity.

    Args:
        in_features: ``D``.

    Shapes:
        ``(B, D) -> (B, 3, 3)``.
    """

    def __init__(self, in_features: int):
        super().__init__()
        self.linear = nn.Linear(in_features, 6)
        nn.init.zeros_(self.linear.weight)
        with torch.no_grad():
            self.linear.bias.copy_(matrix_to_rotation_6d(torch.eye(3)))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """Args: features ``(B, D)``. Returns ``(B, 3, 3)`` rotations."""
        return rotation_6d_to_matrix(self.linear(features))
