"""MSMR-Net: image encoder -> FC -> coarse mesh -> transformer -> mesh decoder -> vertices, joints.

Paper section "Multi-path Mesh Decoder" (architecture figure) and Table 3 (ablation). The model:

1. ``encoder`` (ResNet / HRNet, [`handmesh_tutorial.nn.encoder`][handmesh_tutorial.nn.encoder]):
   image ``(B, 3, H, W)`` to a global feature ``(B, D)``;
2. ``latent_to_mesh`` (the FC of the intermediate module): ``(B, D)`` to ``(B, V_c * C)``, reshaped
   to one ``C``-channel token per coarsest-mesh vertex, ``(B, V_c, C)``;
3. ``transformer`` ([`CoarseMeshTransformer`][handmesh_tutorial.nn.blocks.CoarseMeshTransformer], or
   identity when ``attention=False``): long-range interactions between the coarse vertices;
4. ``decoder`` ([`handmesh_tutorial.nn.decoder`][handmesh_tutorial.nn.decoder], single- or
   multi-path) to a per-vertex field ``(B, V, C_out)``, then ``smoothing`` (a fixed sparse
   Laplacian smoothing of that field) and ``vertex_output``
   ([`handmesh_tutorial.nn.outputs`][handmesh_tutorial.nn.outputs]) to vertices ``(B, V, 3)``;
5. joints ``(B, J, 3)`` = the template's joint regressor ``(J, V)`` applied to the vertices.

[`build_model`][handmesh_tutorial.nn.model.build_model] builds it from keywords or a
[`ModelConfig`][handmesh_tutorial.nn.config.ModelConfig] (named presets:
``ModelConfig.preset("paper")``), and takes the parts one may swap: the encoder, the output module
(``output=``), the rotation head (``global_rotation=``), the keypoint head (``keypoints=``) and the
mesh convolution of every block and decoder (``conv=``, as HandMesh's ``meshconv=``). Everything
topological (hierarchy, spirals, up/down maps, joint regressor) comes from the template and is
rebuilt; the state dict holds only learned weights.

Why the defaults (the affine output and its smoothing, the FC's width): docs page "The network".
Taught in notebooks 07 ("The multi-path decoder") and 08 ("Training").
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np
import torch
from torch import nn

from .blocks import CoarseMeshTransformer, SparseVertexMap
from .config import (
    DEFAULT_LATENT_CHANNELS,
    DEFAULT_MULTI_CHANNELS,
    DEFAULT_SINGLE_CHANNELS,
    DEFAULT_SMOOTHING_LENGTH,
    ModelConfig,
)
from .decoder import MultiPathDecoder, SinglePathDecoder, hierarchy_spirals
from .encoder import build_encoder
from .hierarchy import mesh_hierarchy
from .keypoints import KeypointEncoder
from .mesh_template import MeshTemplate, as_template, root_centred_template
from .outputs import OUTPUTS, AffineOutput, OffsetOutput, XYZOutput, skinned_output
from .rotation import GlobalRotationHead
from .skinned import SkinnedOutput
from .smoothing import smoothing_matrix, smoothing_steps
from .spiral import SpiralConv

__all__ = ["MeshTemplate", "as_template", "root_centred_template", "MSMRNet", "OUTPUTS",
           "ModelConfig", "build_model", "parameter_counts", "parameter_table",
           "DEFAULT_LATENT_CHANNELS", "DEFAULT_SINGLE_CHANNELS", "DEFAULT_MULTI_CHANNELS",
           "DEFAULT_SMOOTHING_LENGTH"]

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
            ([`root_centred_template`][handmesh_tutorial.nn.mesh_template.root_centred_template]),
            needed by ``output`` ``"offset"`` and ``"affine"``; a non-persistent buffer.
        output: a name, ``"affine"``, ``"offset"``, ``"xyz"`` or ``"skinned"``, or an output
            module ``field (B, V, C_out) -> vertices (B, V, 3)``
            ([`handmesh_tutorial.nn.outputs`][handmesh_tutorial.nn.outputs]); kept as
            ``vertex_output``, its name as ``output``.
        smoothing: ``(V, V)`` sparse matrix applied to the decoder's output field (e.g.
            [`smoothing_matrix`][handmesh_tutorial.nn.smoothing.smoothing_matrix]), a sequence of
            them applied in order (``k`` one-step matrices are cheaper than their ``k``-step
            product, whose rows hold the whole ``k``-ring), or ``None``.
        global_rotation: ``True`` for a
            [`GlobalRotationHead`][handmesh_tutorial.nn.rotation.GlobalRotationHead] (not in the
            paper), or a module ``features (B, D) -> (B, 3, 3)`` rotations; the decoded mesh is
            turned by it about the root.
        skinned: the [`SkinnedOutput`][handmesh_tutorial.nn.skinned.SkinnedOutput] that
            ``output="skinned"`` needs.

    Shapes:
        ``images (B, 3, H, W)`` -> ``{"vertices": (B, V, 3), "joints": (B, J, 3)}``, metres.

    Raises:
        ValueError: an unknown output name, or one without the template or skinning it needs.
    """

    def __init__(self, encoder: nn.Module, decoder: nn.Module, coarse_vertices: int,
                 latent_channels: int, joint_regressor, transformer: nn.Module | None = None,
                 output_scale: float = 0.1, faces=None, template_vertices=None,
                 output: str | nn.Module = "xyz", smoothing=None,
                 global_rotation: bool | nn.Module = False, skinned: nn.Module | None = None):
        super().__init__()
        if isinstance(output, nn.Module):
            self.vertex_output = output
            self.output = getattr(output, "name", None) or (
                "skinned" if isinstance(output, SkinnedOutput) else type(output).__name__)
        else:
            self.vertex_output = _named_output(output, template_vertices, output_scale, skinned)
            self.output = output
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
        if isinstance(global_rotation, nn.Module):
            self.rotation = global_rotation
        else:
            self.rotation = GlobalRotationHead(encoder.out_features) if global_rotation else None
        if smoothing is None:
            self.smoothing = nn.Identity()
        elif isinstance(smoothing, list | tuple):
            self.smoothing = nn.Sequential(*[SparseVertexMap(m) for m in smoothing])
        else:
            self.smoothing = SparseVertexMap(smoothing)

    @property
    def skinned(self) -> SkinnedOutput | None:
        """The [`SkinnedOutput`][handmesh_tutorial.nn.skinned.SkinnedOutput] when the output is
        skinned, else ``None``."""
        out = self.vertex_output
        return out if isinstance(out, SkinnedOutput) else None

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
        """Vertices from the decoder's per-vertex output field (``vertex_output``).

        Args:
            raw: ``(B, V, 3)`` (``output`` ``"xyz"`` or ``"offset"``), ``(B, V, 12)``
                (``"affine"``: 9 entries of ``A_v - I`` row-major, then 3 of ``t_v``),
                ``(B, V, 6 + S)`` (``"skinned"``) or what a custom output module reads.

        Returns:
            ``(B, V, 3)`` vertices, metres: ``s * raw`` (xyz), ``p_v + s * raw`` (offset) or
            ``(I + A_v) p_v + s * t_v`` (affine), with ``p_v`` the root-centred template and
            ``s`` the ``output_scale``, or the skinned template (skinned).
        """
        return self.vertex_output(raw)

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


def _named_output(output: str, template_vertices, scale: float, skinned) -> nn.Module:
    """The output module ``MSMRNet(output=<name>)`` makes."""
    if output not in OUTPUTS:
        raise ValueError(f"output must be one of {OUTPUTS}, got {output!r}")
    if output != "xyz" and template_vertices is None:
        raise ValueError(f"output={output!r} needs template_vertices")
    if output == "skinned":
        if skinned is None:
            raise ValueError("output='skinned' needs a SkinnedOutput (skinned=)")
        return skinned
    if output == "xyz":
        return XYZOutput(scale)
    tv = np.asarray(_numpy(template_vertices))
    return (AffineOutput if output == "affine" else OffsetOutput)(tv, scale)


_ARCH = tuple(f.name for f in dataclasses.fields(ModelConfig))


def build_model(encoder: str | nn.Module | ModelConfig = "resnet18", decoder: str = "multi",
                attention: bool = True, template=None, channels: Sequence[int] | None = None,
                latent_channels: int = DEFAULT_LATENT_CHANNELS, spiral_length: int = 9,
                dilation: int = 1, num_blocks: int = 1,
                factors: Sequence[float] = (2, 2, 2, 2), num_heads: int = 2,
                transformer_layers: int = 1, fuse_head: bool = False,
                output_scale: float = 0.1, hierarchy=None, output: str | nn.Module = "affine",
                smoothing_length: float = DEFAULT_SMOOTHING_LENGTH, zero_head: bool = True,
                head: str = "linear", keypoints: bool | Callable[..., nn.Module] = False,
                global_rotation: bool | nn.Module = False, skinning=None, *,
                config: ModelConfig | None = None,
                conv: Callable[..., nn.Module] = SpiralConv) -> MSMRNet:
    """Build MSMR-Net (or the single-path / no-attention ablations of the paper's Table 3).

    Args:
        encoder: encoder name (``resnet10``, ``resnet18``, ``resnet34``, ``resnet50``,
            ``hrnet18``), a module ``(B, 3, H, W) -> (B, D)`` with attribute ``out_features``, or
            a [`ModelConfig`][handmesh_tutorial.nn.config.ModelConfig] (as ``config``).
        decoder: ``"multi"`` (MSMR multi-path) or ``"single"`` (coarse-to-fine baseline).
        attention: put the transformer on the coarse-mesh tokens.
        template: see [`as_template`][handmesh_tutorial.nn.mesh_template.as_template]; default the
            open right hand.
        channels: decoder channels per hierarchy level, finest first (default
            [`DEFAULT_MULTI_CHANNELS`][handmesh_tutorial.nn.config.DEFAULT_MULTI_CHANNELS] or
            [`DEFAULT_SINGLE_CHANNELS`][handmesh_tutorial.nn.config.DEFAULT_SINGLE_CHANNELS]).
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
        hierarchy: a precomputed [`MeshHierarchy`][handmesh_tutorial.nn.hierarchy.MeshHierarchy] of
            the template (default: computed, cached on disk by ``mesh_hierarchy``).
        output: what the decoder's field means
            ([`handmesh_tutorial.nn.outputs`][handmesh_tutorial.nn.outputs]): ``"affine"``
            (default; ``I + A_v`` and ``t_v`` applied to the template vertex), ``"offset"`` (from
            the template), ``"xyz"`` (coordinates, as the paper), ``"skinned"`` (joint rotations
            and shape, then skinning; no output smoothing), or a module with attribute
            ``channels`` (the field width), field ``(B, V, channels)`` -> ``(B, V, 3)``.
        smoothing_length: metres; the decoder's output field is smoothed by
            [`smoothing_matrix`][handmesh_tutorial.nn.smoothing.smoothing_matrix] with
            [`smoothing_steps`][handmesh_tutorial.nn.smoothing.smoothing_steps] steps for this
            length (0 = none).
        zero_head: start the decoder's head at zero, so the first output is the template
            (``"affine"``, ``"offset"``) or zeros (``"xyz"``).
        head: the decoder's output head, ``"linear"``, ``"spiral"`` or ``"pyramid"``
            ([`handmesh_tutorial.nn.decoder`][handmesh_tutorial.nn.decoder]).
        keypoints: ``True`` wraps a ResNet encoder in a
            [`KeypointEncoder`][handmesh_tutorial.nn.keypoints.KeypointEncoder] (2D keypoint head,
            features pooled at the predicted joints; the model then also returns ``uv``; not in the
            paper); or a factory ``keypoints(encoder, num_joints=J)`` -> such a module.
        global_rotation: ``True`` for a
            [`GlobalRotationHead`][handmesh_tutorial.nn.rotation.GlobalRotationHead] that turns
            the decoded mesh (not in the paper), or a module ``(B, D) -> (B, 3, 3)``.
        skinning: for ``output="skinned"``, the hand model whose skinning weights, joints and
            shape space are used (default: ``template`` when it has them, else the library's right
            hand); its rest vertices must be the template's.
        config: the architecture as a [`ModelConfig`][handmesh_tutorial.nn.config.ModelConfig]
            (e.g. ``ModelConfig.preset("cpu")``) instead of the keywords ``encoder`` to
            ``global_rotation``, which must then be left out.
        conv: the mesh convolution of every residual block and of a spiral head,
            ``conv(in_channels, out_channels, indices)`` -> module ``(B, V, C_in) ->
            (B, V, C_out)`` (default [`SpiralConv`][handmesh_tutorial.nn.spiral.SpiralConv]).

    Returns:
        [`MSMRNet`][handmesh_tutorial.nn.model.MSMRNet] with submodules ``encoder``,
        ``latent_to_mesh``, ``transformer``, ``decoder``, ``vertex_output``, and attributes
        ``hierarchy``, ``spirals`` and ``config``.

    Raises:
        ValueError: unknown encoder, decoder, head or output, bad template, channel count
            mismatch, a config field out of range.
        TypeError: ``config`` together with architecture keywords.
    """
    args = dict(locals())
    given = {k: args[k] for k in _ARCH}
    if isinstance(encoder, ModelConfig):
        config, given["encoder"] = encoder, "resnet18"
    if config is None:
        config = ModelConfig(**given)
    else:
        clash = [k for k, v in given.items() if not _is_default(v, _DEFAULTS[k])]
        if clash:
            raise TypeError(f"build_model got config= and the keywords {clash}; put them in the "
                            f"config instead: config.replace({clash[0]}=...)")
    return _build(config, template, hierarchy, skinning, conv)


def _is_default(value, default) -> bool:
    if value is default:
        return True
    try:
        return type(value) is type(default) and bool(value == default)
    except (TypeError, ValueError, RuntimeError):  # arrays, tensors
        return False


_DEFAULTS = {f.name: f.default for f in dataclasses.fields(ModelConfig)}


def _build(c: ModelConfig, template, hierarchy, skinning, conv) -> MSMRNet:
    tmpl = as_template(template)
    if hierarchy is None:
        hierarchy = mesh_hierarchy(tmpl.vertices, tmpl.faces, c.factors)
    if len(hierarchy.vertices[0]) != len(tmpl.vertices):
        raise ValueError(f"hierarchy has {len(hierarchy.vertices[0])} finest vertices, the "
                         f"template {len(tmpl.vertices)}")
    spirals = hierarchy_spirals(hierarchy, c.spiral_length, c.dilation)
    channels = c.channels
    if channels is None:
        channels = DEFAULT_MULTI_CHANNELS if c.decoder == "multi" else DEFAULT_SINGLE_CHANNELS
        channels = tuple(channels)[:len(spirals)] if len(spirals) <= len(channels) else None
        if channels is None:
            raise ValueError(f"{len(spirals)} levels: pass channels (one per level)")
    enc = build_encoder(c.encoder) if isinstance(c.encoder, str) else c.encoder
    if not hasattr(enc, "out_features"):
        raise ValueError("a custom encoder needs an attribute out_features (its output width D)")
    if c.keypoints:
        factory = c.keypoints if callable(c.keypoints) else KeypointEncoder
        enc = factory(enc, num_joints=len(tmpl.joint_regressor))
    if isinstance(c.output, nn.Module):
        out, skinned = c.output, None
        if not isinstance(getattr(out, "channels", None), int):
            raise ValueError(f"an output module needs an integer attribute channels (the field "
                             f"width), {type(out).__name__} has none")
        smooth = getattr(out, "smooth_field", not isinstance(out, SkinnedOutput))
    else:
        skinned = skinned_output(template, skinning) if c.output == "skinned" else None
        out, smooth = c.output, skinned is None
    out_ch = out.channels if isinstance(out, nn.Module) else (
        skinned.channels if skinned else (12 if out == "affine" else 3))
    kw = dict(in_channels=c.latent_channels, head=c.head, out_channels=out_ch,
              zero_head=c.zero_head, conv=conv)
    if c.decoder == "multi":
        dec = MultiPathDecoder(hierarchy, spirals, channels, c.num_blocks, fuse_head=c.fuse_head,
                               **kw)
    else:
        dec = SinglePathDecoder(hierarchy, spirals, channels, c.num_blocks, **kw)
    coarse = len(spirals[-1])
    transformer = (CoarseMeshTransformer(coarse, c.latent_channels, c.num_heads,
                                         c.transformer_layers) if c.attention else None)
    steps = smoothing_steps(tmpl.vertices, tmpl.faces, c.smoothing_length) if smooth else 0
    smoothing = [smoothing_matrix(tmpl.faces, 1, len(tmpl.vertices))] * steps if steps else None
    model = MSMRNet(enc, dec, coarse, c.latent_channels, tmpl.joint_regressor, transformer,
                    c.output_scale, faces=tmpl.faces,
                    template_vertices=root_centred_template(tmpl), output=out,
                    smoothing=smoothing, global_rotation=c.global_rotation, skinned=skinned)
    model.hierarchy = hierarchy
    model.spirals = spirals
    model.config = c
    return model


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
