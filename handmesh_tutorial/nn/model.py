"""MSMR-Net: image encoder -> FC -> coarse mesh -> transformer -> mesh decoder -> vertices, joints.

Paper section "Multi-path Mesh Decoder" (architecture figure) and Table 3 (ablation). The model:

1. ``encoder`` (ResNet / HRNet, [`handmesh_tutorial.nn.encoder`][handmesh_tutorial.nn.encoder]):
   image ``(B, 3, H, W)`` to a global feature ``(B, D)``;
2. ``latent_to_mesh`` (the FC of the intermediate module): ``(B, D)`` to ``(B, V_c * C)``, reshaped
   to one ``C``-channel token per coarsest-mesh vertex, ``(B, V_c, C)``;
3. ``transformer`` ([`CoarseMeshTransformer`][handmesh_tutorial.nn.blocks.CoarseMeshTransformer], or
   identity when ``attention=False``): long-range interactions between the coarse vertices;
4. ``decoder`` ([`handmesh_tutorial.nn.decoder`][handmesh_tutorial.nn.decoder], single- or
   multi-path) to a per-vertex field ``(B, V, 12)`` (or ``(B, V, 3)``), then ``smoothing`` (a fixed
   sparse Laplacian smoothing of that field) and
   [`MSMRNet.vertices_from_field`][handmesh_tutorial.nn.model.MSMRNet.vertices_from_field] to
   vertices ``(B, V, 3)``;
5. joints ``(B, J, 3)`` = the template's joint regressor ``(J, V)`` applied to the vertices.

**What the decoder predicts** (``output`` of
[`build_model`][handmesh_tutorial.nn.model.build_model]). The paper's decoder regresses vertex
coordinates. Fitting it to known hands
(``fit_decoder`` (``benchmarks/fit_probe.py``), an auto-decoder: one
learnable code per hand instead of an image) showed why every trained model came out as crumpled
foil: the finest-level features differ from vertex to vertex, so the regressed coordinates carry
vertex-level noise, and the surface is very sensitive to it (0.3 mm of independent noise per vertex
already gives ~3 degrees of roughness,
[`roughness_deg`][handmesh_tutorial.metrics.surface.roughness_deg]). Smoothing the output removes
the noise, but not when the output is a position or an offset from the template: a bent finger moves
its vertices by a *rotation* of the template, and the offsets of a thin curved finger are themselves
rough (two smoothing steps on exact offsets already cost 0.95 mm and 3.2 degrees). The default
``output="affine"`` therefore predicts, per vertex, an affine map ``A_v`` and a translation ``t_v``
applied to the root-centred template vertex ``p_v``: ``v = (I + A_v) p_v + t_v``. A skinned hand is
exactly of this form with ``A_v, t_v`` the skinning-weighted blends of the bone transforms, which
are smooth (two smoothing steps on exact fields cost 0.35 mm and 1.1 degrees), so the field is
smoothed before it is applied (``smoothing_length``). With the head starting at zero the model's
first output is the template itself. ``"offset"`` (``v = p_v + s * d_v``) and ``"xyz"`` (``v = s *
d_v``, the paper's) are kept for comparison. ``"skinned"`` goes one step further
([`handmesh_tutorial.nn.skinned`][handmesh_tutorial.nn.skinned]): the field is pooled per bone with
the template's skinning weights into one local rotation per joint and the shape parameters, and the
vertices are the template skinned with them, so every output is a hand surface.

The FC is kept modest by a small coarse width ``C`` (``latent_channels``, default 16); in CMR the FC
is ~73% of the decoder's parameters; with a ResNet-18, our hand (49 coarse vertices) and the default
channels ours is 410k parameters, 0.76 of the single-path decoder and 0.61 of the multi-path one.
[`parameter_table`][handmesh_tutorial.nn.model.parameter_table] prints the split.

Everything topological (hierarchy, spirals, up/down maps, joint regressor) comes from the template
and is rebuilt by [`build_model`][handmesh_tutorial.nn.model.build_model]; the state dict holds only
learned weights.

Taught in notebooks 07 ("The multi-path decoder") and 08 ("Training").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from .blocks import CoarseMeshTransformer, SparseVertexMap
from .decoder import MultiPathDecoder, SinglePathDecoder, hierarchy_spirals
from .encoder import build_encoder
from .hierarchy import mesh_hierarchy
from .keypoints import KeypointEncoder
from .rotation import GlobalRotationHead
from .skinned import SkinnedOutput, skinning_of
from .smoothing import smoothing_matrix, smoothing_steps

__all__ = ["MeshTemplate", "as_template", "root_centred_template", "MSMRNet", "OUTPUTS",
           "build_model", "parameter_counts", "parameter_table",
           "DEFAULT_LATENT_CHANNELS", "DEFAULT_SINGLE_CHANNELS", "DEFAULT_MULTI_CHANNELS",
           "DEFAULT_SMOOTHING_LENGTH"]

DEFAULT_SINGLE_CHANNELS = (32, 32, 64, 64, 128)
"""Per-level decoder channels of the single-path baseline, finest level first."""
DEFAULT_MULTI_CHANNELS = (16, 24, 32, 48, 64)
"""Per-level branch channels of the multi-path decoder, finest first. Narrower than the
single path because level ``l`` (0 = finest) runs in ``L - l`` stages; with these widths the
multi-path decoder plus transformer has ~20-25% more parameters than the single path at the same
depth (``benchmarks/model.py`` prints the ratio).
"""
DEFAULT_SMOOTHING_LENGTH = 0.009
"""Default ``smoothing_length`` of [`build_model`][handmesh_tutorial.nn.model.build_model], metres:
3 smoothing steps on the open hand (mean edge 7.3 mm), 0 on a 200-vertex hand, ~6 on a 1,600-vertex
one.
"""
OUTPUTS = ("xyz", "offset", "affine", "skinned")
"""What the decoder's per-vertex output means
([`MSMRNet.vertices_from_field`][handmesh_tutorial.nn.model.MSMRNet.vertices_from_field])."""
DEFAULT_LATENT_CHANNELS = 16
"""Channels per coarse-mesh token (output of the FC, width of the transformer)."""


@dataclass
class MeshTemplate:
    """A template mesh with a joint regressor: all the model needs to know about the hand.

    Attributes:
        vertices: ``(V, 3)`` float64 rest positions, metres.
        faces: ``(F, 3)`` int64 triangles.
        joint_regressor: ``(J, V)`` float64; joints = ``joint_regressor @ vertices``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    joint_regressor: np.ndarray


def as_template(template=None) -> MeshTemplate:
    """Normalise a template argument.

    Args:
        template: ``None`` (the library's open right hand, ``hmt.hand.HandModel("right")``); a
            [`MeshTemplate`][handmesh_tutorial.nn.model.MeshTemplate]; a mapping with keys
            ``vertices``, ``faces``, ``joint_regressor``; a ``(vertices, faces, joint_regressor)``
            tuple; or any object with attributes ``faces``, ``joint_regressor`` and
            ``template_vertices`` or ``vertices`` (e.g. a ``HandModel`` or a user's MANO model).

    Returns:
        A validated [`MeshTemplate`][handmesh_tutorial.nn.model.MeshTemplate].

    Raises:
        ValueError: wrong shapes, face ids out of range, or a missing field.
    """
    if template is None:
        from ..hand import HandModel  # lazy: the hand is built only when needed

        template = HandModel("right")
    if isinstance(template, MeshTemplate):
        v, f, jr = template.vertices, template.faces, template.joint_regressor
    elif isinstance(template, Mapping):
        missing = {"vertices", "faces", "joint_regressor"} - set(template)
        if missing:
            raise ValueError(f"template mapping lacks keys {sorted(missing)}")
        v, f, jr = template["vertices"], template["faces"], template["joint_regressor"]
    elif isinstance(template, tuple | list):
        if len(template) != 3:
            raise ValueError("a template tuple must be (vertices, faces, joint_regressor), got "
                             f"{len(template)} items")
        v, f, jr = template
    else:
        v = getattr(template, "template_vertices", None)
        if v is None:
            v = getattr(template, "vertices", None)
        f = getattr(template, "faces", None)
        jr = getattr(template, "joint_regressor", None)
        if v is None or f is None or jr is None:
            raise ValueError("template object needs attributes faces, joint_regressor and "
                             f"template_vertices (or vertices); got {type(template).__name__}")
    v, f, jr = (np.asarray(_numpy(x)) for x in (v, f, jr))
    v = v.astype(np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"template vertices must be (V, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"template faces must be (F, 3) integers, got {f.shape} {f.dtype}")
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"template face ids must lie in [0, {len(v)}), got [{f.min()}, "
                         f"{f.max()}]")
    jr = jr.astype(np.float64)
    if jr.ndim != 2 or jr.shape[1] != len(v):
        raise ValueError(f"joint_regressor must be (J, {len(v)}), got {jr.shape}")
    return MeshTemplate(v, f.astype(np.int64), jr)


def root_centred_template(template) -> np.ndarray:
    """Template vertices centred like the training targets.

    Args:
        template: anything [`as_template`][handmesh_tutorial.nn.model.as_template] accepts.

    Returns:
        ``(V, 3)`` float64 vertices minus the root keypoint (joint 9, the middle-finger MCP,
        for a 21-joint regressor; the vertex centroid otherwise), metres.
    """
    t = as_template(template)
    root = (t.joint_regressor[9] @ t.vertices if len(t.joint_regressor) == 21
            else t.vertices.mean(0))
    return t.vertices - root


def _numpy(x):
    return x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else x


class MSMRNet(nn.Module):
    """The full model: ``encoder -> latent_to_mesh -> transformer -> decoder`` (+ joints).

    Build it with [`build_model`][handmesh_tutorial.nn.model.build_model].

    Args:
        encoder: module ``(B, 3, H, W) -> (B, D)`` with attribute ``out_features`` (``D``).
        decoder: [`SinglePathDecoder`][handmesh_tutorial.nn.decoder.SinglePathDecoder] or
            [`MultiPathDecoder`][handmesh_tutorial.nn.decoder.MultiPathDecoder] with input width
            ``latent_channels``.
        coarse_vertices: ``V_c``, vertices of the coarsest mesh.
        latent_channels: ``C``, channels per coarse vertex.
        joint_regressor: ``(J, V)`` array or tensor.
        transformer: module on ``(B, V_c, C)`` or ``None`` (no attention).
        output_scale: metres per decoder output unit (the decoder's layer-normalised features
            give O(1) outputs; 0.1 m puts them at hand size); for ``output="affine"`` it scales
            the translation ``t_v`` only.
        faces: ``(F, 3)`` faces of the output mesh (kept for plotting and export).
        template_vertices: ``(V, 3)`` root-centred template
            ([`root_centred_template`][handmesh_tutorial.nn.model.root_centred_template]), needed by
            ``output`` ``"offset"`` and ``"affine"``; a non-persistent buffer.
        output: ``"affine"``, ``"offset"``, ``"xyz"`` or ``"skinned"``: how
            [`vertices_from_field`][handmesh_tutorial.nn.model.MSMRNet.vertices_from_field] reads
            the decoder's output (12, 3, 3 or ``skinned.channels`` channels per vertex).
        smoothing: ``(V, V)`` sparse matrix applied to the decoder's output field (e.g.
            [`smoothing_matrix`][handmesh_tutorial.nn.smoothing.smoothing_matrix]), a sequence of
            them applied in order (``k`` one-step matrices are cheaper than their ``k``-step
            product,
            whose rows hold the whole ``k``-ring), or ``None``.
        global_rotation: turn the decoded mesh by a rotation predicted from the features
            ([`GlobalRotationHead`][handmesh_tutorial.nn.rotation.GlobalRotationHead]; not in the
            paper).
        skinned: the [`SkinnedOutput`][handmesh_tutorial.nn.skinned.SkinnedOutput] that
            ``output="skinned"`` needs.

    Shapes:
        ``images (B, 3, H, W)`` -> ``{"vertices": (B, V, 3), "joints": (B, J, 3)}``, metres.
    """

    def __init__(self, encoder: nn.Module, decoder: nn.Module, coarse_vertices: int,
                 latent_channels: int, joint_regressor, transformer: nn.Module | None = None,
                 output_scale: float = 0.1, faces=None, template_vertices=None,
                 output: str = "xyz", smoothing=None, global_rotation: bool = False,
                 skinned: nn.Module | None = None):
        super().__init__()
        if output not in OUTPUTS:
            raise ValueError(f"output must be one of {OUTPUTS}, got {output!r}")
        if output != "xyz" and template_vertices is None:
            raise ValueError(f"output={output!r} needs template_vertices")
        if output == "skinned" and skinned is None:
            raise ValueError("output='skinned' needs a SkinnedOutput (skinned=)")
        self.output = output
        self.skinned = skinned if output == "skinned" else None
        self.encoder = encoder
        self.coarse_vertices = coarse_vertices
        self.latent_channels = latent_channels
        self.latent_to_mesh = nn.Linear(encoder.out_features, coarse_vertices * latent_channels)
        self.transformer = transformer if transformer is not None else nn.Identity()
        self.decoder = decoder
        self.output_scale = float(output_scale)
        self.faces = None if faces is None else np.asarray(faces)
        jr = torch.as_tensor(np.asarray(_numpy(joint_regressor)), dtype=torch.float32)
        self.register_buffer("joint_regressor", jr, persistent=False)
        if template_vertices is None:
            self.template = None
        else:
            tv = torch.as_tensor(np.asarray(_numpy(template_vertices)), dtype=torch.float32)
            self.register_buffer("template", tv, persistent=False)
        # the hand's orientation from the features; the decoder's mesh is turned by it
        self.rotation = GlobalRotationHead(encoder.out_features) if global_rotation else None
        if smoothing is None:
            self.smoothing = nn.Identity()
        elif isinstance(smoothing, list | tuple):
            self.smoothing = nn.Sequential(*[SparseVertexMap(m) for m in smoothing])
        else:
            self.smoothing = SparseVertexMap(smoothing)

    def decode(self, features: torch.Tensor) -> dict[str, torch.Tensor]:
        """Everything after the encoder.

        Args:
            features: global image features ``(B, D)``.

        Returns:
            dict with ``vertices`` ``(B, V, 3)`` and ``joints`` ``(B, J, 3)``, metres.
        """
        if features.dim() != 2 or features.shape[1] != self.latent_to_mesh.in_features:
            raise ValueError(f"expected features (B, {self.latent_to_mesh.in_features}), got "
                             f"{tuple(features.shape)}")
        tokens = self.latent_to_mesh(features).reshape(-1, self.coarse_vertices,
                                                       self.latent_channels)
        raw = self.smoothing(self.decoder(self.transformer(tokens)))
        vertices = self.vertices_from_field(raw)
        if self.rotation is not None:  # about the root, the origin of the network frame
            vertices = vertices @ self.rotation(features).transpose(1, 2).to(vertices.dtype)
        joints = torch.einsum("jv,bvc->bjc", self.joint_regressor.to(vertices.dtype), vertices)
        return {"vertices": vertices, "joints": joints}

    def vertices_from_field(self, raw: torch.Tensor) -> torch.Tensor:
        """Vertices from the decoder's per-vertex output field.

        Args:
            raw: ``(B, V, 3)`` (``output`` ``"xyz"`` or ``"offset"``), ``(B, V, 12)``
                (``"affine"``: 9 entries of ``A_v - I`` row-major, then 3 of ``t_v``) or
                ``(B, V, 6 + S)`` (``"skinned"``, see
                [`SkinnedOutput`][handmesh_tutorial.nn.skinned.SkinnedOutput]).

        Returns:
            ``(B, V, 3)`` vertices, metres: ``s * raw`` (xyz), ``p_v + s * raw`` (offset) or
            ``(I + A_v) p_v + s * t_v`` (affine), with ``p_v`` the root-centred template and
            ``s`` the ``output_scale``, or the skinned template (skinned).
        """
        if self.output == "skinned":
            return self.skinned(raw)
        if self.output == "xyz":
            return raw * self.output_scale
        tmpl = self.template.to(raw.dtype)
        if self.output == "offset":
            return tmpl + raw * self.output_scale
        lin = raw[..., :9].unflatten(-1, (3, 3))
        return (tmpl + torch.einsum("bvrc,vc->bvr", lin, tmpl)
                + raw[..., 9:] * self.output_scale)

    def forward(self, images: torch.Tensor) -> dict[str, torch.Tensor]:
        """Args: images ``(B, 3, H, W)`` float. Returns ``{"vertices", "joints"}`` (metres), and
        ``uv`` ``(B, J, 2)`` (normalised 2D keypoints) with a
        [`KeypointEncoder`][handmesh_tutorial.nn.keypoints.KeypointEncoder]."""
        enc = self.encoder(images)
        if isinstance(enc, dict):  # a keypoint encoder: features + 2D keypoints
            out = self.decode(enc["features"])
            out["uv"] = enc["uv"]
            return out
        return self.decode(enc)


def build_model(encoder: str | nn.Module = "resnet18", decoder: str = "multi",
                attention: bool = True, template=None, channels: Sequence[int] | None = None,
                latent_channels: int = DEFAULT_LATENT_CHANNELS, spiral_length: int = 9,
                dilation: int = 1, num_blocks: int = 1,
                factors: Sequence[float] = (2, 2, 2, 2), num_heads: int = 2,
                transformer_layers: int = 1, fuse_head: bool = False,
                output_scale: float = 0.1, hierarchy=None, output: str = "affine",
                smoothing_length: float = DEFAULT_SMOOTHING_LENGTH, zero_head: bool = True,
                head: str = "linear", keypoints: bool = False,
                global_rotation: bool = False, skinning=None) -> MSMRNet:
    """Build MSMR-Net (or the single-path / no-attention ablations of the paper's Table 3).

    Args:
        encoder: encoder name (``resnet18``, ``resnet34``, ``resnet50``, ``hrnet18``) or a module
            ``(B, 3, H, W) -> (B, D)`` with attribute ``out_features``.
        decoder: ``"multi"`` (MSMR multi-path) or ``"single"`` (coarse-to-fine baseline).
        attention: put the transformer on the coarse-mesh tokens.
        template: see [`as_template`][handmesh_tutorial.nn.model.as_template]; default the open
            right hand.
        channels: decoder channels per hierarchy level, finest first (default
            [`DEFAULT_MULTI_CHANNELS`][handmesh_tutorial.nn.model.DEFAULT_MULTI_CHANNELS] or
            [`DEFAULT_SINGLE_CHANNELS`][handmesh_tutorial.nn.model.DEFAULT_SINGLE_CHANNELS]).
        latent_channels: channels per coarse-mesh token (FC output, transformer width).
        spiral_length: spiral length ``L``.
        dilation: spiral dilation.
        num_blocks: residual spiral blocks per level (single) or per branch and stage (multi);
            equal values give equal depth.
        factors: reduction factors of the hierarchy (len + 1 levels = stages).
        num_heads: attention heads (must divide ``latent_channels``).
        transformer_layers: transformer blocks.
        fuse_head: multi-path only; head on all branches upsampled and concatenated.
        output_scale: metres per decoder output unit (the translation part for ``"affine"``).
        output: what the decoder predicts per vertex: ``"affine"`` (default; ``I + A_v`` and
            ``t_v`` applied to the template vertex), ``"offset"`` (from the template), ``"xyz"``
            (coordinates, as the paper) or ``"skinned"`` (per-joint rotations and shape pooled
            from the field, then skinning;
            [`handmesh_tutorial.nn.skinned`][handmesh_tutorial.nn.skinned]; no output smoothing).
            See the module docstring.
        smoothing_length: metres; the decoder's output field is smoothed by
            [`smoothing_matrix`][handmesh_tutorial.nn.smoothing.smoothing_matrix] with
            [`smoothing_steps`][handmesh_tutorial.nn.smoothing.smoothing_steps] steps for this
            length (0 = none; default
            [`DEFAULT_SMOOTHING_LENGTH`][handmesh_tutorial.nn.model.DEFAULT_SMOOTHING_LENGTH]).
        zero_head: start the decoder's head at zero, so the first output is the template
            (``"affine"``, ``"offset"``) or zeros (``"xyz"``).
        head: the decoder's output head, ``"linear"``, ``"spiral"`` or ``"pyramid"``
            ([`handmesh_tutorial.nn.decoder`][handmesh_tutorial.nn.decoder]).
        keypoints: wrap a ResNet encoder in a
            [`KeypointEncoder`][handmesh_tutorial.nn.keypoints.KeypointEncoder] (2D keypoint head,
            features pooled at the predicted joints; the model then also returns ``uv``). Not in the
            paper; what lets training from scratch on a CPU learn articulation (see
            [`handmesh_tutorial.nn.keypoints`][handmesh_tutorial.nn.keypoints]).
        global_rotation: predict the hand's orientation with a separate head and turn the decoded
            mesh by it ([`handmesh_tutorial.nn.rotation`][handmesh_tutorial.nn.rotation]; not in the
            paper).
        skinning: for ``output="skinned"``, the hand model whose skinning weights, joints and
            shape space are used (default: ``template`` when it has them, else the library's right
            hand); its rest vertices must be the template's.
        hierarchy: a precomputed [`MeshHierarchy`][handmesh_tutorial.nn.hierarchy.MeshHierarchy] of
            the template (default: computed, cached on disk by ``mesh_hierarchy``).

    Returns:
        [`MSMRNet`][handmesh_tutorial.nn.model.MSMRNet] with submodules ``encoder``,
        ``latent_to_mesh``, ``transformer``, ``decoder``, and attributes ``hierarchy`` and
        ``spirals``.

    Raises:
        ValueError: unknown encoder or decoder, bad template, channel count mismatch.
    """
    tmpl = as_template(template)
    if decoder not in ("multi", "single"):
        raise ValueError(f"decoder must be 'multi' or 'single', got {decoder!r}")
    if hierarchy is None:
        hierarchy = mesh_hierarchy(tmpl.vertices, tmpl.faces, factors)
    if len(hierarchy.vertices[0]) != len(tmpl.vertices):
        raise ValueError(f"hierarchy has {len(hierarchy.vertices[0])} finest vertices, the "
                         f"template {len(tmpl.vertices)}")
    spirals = hierarchy_spirals(hierarchy, spiral_length, dilation)
    if channels is None:
        channels = DEFAULT_MULTI_CHANNELS if decoder == "multi" else DEFAULT_SINGLE_CHANNELS
        channels = tuple(channels)[:len(spirals)] if len(spirals) <= len(channels) else None
        if channels is None:
            raise ValueError(f"{len(spirals)} levels: pass channels (one per level)")
    enc = build_encoder(encoder) if isinstance(encoder, str) else encoder
    if not hasattr(enc, "out_features"):
        raise ValueError("a custom encoder needs an attribute out_features (its output width D)")
    if keypoints:
        enc = KeypointEncoder(enc, num_joints=len(tmpl.joint_regressor))
    if output not in OUTPUTS:
        raise ValueError(f"output must be one of {OUTPUTS}, got {output!r}")
    skinned = _skinned_output(template, tmpl, skinning) if output == "skinned" else None
    out_ch = skinned.channels if skinned else (12 if output == "affine" else 3)
    if decoder == "multi":
        dec = MultiPathDecoder(hierarchy, spirals, channels, num_blocks, fuse_head=fuse_head,
                               in_channels=latent_channels, head=head, out_channels=out_ch,
                               zero_head=zero_head)
    else:
        dec = SinglePathDecoder(hierarchy, spirals, channels, num_blocks,
                                in_channels=latent_channels, head=head, out_channels=out_ch,
                                zero_head=zero_head)
    coarse = len(spirals[-1])
    transformer = (CoarseMeshTransformer(coarse, latent_channels, num_heads, transformer_layers)
                   if attention else None)
    steps = smoothing_steps(tmpl.vertices, tmpl.faces, smoothing_length) if not skinned else 0
    smooth = [smoothing_matrix(tmpl.faces, 1, len(tmpl.vertices))] * steps if steps else None
    model = MSMRNet(enc, dec, coarse, latent_channels, tmpl.joint_regressor, transformer,
                    output_scale, faces=tmpl.faces, template_vertices=root_centred_template(tmpl),
                    output=output, smoothing=smooth, global_rotation=global_rotation,
                    skinned=skinned)
    model.hierarchy = hierarchy
    model.spirals = spirals
    return model


def _skinned_output(template, tmpl: MeshTemplate, skinning) -> SkinnedOutput:
    """The skinned output head for ``tmpl``, from ``skinning``, ``template`` or the library's
    right hand (the first that has skinning data), checked against ``tmpl``'s vertices."""
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


def _count(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def parameter_counts(model: MSMRNet) -> dict[str, int]:
    """Trainable parameters per part.

    Args:
        model: an [`MSMRNet`][handmesh_tutorial.nn.model.MSMRNet].

    Returns:
        dict ``encoder``, ``latent_to_mesh``, ``transformer``, ``decoder``, ``total``.
    """
    parts = {name: _count(getattr(model, name))
             for name in ("encoder", "latent_to_mesh", "transformer", "decoder")}
    parts["total"] = _count(model)
    return parts


def parameter_table(model: MSMRNet) -> str:
    """A text table of parameters per part, with shares.

    Columns: part, parameters, share of the whole model, share of the mesh part (everything
    after the encoder: FC + transformer + decoder). The last line gives FC / decoder, the ratio
    that DESIGN.md measures as ~0.73 in CMR.

    Args:
        model: an [`MSMRNet`][handmesh_tutorial.nn.model.MSMRNet].

    Returns:
        The table as a string (print it).
    """
    c = parameter_counts(model)
    mesh = c["latent_to_mesh"] + c["transformer"] + c["decoder"]
    lines = [f"{'part':<16}{'parameters':>12}{'% model':>9}{'% mesh':>9}"]
    for name in ("encoder", "latent_to_mesh", "transformer", "decoder"):
        share_mesh = "" if name == "encoder" else f"{100 * c[name] / max(mesh, 1):8.1f}%"
        lines.append(f"{name:<16}{c[name]:>12,}{100 * c[name] / c['total']:8.1f}%{share_mesh:>9}")
    lines.append(f"{'total':<16}{c['total']:>12,}")
    lines.append(f"FC / decoder = {c['latent_to_mesh'] / max(c['decoder'], 1):.2f}")
    return "\n".join(lines)
