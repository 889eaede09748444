"""Building blocks of the mesh decoders: residual spiral blocks, multi-resolution group convolution,
multi-resolution fusion (HRNet on a mesh) and the transformer on the coarse-mesh tokens.

Paper section "Multi-path Mesh Decoder": the decoder's stages consist of *multi-resolution blocks*,
i.e. a multi-resolution group convolution (every resolution runs its own residual spiral blocks)
followed by a multi-resolution convolution (the fusion of HRNet, Wang et al. 2020), whose
cross-resolution connections use the precomputed up- and downsampling matrices of
[`handmesh_tutorial.nn.hierarchy.mesh_hierarchy`][handmesh_tutorial.nn.hierarchy.mesh_hierarchy].

Conventions: per-vertex features are tensors of shape ``(B, V, C)`` (batch, vertices, channels).
Hierarchy level ``0`` is the finest mesh, level ``L-1`` the coarsest (the order of
``mesh_hierarchy``). ``down[l]`` maps level ``l`` to ``l+1`` (shape ``V_{l+1} x V_l``), ``up[l]``
maps level ``l+1`` to ``l`` (shape ``V_l x V_{l+1}``).

The mesh convolution is a hook: every block that convolves takes ``conv``, a factory
``conv(in_channels, out_channels, indices) -> nn.Module`` mapping ``(B, V, C_in)`` to
``(B, V, C_out)`` with ``indices`` the ``(V, L)`` spiral indices (default
[`SpiralConv`][handmesh_tutorial.nn.spiral.SpiralConv]; HandMesh's ``meshconv=`` swaps in its
depthwise-separable ``DSConv`` the same way).

Fixed sparse maps ([`SparseVertexMap`][handmesh_tutorial.nn.blocks.SparseVertexMap]) are torch CSR
products on vertex-major features, with a gather-and-sum reference path that graph capture uses;
why and how fast: docs page "The network".

Taught in notebook 07 ("The multi-path decoder"); its section 4 writes the coarse-mesh
transformer from scratch and draws the shipped network's attention weights.

Why one file: every block here is built on the same two parts, the spiral convolution and the
fixed vertex map, and reads next to them.

"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import scipy.sparse as sp
import torch
from torch import nn

from .spiral import SpiralConv

__all__ = [
    "SparseVertexMap", "Pool", "compose_up", "compose_down", "channel_map", "ResSpiralBlock",
    "MultiResolutionGroupConv", "MultiResolutionFusion", "TransformerBlock",
    "CoarseMeshTransformer",
]


def _csr_parts(m: sp.csr_matrix) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(row pointers, column indices, float32 values) of ``m`` with sorted indices."""
    m = sp.csr_matrix(m, copy=True)  # a copy: sorting must not touch arrays shared with the caller
    m.sort_indices()
    return (torch.from_numpy(m.indptr.astype(np.int64)),
            torch.from_numpy(m.indices.astype(np.int64)),
            torch.from_numpy(m.data.astype(np.float32)))


def _csr(crow, col, values, shape) -> torch.Tensor:
    import warnings

    with warnings.catch_warnings():  # "sparse CSR support is in beta": only mm is used here
        warnings.simplefilter("ignore", UserWarning)
        return torch.sparse_csr_tensor(crow, col, values, shape, check_invariants=False)


def _tracing() -> bool:
    """A graph is being captured (``torch.compile``, ``torch.export`` and the ONNX exporter
    built on it, ``torch.jit.trace``): sparse CSR tensors cannot be traced."""
    return torch.compiler.is_compiling() or torch.jit.is_tracing()


class _VertexMatmul(torch.autograd.Function):
    """``y[b] = M @ x[b]`` for a fixed sparse ``M``: x ``(B, V_in, C)`` -> ``(B, V_out, C)``.

    The batch is laid out vertex-major, ``(V_in, B*C)``, so one CSR product serves the whole
    batch; the backward pass is the product with the precomputed transpose ``M^T``."""

    @staticmethod
    def forward(ctx, x, matrix, transpose):
        ctx.transpose = transpose
        b, v, c = x.shape
        with torch.autocast(x.device.type, enabled=False):  # the product stays in x's dtype
            y = matrix @ x.transpose(0, 1).reshape(v, b * c)
        return y.view(-1, b, c).transpose(0, 1).contiguous()

    @staticmethod
    def backward(ctx, grad):
        b, v, c = grad.shape
        with torch.autocast(grad.device.type, enabled=False):
            g = ctx.transpose @ grad.transpose(0, 1).reshape(v, b * c)
        return g.view(-1, b, c).transpose(0, 1).contiguous(), None, None


class SparseVertexMap(nn.Module):
    """A fixed sparse linear map between two vertex sets, applied to batched features.

    ``y[b, i, c] = sum_k M[i, k] x[b, k, c]`` for a sparse ``M`` of shape ``(V_out, V_in)``.
    ``M`` is stored row-wise in padded form: ``index`` ``(V_out, K)`` (long) and ``weight``
    ``(V_out, K)`` (float32), ``K`` the largest number of non-zeros in a row, padding has weight 0.
    Both are non-persistent buffers: they move with ``.to(device)`` but, like the spiral indices,
    are rebuilt from the template rather than saved in the state dict.
    A 0/1 selection matrix (one 1 per row, like the downsampling matrices) becomes a plain
    ``index_select``. Other matrices are applied as a CSR product (``method="csr"``, the
    default; the CSR parts of ``M`` and ``M^T``, float32, are non-persistent buffers too) or by
    the original gather and weighted sum over the padded rows (``method="gather"``, the
    reference); both give the same values up to float rounding (the order of the sums differs).
    While a graph is captured (``torch.compile``, ``torch.export`` and the ONNX export built on
    it, ``torch.jit.trace``) the map uses the gather path whatever ``method`` says: sparse
    tensors cannot be traced, so exported and compiled networks hold only dense operations
    (``docs/concepts/export.md``).

    Args:
        matrix: scipy sparse matrix or dense array, shape ``(V_out, V_in)``.
        method: ``"csr"`` or ``"gather"``; an attribute, so it can be switched after
            construction.

    Raises:
        ValueError: ``matrix`` is not two-dimensional or has a row without entries.
    """

    def __init__(self, matrix, method: str = "csr"):
        super().__init__()
        if method not in ("csr", "gather"):
            raise ValueError(f"method must be 'csr' or 'gather', got {method!r}")
        self.method = method
        if np.ndim(matrix) != 2 and not sp.issparse(matrix):
            raise ValueError(f"matrix must be 2-D, got shape {np.shape(matrix)}")
        m = sp.csr_matrix(matrix, dtype=np.float64)
        m.eliminate_zeros()
        v_out, v_in = m.shape
        counts = np.diff(m.indptr)
        if v_out == 0 or counts.min() == 0:
            raise ValueError(f"matrix of shape {m.shape} has a row without non-zeros; every "
                             "output vertex needs at least one input vertex")
        k = int(counts.max())
        index = np.zeros((v_out, k), dtype=np.int64)
        weight = np.zeros((v_out, k), dtype=np.float32)
        rows = np.repeat(np.arange(v_out), counts)
        slot = np.arange(m.nnz) - np.repeat(m.indptr[:-1], counts)
        index[rows, slot] = m.indices
        weight[rows, slot] = m.data
        # Padding points at the row's first entry with weight 0 (any valid index works).
        pad = weight == 0
        index[pad] = np.broadcast_to(index[:, :1], index.shape)[pad]
        self.in_vertices = v_in
        self.out_vertices = v_out
        self.is_selection = bool(k == 1 and np.all(weight == 1.0))
        self.register_buffer("index", torch.from_numpy(index), persistent=False)
        self.register_buffer("weight", torch.from_numpy(weight), persistent=False)
        # CSR parts of M and M^T as plain (dense) buffers, so that .to(device) and DDP's buffer
        # broadcast handle them; the sparse tensors are assembled on use (cached).
        for name, mat in (("csr", m), ("csr_t", m.T.tocsr())):
            for part, t in zip(("crow", "col", "values"), _csr_parts(mat), strict=True):
                self.register_buffer(f"{name}_{part}", t, persistent=False)
        self._csr_cache: dict = {}

    @property
    def nnz_per_row(self) -> int:
        """``K``, the padded number of non-zeros per row."""
        return int(self.index.shape[1])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Apply the map.

        Args:
            x: features ``(B, V_in, C)``, or ``(V_in, C)`` for one mesh.

        Returns:
            ``(B, V_out, C)`` (``(V_out, C)`` for an unbatched input).
        """
        if x.dim() == 2 and x.shape[0] == self.in_vertices:
            return self.forward(x[None])[0]
        if x.dim() != 3 or x.shape[1] != self.in_vertices:
            raise ValueError(f"expected features (B, {self.in_vertices}, C) or "
                             f"({self.in_vertices}, C), got {tuple(x.shape)}")
        if self.is_selection:
            return x.index_select(1, self.index[:, 0])
        if self.method == "csr" and not _tracing():
            # sparse products exist for float32/float64 only: half precision (autocast) is
            # computed in float32 and cast back
            dt = x.dtype if x.dtype in (torch.float32, torch.float64) else torch.float32
            m, mt = self._matrices(dt)
            return _VertexMatmul.apply(x.to(dt), m, mt).to(x.dtype)
        b, _, c = x.shape
        g = x.index_select(1, self.index.reshape(-1)).reshape(b, self.out_vertices, -1, c)
        # broadcast multiply-and-sum: an einsum here becomes V tiny bmm's, ~3.5x slower on CPU
        return (g * self.weight.to(x.dtype)[None, :, :, None]).sum(2)

    def __getstate__(self):
        # the cached sparse tensors cannot be deep-copied or pickled; they are rebuilt on use
        state = super().__getstate__().copy()
        state["_csr_cache"] = {}
        return state

    def _matrices(self, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor]:
        """Sparse CSR ``M`` and ``M^T`` in ``dtype`` on the buffers' device (cached)."""
        key = (dtype, self.csr_values.device, self.csr_values.data_ptr(),
               self.csr_t_values.data_ptr())
        hit = self._csr_cache.get(key)
        if hit is None:
            shape = (self.out_vertices, self.in_vertices)
            hit = (_csr(self.csr_crow, self.csr_col, self.csr_values.to(dtype), shape),
                   _csr(self.csr_t_crow, self.csr_t_col, self.csr_t_values.to(dtype),
                        shape[::-1]))
            self._csr_cache = {key: hit}
        return hit

    def to_dense(self) -> torch.Tensor:
        """The matrix as a dense ``(V_out, V_in)`` tensor (for checks and figures)."""
        dense = torch.zeros(self.out_vertices, self.in_vertices, dtype=self.weight.dtype,
                            device=self.weight.device)
        rows = torch.arange(self.out_vertices, device=self.index.device)[:, None]
        dense.index_put_((rows.expand_as(self.index), self.index), self.weight, accumulate=True)
        return dense

    def extra_repr(self) -> str:
        kind = "selection" if self.is_selection else f"K={self.nnz_per_row}, {self.method}"
        return f"{self.in_vertices} -> {self.out_vertices} vertices, {kind}"


class Pool(SparseVertexMap):
    """SpiralNet++'s ``Pool(x, trans)`` as a layer: a mesh hierarchy's down- or upsampling map.

    ``Pool(hier.down[l])`` maps features of level ``l`` to level ``l + 1`` (a selection of the
    kept vertices), ``Pool(hier.up[l])`` maps level ``l + 1`` back to ``l`` (closest-triangle
    barycentric weights): ``y[b, i] = sum_k M[i, k] x[b, k]``, what SpiralNet++'s
    ``Pool(x, trans)`` computes with ``torch_scatter``. The same layer as
    [`SparseVertexMap`][handmesh_tutorial.nn.blocks.SparseVertexMap] (the decoders' maps), under
    the name SpiralNet++ and HandMesh code uses.

    Args:
        matrix: ``(V_out, V_in)`` scipy sparse matrix (``hier.down[l]``, ``hier.up[l]``) or array.

    Shape:
        ``(B, V_in, C)`` -> ``(B, V_out, C)``; an unbatched ``(V_in, C)`` -> ``(V_out, C)``.

    Examples:
        >>> import torch, trimesh
        >>> from handmesh_tutorial.nn.hierarchy import mesh_hierarchy
        >>> ico = trimesh.creation.icosphere(subdivisions=2)
        >>> hier = mesh_hierarchy(ico.vertices, ico.faces, factors=(2,), use_cache=False)
        >>> down, up = Pool(hier.down[0]), Pool(hier.up[0])
        >>> x = torch.as_tensor(ico.vertices, dtype=torch.float32)  # (162, 3) one mesh
        >>> down(x).shape, up(down(x)).shape
        (torch.Size([81, 3]), torch.Size([162, 3]))
    """


def compose_up(up: Sequence, fine: int, coarse: int) -> sp.csr_matrix:
    """Upsampling from level ``coarse`` to the finer ``fine``: ``up[fine] @ ... @ up[coarse-1]``.

    Args:
        up: the hierarchy's upsampling matrices, ``up[l]`` of shape ``(V_l, V_{l+1})``.
        fine: target level (finer, smaller index).
        coarse: source level (coarser, larger index), ``coarse > fine``.

    Returns:
        scipy CSR matrix ``(V_fine, V_coarse)``; rows sum to 1 when each factor's rows do.
    """
    if not 0 <= fine < coarse <= len(up):
        raise ValueError(f"need 0 <= fine < coarse <= {len(up)}, got fine={fine}, coarse={coarse}")
    m = sp.csr_matrix(up[fine])
    for level in range(fine + 1, coarse):
        m = m @ sp.csr_matrix(up[level])
    return sp.csr_matrix(m)


def compose_down(down: Sequence, fine: int, coarse: int) -> sp.csr_matrix:
    """Downsampling from level ``fine`` to the coarser level ``coarse``:
    ``down[coarse-1] @ ... @ down[fine]``.

    Args:
        down: the hierarchy's downsampling matrices, ``down[l]`` of shape ``(V_{l+1}, V_l)``.
        fine: source level (finer, smaller index).
        coarse: target level (coarser), ``coarse > fine``.

    Returns:
        scipy CSR matrix ``(V_coarse, V_fine)`` (a 0/1 selection when each factor is one).
    """
    if not 0 <= fine < coarse <= len(down):
        raise ValueError(f"need 0 <= fine < coarse <= {len(down)}, got fine={fine}, "
                         f"coarse={coarse}")
    m = sp.csr_matrix(down[fine])
    for level in range(fine + 1, coarse):
        m = sp.csr_matrix(down[level]) @ m
    return sp.csr_matrix(m)


def channel_map(in_channels: int, out_channels: int) -> nn.Sequential:
    """Per-vertex channel map ``Linear + LayerNorm`` (the 1x1 conv + BN of HRNet on a mesh).

    Args:
        in_channels: ``C_in``.
        out_channels: ``C_out``.

    Returns:
        Module mapping ``(B, V, C_in)`` to ``(B, V, C_out)``.
    """
    return nn.Sequential(nn.Linear(in_channels, out_channels), nn.LayerNorm(out_channels))


class ResSpiralBlock(nn.Module):
    """Residual spiral block: a ResNet basic block on a mesh.

    ``y = ELU(LN(conv2(ELU(LN(conv1(x))))) + shortcut(x))`` with ``conv1``, ``conv2`` made by
    ``conv`` ([`SpiralConv`][handmesh_tutorial.nn.spiral.SpiralConv] layers by default),
    LayerNorm over the channels instead of BatchNorm, ELU as in the paper. The shortcut is the
    identity, or ``Linear + LayerNorm`` (a projection) when the channel count changes.

    Args:
        in_channels: ``C_in``.
        out_channels: ``C_out``.
        indices: spiral indices ``(V, L)`` of the mesh this block runs on.
        conv: the mesh convolution's factory, ``conv(in_channels, out_channels, indices)``,
            a module ``(B, V, C_in) -> (B, V, C_out)``.

    Shapes:
        ``(B, V, C_in) -> (B, V, C_out)``.
    """

    def __init__(self, in_channels: int, out_channels: int, indices,
                 conv: Callable[..., nn.Module] = SpiralConv):
        super().__init__()
        self.conv1 = conv(in_channels, out_channels, indices)
        self.norm1 = nn.LayerNorm(out_channels)
        self.conv2 = conv(out_channels, out_channels, indices)
        self.norm2 = nn.LayerNorm(out_channels)
        self.act = nn.ELU()
        self.shortcut = (nn.Identity() if in_channels == out_channels
                         else channel_map(in_channels, out_channels))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Args: x ``(B, V, C_in)``. Returns ``(B, V, C_out)``."""
        y = self.act(self.norm1(self.conv1(x)))
        y = self.norm2(self.conv2(y))
        return self.act(y + self.shortcut(x))


class MultiResolutionGroupConv(nn.Module):
    """Multi-resolution group convolution: every branch (resolution) runs its own residual blocks.

    Args:
        channels: channels of each branch, ``C_b``.
        spirals: spiral indices of each branch's mesh, ``(V_b, L)``, same order as ``channels``.
        num_blocks: residual spiral blocks per branch (each has two spiral convolutions).
        conv: the mesh convolution's factory
            ([`ResSpiralBlock`][handmesh_tutorial.nn.blocks.ResSpiralBlock]).

    Shapes:
        list of ``(B, V_b, C_b)`` -> list of ``(B, V_b, C_b)``.
    """

    def __init__(self, channels: Sequence[int], spirals: Sequence, num_blocks: int = 1,
                 conv: Callable[..., nn.Module] = SpiralConv):
        super().__init__()
        if len(channels) != len(spirals):
            raise ValueError(f"got {len(channels)} channel counts but {len(spirals)} spiral "
                             "index arrays; need one per branch")
        if num_blocks < 1:
            raise ValueError(f"num_blocks must be >= 1, got {num_blocks}")
        self.num_blocks = num_blocks
        self.branches = nn.ModuleList(
            nn.Sequential(*[ResSpiralBlock(c, c, idx, conv) for _ in range(num_blocks)])
            for c, idx in zip(channels, spirals, strict=True))

    def forward(self, xs: Sequence[torch.Tensor]) -> list[torch.Tensor]:
        """Args: xs, one ``(B, V_b, C_b)`` per branch. Returns the list of branch outputs."""
        if len(xs) != len(self.branches):
            raise ValueError(f"expected {len(self.branches)} branch inputs, got {len(xs)}")
        return [branch(x) for branch, x in zip(self.branches, xs, strict=True)]


class MultiResolutionFusion(nn.Module):
    """Multi-resolution fusion (HRNet's exchange unit) on a mesh hierarchy.

    ``out_i = ELU(sum_j f_ij(x_j))`` where, with ``l_j`` the hierarchy level of input ``j``:

    * ``l_j == l_i``: identity (a channel map if the channel counts differ);
    * ``l_j > l_i`` (``j`` coarser): channel map (``Linear + LayerNorm``) on the coarse mesh, then
      upsampling with ``up[l_i] @ ... @ up[l_j - 1]`` (barycentric, chained over the levels);
    * ``l_j < l_i`` (``j`` finer): downsampling with ``down[l_i - 1] @ ... @ down[l_j]`` (a vertex
      selection), then the channel map.

    Args:
        levels: hierarchy level of each input branch (0 = finest).
        channels: channels of each input branch.
        down: hierarchy downsampling matrices, ``down[l]`` ``(V_{l+1}, V_l)`` (scipy sparse).
        up: hierarchy upsampling matrices, ``up[l]`` ``(V_l, V_{l+1})`` (scipy sparse).
        out_levels: levels of the outputs (default: ``levels``). HRNet's last fusion keeps only
            the finest output.
        out_channels: channels of each output (default: the input channels of the same level).
        activation: apply the ELU after the sum (HRNet's ReLU after the sum).

    Shapes:
        list of ``(B, V_{l_j}, C_j)`` -> list of ``(B, V_{l_i}, C_i)``.
    """

    def __init__(self, levels: Sequence[int], channels: Sequence[int], down: Sequence,
                 up: Sequence, out_levels: Sequence[int] | None = None,
                 out_channels: Sequence[int] | None = None, activation: bool = True):
        super().__init__()
        levels, channels = list(levels), list(channels)
        if len(levels) != len(channels):
            raise ValueError(f"levels ({len(levels)}) and channels ({len(channels)}) differ in "
                             "length")
        out_levels = levels if out_levels is None else list(out_levels)
        if out_channels is None:
            missing = [lv for lv in out_levels if lv not in levels]
            if missing:
                raise ValueError(f"out_channels is needed for output levels {missing} that "
                                 "are not input levels")
            out_channels = [channels[levels.index(lv)] for lv in out_levels]
        out_channels = list(out_channels)
        if len(out_channels) != len(out_levels):
            raise ValueError(f"out_levels ({len(out_levels)}) and out_channels "
                             f"({len(out_channels)}) differ in length")
        self.levels, self.channels = levels, channels
        self.out_levels, self.out_channels = out_levels, out_channels
        self.paths = nn.ModuleList()
        for li, ci in zip(out_levels, out_channels, strict=True):
            row = nn.ModuleList()
            for lj, cj in zip(levels, channels, strict=True):
                if lj == li:
                    row.append(nn.Identity() if ci == cj else channel_map(cj, ci))
                elif lj > li:  # coarser input: map channels where it is cheap, then upsample
                    row.append(nn.Sequential(channel_map(cj, ci),
                                             SparseVertexMap(compose_up(up, li, lj))))
                else:  # finer input: select the coarse vertices, then map channels
                    row.append(nn.Sequential(SparseVertexMap(compose_down(down, lj, li)),
                                             channel_map(cj, ci)))
            self.paths.append(row)
        self.act = nn.ELU() if activation else nn.Identity()

    def forward(self, xs: Sequence[torch.Tensor]) -> list[torch.Tensor]:
        """Args: xs, one ``(B, V_j, C_j)`` per input branch. Returns one tensor per output."""
        if len(xs) != len(self.levels):
            raise ValueError(f"expected {len(self.levels)} branch inputs, got {len(xs)}")
        outs = []
        for row in self.paths:
            total = row[0](xs[0])
            for f, x in zip(row[1:], xs[1:], strict=True):
                total = total + f(x)
            outs.append(self.act(total))
        return outs


class TransformerBlock(nn.Module):
    """Pre-norm transformer block: ``x + MHA(LN(x))``, then ``x + MLP(LN(x))`` (GELU MLP).

    Args:
        channels: token width ``C`` (divisible by ``num_heads``).
        num_heads: attention heads.
        mlp_ratio: hidden width of the MLP as a multiple of ``C``.
        dropout: dropout in attention and MLP.

    Shapes:
        ``(B, N, C) -> (B, N, C)``.
    """

    def __init__(self, channels: int, num_heads: int = 4, mlp_ratio: float = 2.0,
                 dropout: float = 0.0):
        super().__init__()
        if channels % num_heads:
            raise ValueError(f"channels ({channels}) must be divisible by num_heads ({num_heads})")
        hidden = int(round(channels * mlp_ratio))
        self.norm1 = nn.LayerNorm(channels)
        self.attn = nn.MultiheadAttention(channels, num_heads, dropout=dropout, batch_first=True)
        self.norm2 = nn.LayerNorm(channels)
        self.mlp = nn.Sequential(nn.Linear(channels, hidden), nn.GELU(), nn.Dropout(dropout),
                                 nn.Linear(hidden, channels), nn.Dropout(dropout))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Args: x ``(B, N, C)``. Returns ``(B, N, C)``."""
        h = self.norm1(x)
        x = x + self.attn(h, h, h, need_weights=False)[0]
        return x + self.mlp(self.norm2(x))


class CoarseMeshTransformer(nn.Module):
    """Transformer on the coarse-mesh tokens (one token per coarsest vertex).

    Adds a learnable positional embedding per coarse vertex (the tokens have no other notion of
    where they are) and runs ``num_layers`` pre-norm
    [`TransformerBlock`][handmesh_tutorial.nn.blocks.TransformerBlock] s, so every coarse vertex can
    attend to every other (long-range interactions before the local spiral decoder).

    Args:
        num_vertices: coarse-mesh vertices ``V_c`` (tokens).
        channels: token width ``C``.
        num_heads: attention heads.
        num_layers: transformer blocks.
        mlp_ratio: MLP width multiple.
        dropout: dropout probability.

    Shapes:
        ``(B, V_c, C) -> (B, V_c, C)``.
    """

    def __init__(self, num_vertices: int, channels: int, num_heads: int = 4, num_layers: int = 1,
                 mlp_ratio: float = 2.0, dropout: float = 0.0):
        super().__init__()
        self.num_vertices = num_vertices
        self.position = nn.Parameter(torch.zeros(1, num_vertices, channels))
        nn.init.trunc_normal_(self.position, std=0.02)
        self.layers = nn.ModuleList(TransformerBlock(channels, num_heads, mlp_ratio, dropout)
                                    for _ in range(num_layers))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Args: x ``(B, V_c, C)``. Returns ``(B, V_c, C)``."""
        if x.dim() != 3 or x.shape[1:] != self.position.shape[1:]:
            raise ValueError(f"expected tokens (B, {self.num_vertices}, "
                             f"{self.position.shape[2]}), got {tuple(x.shape)}")
        x = x + self.position
        for layer in self.layers:
            x = layer(x)
        return x
