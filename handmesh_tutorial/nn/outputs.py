"""What the decoder's per-vertex field means: output modules, field ``(B, V, C)`` -> vertices
``(B, V, 3)`` in metres, root at the origin.

* [`AffineOutput`][handmesh_tutorial.nn.outputs.AffineOutput] (``"affine"``, the default): per
  vertex a linear map and a translation applied to the root-centred template vertex,
  ``v = (I + A_v) p_v + s t_v``;
* [`OffsetOutput`][handmesh_tutorial.nn.outputs.OffsetOutput] (``"offset"``): ``v = p_v + s d_v``;
* [`XYZOutput`][handmesh_tutorial.nn.outputs.XYZOutput] (``"xyz"``, the paper's): ``v = s d_v``;
* [`SkinnedOutput`][handmesh_tutorial.nn.skinned.SkinnedOutput] (``"skinned"``): joint rotations
  and shape pooled from the field, then linear blend skinning of the template.

Each module has ``channels`` (the field width the decoder must produce) and ``name``;
[`make_output`][handmesh_tutorial.nn.outputs.make_output] builds one by name, and
[`build_model`][handmesh_tutorial.nn.model.build_model] takes a name or any module with
``channels`` (``output=``). A module whose ``smooth_field`` is ``False`` gets no output smoothing.
Why the affine field is the default (fits of the four against known hands): docs page "The
network". Taught in notebook 07 ("The multi-path decoder").
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from .mesh_template import as_template, root_centred_template
from .skinned import SkinnedOutput, skinning_of

__all__ = ["OUTPUTS", "XYZOutput", "OffsetOutput", "AffineOutput", "make_output",
           "skinned_output"]

OUTPUTS = ("xyz", "offset", "affine", "skinned")
"""The output modules' names, as [`build_model`][handmesh_tutorial.nn.model.build_model]'s
``output=`` takes them."""


def _check(field: torch.Tensor, vertices: int | None, channels: int) -> None:
    if field.dim() != 3 or field.shape[2] != channels or (vertices is not None
                                                          and field.shape[1] != vertices):
        v = "V" if vertices is None else vertices
        raise ValueError(f"field must be (B, {v}, {channels}), got {tuple(field.shape)}")


class XYZOutput(nn.Module):
    """The field is the vertices, scaled: ``v = s d_v`` (the paper's decoder).

    Args:
        scale: ``s``, metres per field unit.

    Shapes:
        ``field (B, V, 3)`` -> ``vertices (B, V, 3)``, metres.
    """

    name = "xyz"
    channels = 3

    def __init__(self, scale: float = 0.1):
        super().__init__()
        self.scale = float(scale)

    def forward(self, field: torch.Tensor) -> torch.Tensor:
        """Args: field ``(B, V, 3)``. Returns ``(B, V, 3)`` vertices, metres."""
        _check(field, None, self.channels)
        return field * self.scale


class OffsetOutput(nn.Module):
    """The field moves the root-centred template: ``v = p_v + s d_v``.

    Args:
        template_vertices: ``(V, 3)`` root-centred template ``p``, metres (a non-persistent
            buffer: rebuilt from the template, not saved).
        scale: ``s``, metres per field unit.

    Shapes:
        ``field (B, V, 3)`` -> ``vertices (B, V, 3)``, metres.
    """

    name = "offset"
    channels = 3

    def __init__(self, template_vertices, scale: float = 0.1):
        super().__init__()
        tv = torch.as_tensor(np.asarray(template_vertices), dtype=torch.float32)
        if tv.dim() != 2 or tv.shape[1] != 3:
            raise ValueError(f"template_vertices must be (V, 3), got {tuple(tv.shape)}")
        self.register_buffer("template", tv, persistent=False)
        self.scale = float(scale)

    def forward(self, field: torch.Tensor) -> torch.Tensor:
        """Args: field ``(B, V, 3)``. Returns ``(B, V, 3)`` vertices, metres."""
        _check(field, len(self.template), self.channels)
        return self.template.to(field.dtype) + field * self.scale


class AffineOutput(OffsetOutput):
    """A linear map and a translation per vertex: ``v = (I + A_v) p_v + s t_v``.

    A skinned hand has exactly this form (``A_v``, ``t_v`` the skinning-weighted blends of the bone
    transforms), and that field is smooth, so output smoothing costs it little. A zero field is the
    template.

    Args:
        template_vertices: ``(V, 3)`` root-centred template ``p``, metres.
        scale: ``s``, metres per unit of the translation ``t_v`` (``A_v`` is unscaled).

    Shapes:
        ``field (B, V, 12)`` (9 entries of ``A_v`` row-major, then 3 of ``t_v``) ->
        ``vertices (B, V, 3)``, metres.
    """

    name = "affine"
    channels = 12

    def forward(self, field: torch.Tensor) -> torch.Tensor:
        """Args: field ``(B, V, 12)``. Returns ``(B, V, 3)`` vertices, metres."""
        _check(field, len(self.template), self.channels)
        tmpl = self.template.to(field.dtype)
        lin = field[..., :9].unflatten(-1, (3, 3))
        return tmpl + torch.einsum("bvrc,vc->bvr", lin, tmpl) + field[..., 9:] * self.scale


def skinned_output(template=None, skinning=None) -> SkinnedOutput:
    """The skinned output for a template.

    Args:
        template: anything [`as_template`][handmesh_tutorial.nn.mesh_template.as_template]
            accepts (default the library's right hand).
        skinning: the hand model whose skinning weights, joints and shape space are used
            (default: ``template`` when it has them, else the library's right hand).

    Returns:
        A [`SkinnedOutput`][handmesh_tutorial.nn.skinned.SkinnedOutput] whose root is the
        training targets' (keypoint 9, the middle MCP, on MANO's 16-joint tree).

    Raises:
        ValueError: the skinning model's rest vertices are not the template's.
    """
    tmpl = as_template(template)
    if skinning is None:
        skinning = template if getattr(template, "skinning_weights", None) is not None else None
    if skinning is None:
        from ..hand import HandModel

        skinning = HandModel("right")
    data = skinning_of(skinning)
    if data["vertices"].shape != tmpl.vertices.shape or \
            np.abs(data["vertices"] - tmpl.vertices).max() > 1e-6:
        raise ValueError(f"output='skinned': the skinning model's rest vertices "
                         f"{data['vertices'].shape} are not the template's "
                         f"{tmpl.vertices.shape}; pass skinning= the template's hand model")
    from ..hand import MANO_TO_FREIHAND

    # the targets' root is keypoint 9 (middle MCP): MANO joint 4 on a 16-joint tree
    root = int(MANO_TO_FREIHAND[9]) if len(data["joints"]) == 16 else 0
    return SkinnedOutput(data["vertices"], data["weights"], data["joints"], data["parents"],
                         root, data.get("shape_dirs"), data.get("joint_shape_dirs"))


def make_output(kind: str, template=None, scale: float = 0.1, skinning=None) -> nn.Module:
    """An output module by name.

    Args:
        kind: one of [`OUTPUTS`][handmesh_tutorial.nn.outputs.OUTPUTS].
        template: anything [`as_template`][handmesh_tutorial.nn.mesh_template.as_template]
            accepts (default the library's right hand; unused by ``"xyz"``).
        scale: metres per field unit (``"xyz"``, ``"offset"``, the translation of ``"affine"``).
        skinning: for ``"skinned"``, see
            [`skinned_output`][handmesh_tutorial.nn.outputs.skinned_output].

    Returns:
        The module, field ``(B, V, channels)`` -> vertices ``(B, V, 3)``.

    Raises:
        ValueError: unknown ``kind``.
    """
    if kind not in OUTPUTS:
        raise ValueError(f"output must be one of {OUTPUTS}, got {kind!r}")
    if kind == "xyz":
        return XYZOutput(scale)
    if kind == "skinned":
        return skinned_output(template, skinning)
    cls = AffineOutput if kind == "affine" else OffsetOutput
    return cls(root_centred_template(template), scale)
