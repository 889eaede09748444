"""Training losses: the paper's L1 vertex loss and the optional terms of the CPU recipe.

The paper trains MSMR-Net with one loss, the L1 distance of predicted to true vertices
([`vertex_loss`][handmesh_tutorial.nn.losses.vertex_loss]);
[`TrainConfig`][handmesh_tutorial.train.TrainConfig] keeps that as its default. Training from
scratch on a CPU for minutes needs more guidance; the optional terms, each weighted by a
``TrainConfig`` field (0 = off), are those standard in the field:

* [`keypoint_loss`][handmesh_tutorial.nn.keypoints.keypoint_loss] (``keypoint_weight``): L1 of the
  2D keypoint head's normalised joint positions (MobRecon);
* [`aligned_joint_loss`][handmesh_tutorial.nn.losses.aligned_joint_loss] (``aligned_weight``): L1 of
  the joints after a differentiable similarity (Procrustes) alignment to the truth. The vertex loss
  is dominated by the global orientation (a 10 degree tilt moves a fingertip by 15 mm); the aligned
  term is the part of the error the PA- metrics measure, the hand's articulation;
* [`edge_length_loss`][handmesh_tutorial.nn.losses.edge_length_loss] (``edge_weight``) and
  [`normal_loss`][handmesh_tutorial.nn.losses.normal_loss] (``normal_weight``): the mesh
  regularisers of CMR / MobRecon (Chen et al. 2021, 2022) against crumpled surfaces.

All take metres and return scalar tensors. Taught in notebook 08 ("Training").
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["vertex_loss", "aligned_joint_loss", "similarity_align", "edge_length_loss",
           "normal_loss"]


def _check_pair(pred: torch.Tensor, target: torch.Tensor) -> None:
    if pred.shape != target.shape:
        raise ValueError(f"pred {tuple(pred.shape)} and target {tuple(target.shape)} differ")
    if pred.dim() != 3 or pred.shape[-1] != 3:
        raise ValueError(f"expected (B, P, 3) point sets, got {tuple(pred.shape)}")


def vertex_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """The paper's L1 vertex loss, as a mean over vertices and coordinates.

    Args:
        pred: ``(B, V, 3)`` predicted vertices, metres.
        target: ``(B, V, 3)`` ground truth (root-centred), metres.

    Returns:
        Scalar tensor: ``mean |pred - target|`` (metres).
    """
    if pred.shape != target.shape:
        raise ValueError(f"pred {tuple(pred.shape)} and target {tuple(target.shape)} differ")
    return (pred - target).abs().mean()


def similarity_align(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """``pred`` moved by the similarity transform (rotation, scale, translation) that best
    fits it to ``target`` in least squares (Umeyama 1991; proper rotations only), differentiable.

    Args:
        pred: ``(B, P, 3)`` points.
        target: ``(B, P, 3)`` points.

    Returns:
        ``(B, P, 3)`` the aligned ``pred``. Computed in float64 (the SVD's gradient is
        ill-conditioned near repeated singular values in float32).
    """
    _check_pair(pred, target)
    p, t = pred.double(), target.double()
    mp, mt = p.mean(1, keepdim=True), t.mean(1, keepdim=True)
    a, b = p - mp, t - mt
    u, s, vh = torch.linalg.svd(b.transpose(1, 2) @ a)  # (B, 3, 3): target^T pred
    d = torch.sign(torch.det(u @ vh))
    d = torch.where(d == 0, torch.ones_like(d), d)
    signs = torch.stack([torch.ones_like(d), torch.ones_like(d), d], -1)
    rot = u @ torch.diag_embed(signs) @ vh
    scale = (s * signs).sum(-1) / (a ** 2).sum((1, 2)).clamp_min(1e-12)
    return (scale[:, None, None] * a @ rot.transpose(1, 2) + mt).to(pred.dtype)


def aligned_joint_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """L1 of points after [`similarity_align`][handmesh_tutorial.nn.losses.similarity_align] (the
    loss behind PA-MPJPE).

    Args:
        pred: ``(B, J, 3)`` predicted joints, metres.
        target: ``(B, J, 3)`` true joints, metres.

    Returns:
        Scalar tensor, metres (mean over points and coordinates).
    """
    return (similarity_align(pred, target) - target).abs().mean()


def _edges(faces: torch.Tensor) -> torch.Tensor:
    e = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return torch.unique(torch.sort(e, dim=1).values, dim=0)


def edge_length_loss(pred: torch.Tensor, target: torch.Tensor,
                     faces: torch.Tensor) -> torch.Tensor:
    """L1 difference of every mesh edge's length to the true one (CMR's edge loss).

    Args:
        pred: ``(B, V, 3)`` predicted vertices, metres.
        target: ``(B, V, 3)`` true vertices, metres.
        faces: ``(F, 3)`` int64 triangles.

    Returns:
        Scalar tensor, metres (mean over unique edges).
    """
    _check_pair(pred, target)
    e = _edges(faces)

    def lengths(v):
        return (v[:, e[:, 0]] - v[:, e[:, 1]]).norm(dim=-1)

    return (lengths(pred) - lengths(target)).abs().mean()


def normal_loss(pred: torch.Tensor, target: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """Mean ``|cos|`` between each predicted face's edges and the true face normal (CMR's
    normal loss): 0 when every predicted face lies in the plane of its true counterpart.

    Args:
        pred: ``(B, V, 3)`` predicted vertices, metres.
        target: ``(B, V, 3)`` true vertices, metres.
        faces: ``(F, 3)`` int64 triangles.

    Returns:
        Scalar tensor (dimensionless, in ``[0, 1]``).
    """
    _check_pair(pred, target)
    t0, t1, t2 = (target[:, faces[:, k]] for k in range(3))
    n = F.normalize(torch.cross(t1 - t0, t2 - t0, dim=-1), dim=-1)
    p = [pred[:, faces[:, k]] for k in range(3)]
    terms = [(F.normalize(p[b] - p[a], dim=-1) * n).sum(-1).abs()
             for a, b in ((0, 1), (1, 2), (2, 0))]
    return torch.stack(terms).mean()
