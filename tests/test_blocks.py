"""Tests of handmesh_tutorial.nn.blocks: sparse maps, residual spiral block, fusion, transformer."""

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
import torch
import trimesh

from handmesh_tutorial.nn import blocks
from handmesh_tutorial.nn.hierarchy import mesh_hierarchy
from handmesh_tutorial.nn.spiral import spiral_indices

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def hier():
    """A 3-level hierarchy of an icosphere (162 -> 81 -> 41 vertices) and its spirals."""
    mesh = trimesh.creation.icosphere(subdivisions=2)
    h = mesh_hierarchy(mesh.vertices, mesh.faces, factors=(2, 2), use_cache=False)
    spirals = [spiral_indices(f, 9) for f in h.faces]
    return SimpleNamespace(down=h.down, up=h.up, faces=h.faces, spirals=spirals,
                           sizes=[len(v) for v in h.vertices])


def _permuted(hier, seed=0):
    """The same hierarchy with every level's vertices relabelled by a random permutation.

    perm[l][k] is the old id of new vertex k at level l.
    """
    rng = np.random.default_rng(seed)
    perms = [rng.permutation(n) for n in hier.sizes]
    invs = [np.argsort(p) for p in perms]
    down = [sp.csr_matrix(d)[perms[l + 1]][:, perms[l]] for l, d in enumerate(hier.down)]
    up = [sp.csr_matrix(u)[perms[l]][:, perms[l + 1]] for l, u in enumerate(hier.up)]
    spirals = [inv[s[p]] for s, p, inv in zip(hier.spirals, perms, invs, strict=True)]
    return SimpleNamespace(down=down, up=up, spirals=spirals, sizes=hier.sizes), perms


# ----------------------------------------------------------------------------------------------
# SparseVertexMap and composition
# ----------------------------------------------------------------------------------------------

def test_sparse_vertex_map_matches_dense_product_and_gradient():
    rng = np.random.default_rng(1)
    dense = rng.random((7, 11)) * (rng.random((7, 11)) < 0.3)
    dense[np.arange(7), rng.integers(0, 11, 7)] += 0.5  # no empty row
    m = blocks.SparseVertexMap(sp.csr_matrix(dense)).double()
    x = torch.randn(3, 11, 5, dtype=torch.float64, requires_grad=True)
    y = m(x)
    expected = torch.einsum("vk,bkc->bvc", torch.from_numpy(dense), x)
    torch.testing.assert_close(y, expected)
    g = torch.randn_like(y)
    (gx,) = torch.autograd.grad((y * g).sum(), x)
    torch.testing.assert_close(gx, torch.einsum("vk,bvc->bkc", torch.from_numpy(dense), g))
    np.testing.assert_allclose(m.to_dense().numpy(), dense, rtol=1e-6)
    assert not m.is_selection


def test_sparse_vertex_map_selection_fast_path(hier):
    m = blocks.SparseVertexMap(hier.down[0])
    assert m.is_selection and m.nnz_per_row == 1
    x = torch.randn(2, hier.sizes[0], 3)
    kept = hier.down[0].indices  # CSR column of each row's single 1
    torch.testing.assert_close(m(x), x[:, kept])


def test_sparse_vertex_map_errors():
    with pytest.raises(ValueError, match="row without non-zeros"):
        blocks.SparseVertexMap(np.array([[1.0, 0.0], [0.0, 0.0]]))
    m = blocks.SparseVertexMap(np.eye(4))
    with pytest.raises(ValueError, match=r"expected features \(B, 4, C\)"):
        m(torch.zeros(1, 5, 2))


def test_compose_up_down_equal_dense_products(hier):
    up = blocks.compose_up(hier.up, 0, 2).toarray()
    np.testing.assert_allclose(up, hier.up[0].toarray() @ hier.up[1].toarray(), atol=1e-12)
    np.testing.assert_allclose(up.sum(1), 1.0, atol=1e-9)  # still interpolation weights
    down = blocks.compose_down(hier.down, 0, 2).toarray()
    np.testing.assert_array_equal(down, hier.down[1].toarray() @ hier.down[0].toarray())
    assert set(np.unique(down)) == {0.0, 1.0} and np.all(down.sum(1) == 1)
    with pytest.raises(ValueError, match="fine < coarse"):
        blocks.compose_up(hier.up, 1, 1)


# ----------------------------------------------------------------------------------------------
# Residual spiral block and group conv
# ----------------------------------------------------------------------------------------------

def test_res_spiral_block_shapes_and_shortcut(hier):
    same = blocks.ResSpiralBlock(8, 8, hier.spirals[0])
    proj = blocks.ResSpiralBlock(8, 16, hier.spirals[0])
    assert isinstance(same.shortcut, torch.nn.Identity)
    assert isinstance(proj.shortcut[0], torch.nn.Linear) and proj.shortcut[0].out_features == 16
    x = torch.randn(2, hier.sizes[0], 8)
    assert same(x).shape == (2, hier.sizes[0], 8)
    assert proj(x).shape == (2, hier.sizes[0], 16)


def test_res_spiral_block_equals_formula(hier):
    blk = blocks.ResSpiralBlock(4, 6, hier.spirals[1]).double()
    x = torch.randn(2, hier.sizes[1], 4, dtype=torch.float64)
    elu, ln = torch.nn.functional.elu, torch.nn.functional.layer_norm
    h = elu(ln(blk.conv1(x), (6,), blk.norm1.weight, blk.norm1.bias))
    h = ln(blk.conv2(h), (6,), blk.norm2.weight, blk.norm2.bias)
    sc = ln(blk.shortcut[0](x), (6,), blk.shortcut[1].weight, blk.shortcut[1].bias)
    torch.testing.assert_close(blk(x), elu(h + sc))


def test_group_conv_runs_each_branch_separately(hier):
    g = blocks.MultiResolutionGroupConv([4, 8], [hier.spirals[1], hier.spirals[2]], num_blocks=2)
    xs = [torch.randn(2, hier.sizes[1], 4), torch.randn(2, hier.sizes[2], 8)]
    ys = g(xs)
    torch.testing.assert_close(ys[1], g.branches[1](xs[1]))
    assert [y.shape for y in ys] == [x.shape for x in xs]
    with pytest.raises(ValueError, match="one per branch"):
        blocks.MultiResolutionGroupConv([4], [hier.spirals[1], hier.spirals[2]])


# ----------------------------------------------------------------------------------------------
# Fusion
# ----------------------------------------------------------------------------------------------

def _np_layer_norm(x, w, b, eps=1e-5):
    mu = x.mean(-1, keepdims=True)
    var = x.var(-1, keepdims=True)
    return (x - mu) / np.sqrt(var + eps) * w + b


def _np_channel_map(seq, x):
    lin, norm = seq[0], seq[1]
    y = x @ lin.weight.detach().numpy().T + lin.bias.detach().numpy()
    return _np_layer_norm(y, norm.weight.detach().numpy(), norm.bias.detach().numpy())


def test_fusion_matches_dense_numpy_computation(hier):
    """out_i = ELU(sum_j f_ij(x_j)) computed with dense numpy up/down matrices."""
    levels, channels = [0, 1, 2], [3, 5, 7]
    fusion = blocks.MultiResolutionFusion(levels, channels, hier.down, hier.up).double()
    for p in fusion.parameters():  # non-trivial LayerNorm affine parameters
        torch.nn.init.normal_(p)
    rng = np.random.default_rng(2)
    xs = [rng.normal(size=(2, hier.sizes[lv], c)) for lv, c in zip(levels, channels, strict=True)]
    outs = fusion([torch.from_numpy(x) for x in xs])
    U = [u.toarray() for u in hier.up]
    D = [d.toarray() for d in hier.down]
    for i, li in enumerate(levels):
        total = 0.0
        for j, lj in enumerate(levels):
            f = fusion.paths[i][j]
            if lj == li:
                term = xs[j]
            elif lj > li:  # coarser: channel map, then upsample level by level
                up = np.eye(hier.sizes[li])
                for lv in range(li, lj):
                    up = up @ U[lv]
                term = np.einsum("vk,bkc->bvc", up, _np_channel_map(f[0], xs[j]))
            else:  # finer: select, then channel map
                down = np.eye(hier.sizes[lj])
                for lv in range(lj, li):
                    down = D[lv] @ down
                term = _np_channel_map(f[1], np.einsum("vk,bkc->bvc", down, xs[j]))
            total = total + term
        expected = np.where(total > 0, total, np.expm1(total))  # ELU
        # The map weights are stored in float32 (1e-7 relative), the rest runs in float64.
        np.testing.assert_allclose(outs[i].detach().numpy(), expected, rtol=1e-6, atol=1e-6)


def test_fusion_out_levels_and_errors(hier):
    f = blocks.MultiResolutionFusion([0, 1, 2], [3, 5, 7], hier.down, hier.up, out_levels=[0])
    xs = [torch.randn(1, n, c) for n, c in zip(hier.sizes, [3, 5, 7], strict=True)]
    (y,) = f(xs)
    assert y.shape == (1, hier.sizes[0], 3)
    with pytest.raises(ValueError, match="out_channels is needed"):
        blocks.MultiResolutionFusion([1, 2], [5, 7], hier.down, hier.up, out_levels=[0])
    with pytest.raises(ValueError, match="expected 3 branch inputs"):
        f(xs[:2])


# ----------------------------------------------------------------------------------------------
# Equivariance under vertex relabelling
# ----------------------------------------------------------------------------------------------

def test_block_and_fusion_are_equivariant_to_vertex_relabelling(hier):
    perm_h, perms = _permuted(hier, seed=3)
    torch.manual_seed(0)
    blk = blocks.ResSpiralBlock(4, 6, hier.spirals[0])
    blk_p = blocks.ResSpiralBlock(4, 6, perm_h.spirals[0])
    blk_p.load_state_dict(blk.state_dict())
    x = torch.randn(2, hier.sizes[0], 4)
    p0 = torch.from_numpy(perms[0])
    torch.testing.assert_close(blk_p(x[:, p0]), blk(x)[:, p0])

    fusion = blocks.MultiResolutionFusion([0, 1, 2], [3, 5, 7], hier.down, hier.up)
    fusion_p = blocks.MultiResolutionFusion([0, 1, 2], [3, 5, 7], perm_h.down, perm_h.up)
    fusion_p.load_state_dict(fusion.state_dict())
    xs = [torch.randn(2, n, c) for n, c in zip(hier.sizes, [3, 5, 7], strict=True)]
    ys = fusion(xs)
    ys_p = fusion_p([x[:, torch.from_numpy(p)] for x, p in zip(xs, perms, strict=True)])
    for y, y_p, p in zip(ys, ys_p, perms, strict=True):
        torch.testing.assert_close(y_p, y[:, torch.from_numpy(p)], rtol=1e-5, atol=1e-5)
    # A wrong (unpermuted) topology breaks it: the test can fail.
    assert not torch.allclose(blk(x[:, p0]), blk(x)[:, p0], atol=1e-3)


# ----------------------------------------------------------------------------------------------
# Transformer
# ----------------------------------------------------------------------------------------------

def test_transformer_block_matches_written_out_prenorm():
    torch.manual_seed(0)
    blk = blocks.TransformerBlock(8, num_heads=2).eval()
    x = torch.randn(2, 5, 8)
    h = blk.norm1(x)
    a = blk.attn(h, h, h)[0]
    y = x + a
    expected = y + blk.mlp(blk.norm2(y))
    torch.testing.assert_close(blk(x), expected)
    with pytest.raises(ValueError, match="divisible"):
        blocks.TransformerBlock(10, num_heads=4)


def test_coarse_transformer_positional_embedding_breaks_permutation_symmetry():
    torch.manual_seed(0)
    tr = blocks.CoarseMeshTransformer(6, 8, num_heads=2, num_layers=2).eval()
    x = torch.randn(2, 6, 8)
    perm = torch.tensor([3, 0, 5, 1, 2, 4])
    y = tr(x)
    assert y.shape == (2, 6, 8)
    # Attention alone is permutation-equivariant; the learned position per coarse vertex is not.
    with torch.no_grad():
        tr.position.zero_()
    torch.testing.assert_close(tr(x[:, perm]), tr(x)[:, perm], rtol=1e-5, atol=1e-5)
    with torch.no_grad():
        tr.position.normal_()
    assert not torch.allclose(tr(x[:, perm]), tr(x)[:, perm], atol=1e-3)
    with pytest.raises(ValueError, match=r"expected tokens \(B, 6, 8\)"):
        tr(torch.zeros(1, 7, 8))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_sparse_vertex_map_csr_equals_gather_reference(hier, dtype):
    import copy
    # composed upsampling (several non-zeros per row) and a dense-ish random map
    rng = np.random.default_rng(4)
    dense = rng.random((30, 20)) * (rng.random((30, 20)) < 0.4) + np.eye(30, 20)
    for mat in (blocks.compose_up(hier.up, 0, 2), hier.up[1], sp.csr_matrix(dense)):
        m = blocks.SparseVertexMap(mat).to(dtype)
        assert m.method == "csr"
        x = torch.randn(3, mat.shape[1], 5, dtype=dtype, requires_grad=True)
        g = torch.randn(3, mat.shape[0], 5, dtype=dtype)
        outs = {}
        for method in ("gather", "csr"):
            m.method = method
            y = m(x)
            (gx,) = torch.autograd.grad((y * g).sum(), x)
            outs[method] = (y.detach(), gx)
        tol = {"rtol": 1e-5, "atol": 1e-6} if dtype == torch.float32 else {}
        torch.testing.assert_close(outs["csr"][0], outs["gather"][0], **tol)
        torch.testing.assert_close(outs["csr"][1], outs["gather"][1], **tol)
        # and against the dense product with the stored (float32) weights
        d = m.to_dense().to(dtype)
        torch.testing.assert_close(outs["csr"][0], torch.einsum("vk,bkc->bvc", d, x.detach()),
                                   **tol)
        torch.testing.assert_close(outs["csr"][1], torch.einsum("vk,bvc->bkc", d, g), **tol)
        m.method = "csr"
        torch.testing.assert_close(copy.deepcopy(m)(x.detach()), outs["csr"][0])
    with pytest.raises(ValueError, match="method"):
        blocks.SparseVertexMap(dense, method="dense")


def test_pool_layer_is_a_hand_written_barycentric_pooling_and_takes_one_mesh():
    """Issue 54: ``Pool`` (SpiralNet++'s name) against closest-point barycentric interpolation
    written here with trimesh's triangle routines, and the down map against plain indexing."""
    from handmesh_tutorial.nn.hierarchy import to_torch_sparse

    mesh = trimesh.creation.icosphere(subdivisions=2)
    mesh.vertices = mesh.vertices * np.array([1.0, 0.7, 0.4])  # not a sphere: uneven triangles
    h = mesh_hierarchy(mesh.vertices, mesh.faces, factors=(2,), use_cache=False)
    fine, coarse, cf = h.vertices[0], h.vertices[1], h.faces[1]
    feats = np.random.default_rng(0).standard_normal((len(coarse), 5))
    want = np.zeros((len(fine), 5))
    tris = coarse[cf]
    for i, p in enumerate(fine):
        close = trimesh.triangles.closest_point(tris, np.repeat(p[None], len(tris), 0))
        t = int(np.argmin(np.linalg.norm(close - p, axis=1)))
        bary = trimesh.triangles.points_to_barycentric(tris[t:t + 1], close[t:t + 1])[0]
        bary = np.clip(bary, 0, None) / np.clip(bary, 0, None).sum()
        want[i] = bary @ feats[cf[t]]
    want[h.kept[0]] = feats  # a kept vertex copies its coarse self
    up, down = blocks.Pool(h.up[0]), blocks.Pool(h.down[0])
    x = torch.from_numpy(feats).float()
    np.testing.assert_allclose(up(x).numpy(), want, atol=1e-5)  # unbatched (V, C)
    np.testing.assert_allclose(up(x[None].expand(2, -1, -1)).numpy(), [want, want], atol=1e-5)
    y = torch.from_numpy(want).float()
    torch.testing.assert_close(down(y), y[torch.from_numpy(h.kept[0])])
    torch.testing.assert_close(torch.sparse.mm(to_torch_sparse(h.up[0]), x), up(x))
    with pytest.raises(ValueError, match=r"\(B, 81, C\) or \(81, C\)"):
        up(torch.zeros(80, 5))


def test_spiral_conv_takes_one_unbatched_mesh():
    from handmesh_tutorial.nn.spiral import SpiralConv

    mesh = trimesh.creation.icosphere(subdivisions=1)
    idx = spiral_indices(mesh.faces, 9)
    conv = SpiralConv(3, 4, idx)
    x = torch.randn(len(mesh.vertices), 3)
    want = conv.linear(x[torch.from_numpy(idx)].reshape(len(idx), -1))  # gather by hand
    torch.testing.assert_close(conv(x), want)
    torch.testing.assert_close(conv(x[None])[0], want)
    with pytest.raises(ValueError, match="or \\(42, 3\\)"):
        conv(torch.zeros(42, 4))
