"""``torch.autograd.gradcheck`` of the liftable ops: each analytical gradient (including the
hand-written backward of the sparse vertex product) against finite differences, in float64.

A user who lifts a block into their own network relies on its gradient; a wrong backward trains
silently worse, so every differentiable op a researcher may take is checked here on small inputs.
"""

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
import torch
import trimesh
from torch.autograd import gradcheck, gradgradcheck

from handmesh_tutorial.nn import blocks, keypoints, losses, rotation
from handmesh_tutorial.nn.hierarchy import mesh_hierarchy
from handmesh_tutorial.nn.spiral import SpiralConv, spiral_indices

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def hier():
    """A 3-level hierarchy of an icosahedron sphere (42 -> 21 -> 11 vertices), spirals of 9."""
    mesh = trimesh.creation.icosphere(subdivisions=1)
    h = mesh_hierarchy(mesh.vertices, mesh.faces, factors=(2, 2), use_cache=False)
    spirals = [spiral_indices(f, 9) for f in h.faces]
    return SimpleNamespace(down=h.down, up=h.up, faces=h.faces, spirals=spirals,
                           sizes=[len(v) for v in h.vertices])


def _x(*shape, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.randn(*shape, generator=g, dtype=torch.float64).requires_grad_(True)


def _random_sparse(rows, cols, seed=0):
    rng = np.random.default_rng(seed)
    dense = rng.random((rows, cols)) * (rng.random((rows, cols)) < 0.3)
    dense[np.arange(rows), rng.integers(0, cols, rows)] += 0.5  # no empty row
    return sp.csr_matrix(dense)


@pytest.mark.parametrize("method", ["csr", "gather"])
def test_sparse_vertex_map_gradient(method):
    m = blocks.SparseVertexMap(_random_sparse(7, 11), method=method).double()
    assert gradcheck(m, (_x(2, 11, 3),))


def test_sparse_vertex_map_second_derivative():
    # the custom autograd.Function's backward is itself a (linear) product: double backward works
    m = blocks.SparseVertexMap(_random_sparse(6, 9, seed=1)).double()
    assert gradgradcheck(m, (_x(2, 9, 2),))


def test_sparse_vertex_map_transpose_is_the_adjoint():
    # <M x, y> == <x, M^T y>: the backward uses the stored transpose, checked without autograd
    mat = _random_sparse(8, 13, seed=2)
    fwd = blocks.SparseVertexMap(mat).double()
    adj = blocks.SparseVertexMap(mat.T).double()
    x, y = _x(3, 13, 4, seed=3).detach(), _x(3, 8, 4, seed=4).detach()
    torch.testing.assert_close((fwd(x) * y).sum(), (x * adj(y)).sum())


def test_selection_map_gradient(hier):
    m = blocks.SparseVertexMap(hier.down[0]).double()
    assert m.is_selection
    assert gradcheck(m, (_x(2, hier.sizes[0], 2),))


def test_spiral_conv_gradient_wrt_input_and_weights(hier):
    conv = SpiralConv(3, 4, hier.spirals[1]).double()
    x = _x(2, hier.sizes[1], 3)
    assert gradcheck(conv, (x,))
    w, b = conv.linear.weight, conv.linear.bias

    def as_function_of_weights(weight, bias):
        return torch.nn.functional.linear(
            x.detach()[:, conv.indices.reshape(-1)].reshape(2, hier.sizes[1], -1), weight, bias)

    torch.testing.assert_close(as_function_of_weights(w, b), conv(x.detach()))
    assert gradcheck(as_function_of_weights, (w.detach().clone().requires_grad_(True),
                                              b.detach().clone().requires_grad_(True)))


def test_residual_spiral_block_gradient(hier):
    block = blocks.ResSpiralBlock(3, 5, hier.spirals[2]).double()
    assert gradcheck(block, (_x(2, hier.sizes[2], 3),))


def test_multi_resolution_fusion_gradient(hier):
    fusion = blocks.MultiResolutionFusion([0, 1, 2], [3, 4, 2], hier.down, hier.up).double()
    xs = [_x(1, n, c, seed=i) for i, (n, c) in enumerate(zip(hier.sizes, [3, 4, 2], strict=True))]

    def flat(*inputs):
        return torch.cat([y.flatten() for y in fusion(list(inputs))])

    assert gradcheck(flat, tuple(xs))


def test_coarse_mesh_transformer_gradient():
    torch.manual_seed(0)
    tr = blocks.CoarseMeshTransformer(num_vertices=5, channels=8, num_heads=2).double().eval()
    assert gradcheck(tr, (_x(2, 5, 8),))


def test_similarity_align_and_aligned_joint_loss_gradients():
    target = _x(2, 6, 3, seed=1).detach()
    assert gradcheck(lambda p: losses.similarity_align(p, target), (_x(2, 6, 3),))
    assert gradcheck(lambda p: losses.aligned_joint_loss(p, target), (_x(2, 6, 3, seed=2),))


def test_mesh_losses_gradients(hier):
    faces = torch.as_tensor(np.asarray(hier.faces[2]), dtype=torch.int64)
    n = hier.sizes[2]
    target = _x(1, n, 3, seed=5).detach()
    assert gradcheck(lambda p: losses.edge_length_loss(p, target, faces), (_x(1, n, 3),))
    assert gradcheck(lambda p: losses.normal_loss(p, target, faces), (_x(1, n, 3, seed=6),))


def test_rotation_6d_and_soft_argmax_gradients():
    assert gradcheck(rotation.rotation_6d_to_matrix, (_x(3, 6),))
    assert gradcheck(keypoints.soft_argmax, (_x(1, 2, 4, 5),))
