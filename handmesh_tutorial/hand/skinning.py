"""Rotations, linear blend skinning along a kinematic tree, and right/left mirroring (torch).

[`axis_angle_to_matrix`][handmesh_tutorial.hand.skinning.axis_angle_to_matrix] (Rodrigues, batched,
differentiable) and [`lbs`][handmesh_tutorial.hand.skinning.lbs] are the skinning both
[`HandModel`][handmesh_tutorial.hand.model.HandModel] and
[`ManoModel`][handmesh_tutorial.hand.mano.model.ManoModel] use: joint k's rotation is expressed in
the rest-pose axes, relative to its parent, applied about the joint. The left hand is the mirror of
the
right through z = 0: points mirror as ``(x, y, z) -> (x, y, -z)``
([`mirror_points`][handmesh_tutorial.hand.skinning.mirror_points]), axis-angle rotations as
``(x, y, z) -> (-x, -y, z)``
([`mirror_axis_angle`][handmesh_tutorial.hand.skinning.mirror_axis_angle]).

Taught in notebook 01 (the hand model).
"""

from __future__ import annotations

import numpy as np
import torch

from .joints import MIRROR_AXIS

__all__ = ["axis_angle_to_matrix", "lbs", "mirror_points", "mirror_axis_angle"]


def axis_angle_to_matrix(rotvec: torch.Tensor) -> torch.Tensor:
    """Rodrigues' formula, batched and differentiable (also at zero rotation).

    Args:
        rotvec: (...,3) axis-angle vectors, radians.

    Returns:
        (...,3,3) rotation matrices (exactly the identity for a zero vector).
    """
    theta2 = (rotvec * rotvec).sum(-1, keepdim=True)[..., None]           # (...,1,1)
    theta = torch.sqrt(theta2 + 1e-16)
    x, y, z = rotvec.unbind(-1)
    zero = torch.zeros_like(x)
    k = torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).reshape(*rotvec.shape[:-1], 3, 3)
    small = theta2 < 1e-8
    # sin(t)/t and (1-cos t)/t^2 with Taylor series near 0 (exact gradients at the identity).
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / (theta2 + 1e-30))
    eye = torch.eye(3, dtype=rotvec.dtype, device=rotvec.device)
    return eye + a * k + b * (k @ k)


def lbs(vertices: torch.Tensor, joints: torch.Tensor, rotations: torch.Tensor,
        weights: torch.Tensor, parents) -> tuple[torch.Tensor, torch.Tensor]:
    """Linear blend skinning along a kinematic tree.

    Args:
        vertices: (B,V,3) rest (shaped) vertices.
        joints: (B,J,3) rest joints.
        rotations: (B,J,3,3) local rotations; joint k's rotation is expressed in the rest-pose
            axes and applied about joint k, after its parent's (``rotations[:,0]`` = global).
        weights: (V,J) skinning weights.
        parents: (J,) parent indices, -1 for the root, parents before children.

    Returns:
        ``(posed vertices (B,V,3), world transforms (B,J,4,4))``; transform k maps the joint's
        rest frame (axes of the template, origin at joint k) to the posed world.
    """
    batch, n = rotations.shape[:2]
    rot_w = [rotations[:, 0]]
    pos_w = [joints[:, 0]]
    for k in range(1, n):
        p = int(parents[k])
        rot_w.append(rot_w[p] @ rotations[:, k])
        pos_w.append(pos_w[p] + (rot_w[p] @ (joints[:, k] - joints[:, p])[..., None])[..., 0])
    rot_w = torch.stack(rot_w, 1)                                          # (B,J,3,3)
    pos_w = torch.stack(pos_w, 1)                                          # (B,J,3)
    trans = pos_w - (rot_w @ joints[..., None])[..., 0]                    # t_k = p_k - R_k J_k
    blend_r = torch.einsum("vj,bjrc->bvrc", weights, rot_w)
    blend_t = torch.einsum("vj,bjc->bvc", weights, trans)
    posed = (blend_r @ vertices[..., None])[..., 0] + blend_t
    bottom = torch.zeros(batch, n, 1, 4, dtype=rot_w.dtype, device=rot_w.device)
    bottom[..., 0, 3] = 1
    transforms = torch.cat([torch.cat([rot_w, pos_w[..., None]], -1), bottom], -2)
    return posed, transforms


def mirror_points(points):
    """Mirror points (or vectors) between right and left: negate
    [`MIRROR_AXIS`][handmesh_tutorial.hand.joints.MIRROR_AXIS] (z).

    Args:
        points: (...,3) numpy array or torch tensor.

    Returns:
        The mirrored copy, same type and shape.
    """
    sign = [1.0, 1.0, 1.0]
    sign[MIRROR_AXIS] = -1.0
    if isinstance(points, torch.Tensor):
        return points * points.new_tensor(sign)
    return np.asarray(points) * np.asarray(sign)


def mirror_axis_angle(rotvec):
    """Mirror axis-angle rotations (pose or global_orient) between right and left.

    A rotation R seen in a mirror is M R M with M = diag(1,1,-1); its axis-angle vector is
    ``-M r``, i.e. ``(x, y, z) -> (-x, -y, z)``. Works for (...,3) and (B,45) layouts.

    Args:
        rotvec: (...,3) or (B,45) numpy array or torch tensor, radians.

    Returns:
        The mirrored copy, same type and shape.
    """
    sign = [-1.0, -1.0, -1.0]
    sign[MIRROR_AXIS] = 1.0
    if isinstance(rotvec, torch.Tensor):
        shp = rotvec.shape
        return (rotvec.reshape(*shp[:-1], -1, 3) * rotvec.new_tensor(sign)).reshape(shp)
    r = np.asarray(rotvec)
    return (r.reshape(*r.shape[:-1], -1, 3) * np.asarray(sign)).reshape(r.shape)

