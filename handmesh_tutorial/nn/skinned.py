"""A skinned output for the mesh decoder: per-joint rotations and shape, then linear blend skinning.

Not in the MSMR-Net paper (its decoder regresses vertex coordinates); an option of
[`build_model`][handmesh_tutorial.nn.model.build_model] (``output="skinned"``) beside the default
per-vertex affine field. Why: the decoder's per-vertex outputs carry vertex-level noise, and a
hand surface is very sensitive to it (0.3 mm of independent noise per vertex is about 3 degrees of
roughness; [`handmesh_tutorial.metrics.surface`][handmesh_tutorial.metrics.surface]). Smoothing the
field lowers the noise but also blurs the sharp change of the transform at each knuckle. The skinned
output
removes the noise by construction: the decoder's field is *pooled* per bone with the template's
skinning weights, read as one local rotation per joint (continuous 6D representation, Zhou et al.
2019) and, pooled over the whole hand, as the template's shape parameters; the vertices are then
the template's [`lbs`][handmesh_tutorial.hand.lbs] for that pose and shape. Every output is a
skinned hand, as smooth as the template, and every skinned hand of the template (pose and shape)
is an output. The decoder still does all the work of turning image features into a per-vertex
field; it only no longer decides each vertex on its own.

The price: the output cannot leave the template's pose-and-shape space (no soft-tissue
deformation the skinning does not model, no object of another topology). For INTER-SH, whose hands
*are* skinned templates, that space contains every target.

Layout of the decoder's field ``(B, V, 6 + S)``: channels ``0:6`` the 6D code of each joint's local
rotation *minus* the identity's code (so a zero field is the rest pose), channels ``6:`` the ``S``
shape parameters. Joint ``j`` reads the skinning-weighted mean of channels ``0:6`` over the
vertices it moves; the shape is the mean over all vertices.

Taught in notebook 07 ("Multi-path mesh decoder", the fit test).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from ..hand import lbs
from .rotation import matrix_to_rotation_6d, rotation_6d_to_matrix

__all__ = ["SkinnedOutput", "skinning_of"]


def skinning_of(source) -> dict[str, np.ndarray]:
    """The skinning data of a hand model, as
    [`SkinnedOutput`][handmesh_tutorial.nn.skinned.SkinnedOutput] needs it.

    Args:
        source: a [`HandModel`][handmesh_tutorial.hand.HandModel] (or any object with
            ``template_vertices`` (V,3), ``skinning_weights`` (V,J), ``rest_joints`` (J,3),
            ``parents`` (J,), and optionally ``shape_dirs`` (V,3,S) with ``j_shapedirs`` (J,3,S)).

    Returns:
        dict with ``vertices``, ``weights``, ``joints``, ``parents`` and, when the model has a
        shape space, ``shape_dirs`` and ``joint_shape_dirs`` (numpy, the model's frame, metres).

    Raises:
        ValueError: an attribute is missing or shapes disagree (the message names it).
    """
    def get(name):
        value = getattr(source, name, None)
        if value is None:
            raise ValueError(f"output='skinned' needs a hand model with skinning data; "
                             f"{type(source).__name__} has no {name!r}")
        return value.detach().cpu().numpy() if torch.is_tensor(value) else np.asarray(value)

    out = {"vertices": get("template_vertices").astype(np.float64),
           "weights": get("skinning_weights").astype(np.float64),
           "joints": get("rest_joints").astype(np.float64),
           "parents": get("parents").astype(np.int64)}
    v, j = len(out["vertices"]), len(out["joints"])
    if out["weights"].shape != (v, j) or out["parents"].shape != (j,):
        raise ValueError(f"skinning weights {out['weights'].shape} and parents "
                         f"{out['parents'].shape} do not fit {v} vertices and {j} joints")
    if getattr(source, "shape_dirs", None) is not None and \
            getattr(source, "j_shapedirs", None) is not None:
        out["shape_dirs"] = get("shape_dirs").astype(np.float64)
        out["joint_shape_dirs"] = get("j_shapedirs").astype(np.float64)
        s = out["shape_dirs"].shape[-1]
        if out["shape_dirs"].shape != (v, 3, s) or out["joint_shape_dirs"].shape != (j, 3, s):
            raise ValueError(f"shape_dirs {out['shape_dirs'].shape} and j_shapedirs "
                             f"{out['joint_shape_dirs'].shape} do not fit {v} vertices and "
                             f"{j} joints")
    return out


class SkinnedOutput(nn.Module):
    """Decoder field ``(B, V, 6 + S)`` -> a posed, shaped template ``(B, V, 3)`` (root at 0).

    Args:
        vertices: ``(V, 3)`` rest template, metres (any frame; the output is re-centred).
        weights: ``(V, J)`` skinning weights, rows sum to 1.
        joints: ``(J, 3)`` rest joints in the frame of ``vertices``.
        parents: ``(J,)`` parent of each joint, ``-1`` for the root, parents first.
        root_joint: the joint whose posed position is moved to the origin, like the training
            targets (for MANO's 16-joint tree, the middle-finger MCP, FreiHAND keypoint 9).
        shape_dirs: ``(V, 3, S)`` vertex offsets per unit of each shape parameter, or ``None``
            (``S = 0``).
        joint_shape_dirs: ``(J, 3, S)`` joint offsets per unit of each shape parameter.

    Attributes:
        channels: ``6 + S``, the decoder field's width.

    Shapes:
        ``field (B, V, 6 + S)`` -> ``vertices (B, V, 3)``, metres.
    """

    def __init__(self, vertices, weights, joints, parents, root_joint: int, shape_dirs=None,
                 joint_shape_dirs=None):
        super().__init__()
        f32 = torch.float32
        w = torch.as_tensor(np.asarray(weights), dtype=f32)
        v = torch.as_tensor(np.asarray(vertices), dtype=f32)
        if w.dim() != 2 or w.shape[0] != v.shape[0]:
            raise ValueError(f"weights must be (V, J) with V = {v.shape[0]}, got {tuple(w.shape)}")
        mass = w.sum(0)
        if (mass <= 0).any():
            raise ValueError(f"joints {torch.nonzero(mass <= 0).flatten().tolist()} move no vertex")
        self.parents = [int(p) for p in np.asarray(parents)]
        self.register_buffer("vertices", v, persistent=False)
        self.register_buffer("weights", w, persistent=False)
        self.register_buffer("pool", (w / mass).T.contiguous(), persistent=False)  # (J, V)
        self.register_buffer("joints", torch.as_tensor(np.asarray(joints), dtype=f32),
                             persistent=False)
        if not 0 <= int(root_joint) < w.shape[1]:
            raise ValueError(f"root_joint must lie in [0, {w.shape[1]}), got {root_joint}")
        self.root_joint = int(root_joint)
        self.register_buffer("identity6d", matrix_to_rotation_6d(torch.eye(3)), persistent=False)
        if shape_dirs is None:
            self.num_shape = 0
            self.vdirs = self.jdirs = None
        else:
            self.register_buffer("vdirs", torch.as_tensor(np.asarray(shape_dirs), dtype=f32),
                                 persistent=False)
            self.register_buffer("jdirs", torch.as_tensor(np.asarray(joint_shape_dirs),
                                                          dtype=f32), persistent=False)
            self.num_shape = int(self.vdirs.shape[-1])
        self.channels = 6 + self.num_shape

    def pose_and_shape(self, field: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The field read as ``(local rotations (B, J, 3, 3), shape (B, S))``."""
        if field.dim() != 3 or field.shape[1:] != (len(self.vertices), self.channels):
            raise ValueError(f"field must be (B, {len(self.vertices)}, {self.channels}), got "
                             f"{tuple(field.shape)}")
        codes = torch.einsum("jv,bvc->bjc", self.pool.to(field.dtype), field[..., :6])
        rotations = rotation_6d_to_matrix(codes + self.identity6d.to(field.dtype))
        return rotations, field[..., 6:].mean(1)

    def forward(self, field: torch.Tensor) -> torch.Tensor:
        """Args: field ``(B, V, 6 + S)``. Returns vertices ``(B, V, 3)``, root at the origin."""
        rotations, shape = self.pose_and_shape(field)
        batch, dt = field.shape[0], field.dtype
        verts = self.vertices.to(dt).expand(batch, -1, -1)
        joints = self.joints.to(dt).expand(batch, -1, -1)
        if self.num_shape:
            verts = verts + torch.einsum("vcs,bs->bvc", self.vdirs.to(dt), shape)
            joints = joints + torch.einsum("jcs,bs->bjc", self.jdirs.to(dt), shape)
        posed, transforms = lbs(verts, joints, rotations, self.weights.to(dt), self.parents)
        return posed - transforms[:, self.root_joint, None, :3, 3]
