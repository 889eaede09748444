"""Mesh decoders: the single-path baseline (Kulon et al. style) and the multi-path MSMR decoder.

Paper section "Multi-path Mesh Decoder" and Table 3 (ablation single vs multi-path).

Both decoders take a mesh hierarchy
([`handmesh_tutorial.nn.hierarchy.mesh_hierarchy`][handmesh_tutorial.nn.hierarchy.mesh_hierarchy]:
level 0 finest, level ``L-1`` coarsest; ``down[l]`` ``(V_{l+1}, V_l)``, ``up[l]``
``(V_l, V_{l+1})``) and one spiral index array per level
([`hierarchy_spirals`][handmesh_tutorial.nn.decoder.hierarchy_spirals]). They map features on the
coarsest mesh ``(B, V_{L-1}, C_in)`` to a per-vertex field on the finest mesh
``(B, V_0, out_channels)``. ``channels`` is given per level, finest first.

* [`SinglePathDecoder`][handmesh_tutorial.nn.decoder.SinglePathDecoder] walks coarse to fine: blocks
  on the coarsest mesh, upsample, blocks, ..., blocks on the finest mesh, then the head.
* [`MultiPathDecoder`][handmesh_tutorial.nn.decoder.MultiPathDecoder] has ``L`` stages (five for the
  usual 4-fold hierarchy). Stage 1 runs on the coarsest mesh only; each later stage first adds the
  next finer resolution (a transition that upsamples the previous finest branch, like HRNet's
  transition layers) and then applies a multi-resolution group convolution and a multi-resolution
  fusion to all its parallel branches. The head reads the finest branch (optionally all
  branches upsampled and concatenated).

With the same ``num_blocks`` both have the same depth: ``2 * num_blocks`` mesh convolutions per
level (single) or per stage (multi) on every input-to-output path, plus the head when it is a
spiral convolution
([`SinglePathDecoder.depth`][handmesh_tutorial.nn.decoder.SinglePathDecoder.depth]).
Fusion and transition layers are per-vertex ``Linear`` maps (HRNet's 1x1 convolutions), not depth.

**Output head** (``head``): ``"linear"`` (default), a per-vertex ``Linear`` on the finest features;
``"spiral"``, a mesh convolution as in CMR/MobRecon; ``"pyramid"``, a ``Linear`` on every level,
upsampled and summed ([`PyramidHead`][handmesh_tutorial.nn.decoder.PyramidHead]). ``zero_head``
starts it at zero, so the first field is all zeros and
[`MSMRNet`][handmesh_tutorial.nn.model.MSMRNet] starts at its template.

**The mesh convolution** (``conv``): every spiral convolution, the spiral head's included, is made
by ``conv(in_channels, out_channels, indices)`` (default
[`SpiralConv`][handmesh_tutorial.nn.spiral.SpiralConv]), as HandMesh's ``meshconv=``.

Why these defaults (fits of the heads, the zero start): docs page "The network". Taught in
notebook 07 ("The multi-path decoder").
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
from torch import nn

from .blocks import (
    MultiResolutionFusion,
    MultiResolutionGroupConv,
    ResSpiralBlock,
    SparseVertexMap,
    channel_map,
    compose_up,
)
from .spiral import SpiralConv, spiral_indices

__all__ = ["hierarchy_spirals", "SinglePathDecoder", "MultiPathDecoder", "DecoderStage",
           "PyramidHead", "count_spiral_convs", "HEADS"]


def hierarchy_spirals(hierarchy, length: int = 9, dilation: int = 1) -> list:
    """Spiral indices for every level of a mesh hierarchy.

    Args:
        hierarchy: result of
            [`handmesh_tutorial.nn.hierarchy.mesh_hierarchy`][handmesh_tutorial.nn.hierarchy.mesh_hierarchy]
            (uses ``.faces``).
        length: spiral length ``L`` (9 as MobRecon, 27 as CMR).
        dilation: spiral dilation.

    Returns:
        list of int arrays ``(V_l, L)``, finest level first.
    """
    return [spiral_indices(f, length, dilation) for f in hierarchy.faces]


def count_spiral_convs(module: nn.Module) -> int:
    """Number of [`SpiralConv`][handmesh_tutorial.nn.spiral.SpiralConv] layers inside ``module``."""
    return sum(isinstance(m, SpiralConv) for m in module.modules())


def _conv_depth(module: nn.Module) -> int:
    """Mesh convolutions in ``module``'s residual blocks (two per block), whatever ``conv``."""
    return 2 * sum(isinstance(m, ResSpiralBlock) for m in module.modules())


def _check(hierarchy, spirals, channels) -> int:
    levels = len(spirals)
    if levels < 1:
        raise ValueError("need spiral indices for at least one level")
    if len(channels) != levels:
        raise ValueError(f"channels has {len(channels)} entries but there are {levels} levels "
                         "(one channel count per level, finest first)")
    if len(hierarchy.up) < levels - 1 or len(hierarchy.down) < levels - 1:
        raise ValueError(f"{levels} levels need {levels - 1} up and down matrices, got "
                         f"{len(hierarchy.up)} up and {len(hierarchy.down)} down")
    for lv in range(levels - 1):
        want = (len(spirals[lv]), len(spirals[lv + 1]))
        if tuple(hierarchy.up[lv].shape) != want:
            raise ValueError(f"up[{lv}] has shape {tuple(hierarchy.up[lv].shape)}, expected "
                             f"{want} from the spiral indices of levels {lv} and {lv + 1}")
        if tuple(hierarchy.down[lv].shape) != want[::-1]:
            raise ValueError(f"down[{lv}] has shape {tuple(hierarchy.down[lv].shape)}, expected "
                             f"{want[::-1]}")
    return levels


class PyramidHead(nn.Module):
    """Output head on every level: ``sum_l U_{0<-l} Linear_l(x_l)``.

    Each level predicts its own ``out_channels`` per vertex with a per-vertex ``Linear``; the
    coarser predictions are upsampled to the finest mesh (barycentric, chained) and summed, so
    coarse levels contribute smooth, low-frequency shape and finer levels add detail (a Laplacian
    pyramid of the output). Equals a linear head on all branches upsampled and concatenated,
    but upsamples ``out_channels`` instead of ``sum(channels)`` features.

    Args:
        channels: channels per level, finest first.
        up: hierarchy upsampling matrices, ``up[l]`` ``(V_l, V_{l+1})``.
        out_channels: outputs per vertex.

    Shapes:
        list of ``(B, V_l, C_l)`` (finest first) -> ``(B, V_0, out_channels)``.
    """

    def __init__(self, channels: Sequence[int], up: Sequence, out_channels: int = 3):
        super().__init__()
        self.linears = nn.ModuleList(nn.Linear(c, out_channels) for c in channels)
        self.upsample = nn.ModuleList(
            [nn.Identity()] + [SparseVertexMap(compose_up(up, 0, lv))
                               for lv in range(1, len(channels))])

    def forward(self, xs: Sequence[torch.Tensor]) -> torch.Tensor:
        """Args: xs, one ``(B, V_l, C_l)`` per level, finest first."""
        if len(xs) != len(self.linears):
            raise ValueError(f"expected {len(self.linears)} levels, got {len(xs)}")
        out = self.linears[0](xs[0])
        for lin, up, x in zip(self.linears[1:], self.upsample[1:], xs[1:], strict=True):
            out = out + up(lin(x))
        return out


HEADS = ("spiral", "linear", "pyramid")


def _head(kind: str, channels: Sequence[int], out_channels: int, indices, up,
          conv: Callable[..., nn.Module] = SpiralConv) -> nn.Module:
    if kind == "spiral":
        return conv(channels[0], out_channels, indices)
    if kind == "linear":
        return nn.Linear(channels[0], out_channels)
    if kind == "pyramid":
        return PyramidHead(channels, up, out_channels)
    raise ValueError(f"head must be one of {HEADS}, got {kind!r}")


def _zero(head: nn.Module) -> None:
    for m in head.modules():
        if isinstance(m, nn.Linear):
            nn.init.zeros_(m.weight)
            nn.init.zeros_(m.bias)


def _stem(in_channels: int, out_channels: int) -> nn.Module:
    # Decouples the width of the coarse input (set by the FC, shared by both decoders) from the
    # width of the first decoder level.
    if in_channels == out_channels:
        return nn.Identity()
    return nn.Sequential(channel_map(in_channels, out_channels), nn.ELU())


class SinglePathDecoder(nn.Module):
    """Single-path coarse-to-fine spiral decoder (the baseline of the paper's ablation).

    ``coarsest blocks -> up -> blocks -> ... -> finest blocks -> head``. The first block of a
    level changes the channel count (projection shortcut).

    Args:
        hierarchy: mesh hierarchy with ``.down`` and ``.up`` (scipy sparse), finest first.
        spirals: spiral indices per level, ``(V_l, L)``, finest first.
        channels: channels per level, finest first (``channels[-1]`` is the input width).
        num_blocks: residual spiral blocks per level.
        out_channels: output channels per vertex (3 for xyz).
        in_channels: channels of the coarse input ``C_in`` (default ``channels[-1]``); when it
            differs, a stem ``ELU(LN(Linear))`` maps it to ``channels[-1]``.
        head: ``"linear"``, ``"spiral"`` or ``"pyramid"`` (see the module docstring).
        zero_head: initialise the head's ``Linear`` weights and biases to zero (output 0 at the
            start).
        conv: the mesh convolution's factory, ``conv(in_channels, out_channels, indices)`` ->
            module ``(B, V, C_in) -> (B, V, C_out)``; used by every block and a spiral head.

    Shapes:
        ``(B, V_{L-1}, C_in) -> (B, V_0, out_channels)``.

    Raises:
        ValueError: channels, spirals and hierarchy disagree on the number of levels or vertices.
    """

    def __init__(self, hierarchy, spirals: Sequence, channels: Sequence[int],
                 num_blocks: int = 1, out_channels: int = 3, in_channels: int | None = None,
                 head: str = "linear", zero_head: bool = True,
                 conv: Callable[..., nn.Module] = SpiralConv):
        super().__init__()
        n = _check(hierarchy, spirals, channels)
        self.channels = list(channels)
        self.in_channels = channels[-1] if in_channels is None else in_channels
        self.stem = _stem(self.in_channels, channels[-1])
        self.num_levels = n
        self.num_blocks = num_blocks
        self.in_vertices = len(spirals[-1])
        self.levels = nn.ModuleList()  # coarsest first
        self.upsample = nn.ModuleList()  # upsample[k] feeds levels[k + 1]
        for lv in range(n - 1, -1, -1):
            c_in = channels[min(lv + 1, n - 1)]  # the level above (the stem feeds the first)
            blocks = [ResSpiralBlock(c_in if b == 0 else channels[lv], channels[lv], spirals[lv],
                                     conv) for b in range(num_blocks)]
            self.levels.append(nn.Sequential(*blocks))
            if lv > 0:
                self.upsample.append(SparseVertexMap(hierarchy.up[lv - 1]))
        self.head_kind = head
        self.head = _head(head, channels, out_channels, spirals[0], hierarchy.up, conv)
        if zero_head:
            _zero(self.head)

    @property
    def depth(self) -> int:
        """Mesh convolutions on the longest input-to-output path (all of them, here; the
        head counts only when it is a spiral convolution)."""
        return _conv_depth(self) + int(self.head_kind == "spiral")

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Args: x ``(B, V_{L-1}, C_in)``. Returns ``(B, V_0, out_channels)``."""
        if x.dim() != 3 or x.shape[1:] != (self.in_vertices, self.in_channels):
            raise ValueError(f"expected coarse features (B, {self.in_vertices}, "
                             f"{self.in_channels}), got {tuple(x.shape)}")
        x = self.levels[0](self.stem(x))
        feats = [x]
        for up, blocks in zip(self.upsample, self.levels[1:], strict=True):
            x = blocks(up(x))
            feats.append(x)
        if self.head_kind == "pyramid":
            return self.head(feats[::-1])
        return self.head(x)


class DecoderStage(nn.Module):
    """One stage of the multi-path decoder: multi-resolution group conv, then fusion.

    Args:
        levels: hierarchy levels of the stage's branches, finest first.
        channels: channels of those branches.
        hierarchy: mesh hierarchy (``.down``, ``.up``).
        spirals: spiral indices of *all* levels (indexed by level).
        num_blocks: residual blocks per branch.
        out_levels: levels the fusion outputs (default all; ``None`` and a single branch: no
            fusion).
        conv: the mesh convolution's factory
            ([`ResSpiralBlock`][handmesh_tutorial.nn.blocks.ResSpiralBlock]).

    Shapes:
        list of ``(B, V_l, C_l)`` (one per branch) -> list (one per output level).
    """

    def __init__(self, levels: Sequence[int], channels: Sequence[int], hierarchy,
                 spirals: Sequence, num_blocks: int = 1, out_levels: Sequence[int] | None = None,
                 conv: Callable[..., nn.Module] = SpiralConv):
        super().__init__()
        self.levels = list(levels)
        self.group = MultiResolutionGroupConv(channels, [spirals[lv] for lv in levels],
                                              num_blocks, conv)
        if len(self.levels) > 1:
            self.fusion = MultiResolutionFusion(levels, channels, hierarchy.down, hierarchy.up,
                                                out_levels=out_levels)
            self.out_levels = self.fusion.out_levels
        else:
            self.fusion = None
            self.out_levels = list(self.levels)

    def forward(self, xs: Sequence[torch.Tensor]) -> list[torch.Tensor]:
        """Args: xs, one ``(B, V_l, C_l)`` per branch. Returns the fused branch features."""
        xs = self.group(xs)
        return xs if self.fusion is None else self.fusion(xs)


class MultiPathDecoder(nn.Module):
    """Multi-path (multi-stream) MSMR decoder: parallel resolutions fused at every stage.

    Stage ``s`` (``s = 1..L``) holds the ``s`` coarsest levels as parallel branches. Before stage
    ``s > 1`` a transition creates the new finest branch from the previous finest one:
    ``ELU(up(LN(Linear(x))))``. The last stage's fusion keeps only the finest output (HRNet V1),
    unless ``fuse_head``, in which case every branch is upsampled to the finest mesh and
    concatenated before the head (HRNet V2 representation head), or ``head="pyramid"``, which
    reads every branch too.

    Args:
        hierarchy: mesh hierarchy with ``.down`` and ``.up`` (scipy sparse), finest first.
        spirals: spiral indices per level, ``(V_l, L)``, finest first.
        channels: channels of the branch at each level, finest first.
        num_blocks: residual spiral blocks per branch and stage.
        out_channels: output channels per vertex (3 for xyz).
        fuse_head: feed the head all branches (upsampled, concatenated) instead of the finest.
        in_channels: channels of the coarse input ``C_in`` (default ``channels[-1]``); when it
            differs, a stem ``ELU(LN(Linear))`` maps it to ``channels[-1]``.
        head: ``"linear"``, ``"spiral"`` or ``"pyramid"`` (see the module docstring).
        zero_head: initialise the head's ``Linear`` weights and biases to zero (output 0 at the
            start).
        conv: the mesh convolution's factory, ``conv(in_channels, out_channels, indices)`` ->
            module ``(B, V, C_in) -> (B, V, C_out)``; used by every block and a spiral head.

    Shapes:
        ``(B, V_{L-1}, C_in) -> (B, V_0, out_channels)``.

    Raises:
        ValueError: channels, spirals and hierarchy disagree; ``fuse_head`` with
            ``head="pyramid"``.
    """

    def __init__(self, hierarchy, spirals: Sequence, channels: Sequence[int],
                 num_blocks: int = 1, out_channels: int = 3, fuse_head: bool = False,
                 in_channels: int | None = None, head: str = "linear", zero_head: bool = True,
                 conv: Callable[..., nn.Module] = SpiralConv):
        super().__init__()
        n = _check(hierarchy, spirals, channels)
        self.channels = list(channels)
        self.in_channels = channels[-1] if in_channels is None else in_channels
        self.stem = _stem(self.in_channels, channels[-1])
        self.num_levels = n
        self.num_blocks = num_blocks
        self.fuse_head = fuse_head
        self.in_vertices = len(spirals[-1])
        self.transitions = nn.ModuleList()  # transitions[s - 1] precedes stages[s]
        self.stages = nn.ModuleList()
        for s in range(n):
            levels = list(range(n - 1 - s, n))  # finest first
            if s > 0:
                new, prev = n - 1 - s, n - s
                self.transitions.append(nn.Sequential(
                    channel_map(channels[prev], channels[new]),
                    SparseVertexMap(hierarchy.up[new]), nn.ELU()))
            last = s == n - 1
            out_levels = levels[:1] if last and not (fuse_head or head == "pyramid") else None
            self.stages.append(DecoderStage(levels, [channels[lv] for lv in levels], hierarchy,
                                            spirals, num_blocks, out_levels, conv))
        self.head_kind = head
        if fuse_head and head == "pyramid":
            raise ValueError("fuse_head and head='pyramid' exclude each other (the pyramid head "
                             "already reads every branch)")
        if fuse_head:
            self.head_upsample = nn.ModuleList(
                [nn.Identity()] + [SparseVertexMap(compose_up(hierarchy.up, 0, lv))
                                   for lv in range(1, n)])
            head_in = sum(channels)
        else:
            self.head_upsample = None
            head_in = channels[0]
        self.head = _head(head, [head_in] if fuse_head else channels, out_channels, spirals[0],
                          hierarchy.up, conv)
        if zero_head:
            _zero(self.head)

    @property
    def depth(self) -> int:
        """Mesh convolutions on the longest input-to-output path.

        Every path crosses each stage once through one branch's blocks, so this is the sum over
        stages of the deepest branch, plus the head when it is a spiral convolution.
        """
        per_stage = [max(_conv_depth(b) for b in st.group.branches) for st in self.stages]
        return sum(per_stage) + int(self.head_kind == "spiral")

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Args: x ``(B, V_{L-1}, C_in)``. Returns ``(B, V_0, out_channels)``."""
        if x.dim() != 3 or x.shape[1:] != (self.in_vertices, self.in_channels):
            raise ValueError(f"expected coarse features (B, {self.in_vertices}, "
                             f"{self.in_channels}), got {tuple(x.shape)}")
        xs = [self.stem(x)]
        for s, stage in enumerate(self.stages):
            if s > 0:
                xs = [self.transitions[s - 1](xs[0]), *xs]
            xs = stage(xs)
        if self.head_upsample is not None:
            ups = [up(f) for up, f in zip(self.head_upsample, xs, strict=True)]
            return self.head(torch.cat(ups, dim=-1))
        if self.head_kind == "pyramid":
            return self.head(xs)
        return self.head(xs[0])
