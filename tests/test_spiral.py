"""Spiral sequences (rings, rotational order, determinism, relabelling) and SpiralConv."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import torch
import trimesh
from scipy.sparse.csgraph import shortest_path

from handmesh_tutorial.nn.spiral import (
    SpiralConv,
    rotational_neighbours,
    spiral_indices,
    vertex_spiral,
)

torch.set_num_threads(1)


def grid_patch(n: int = 7):
    """Open n x n grid, counter-clockwise faces (normal +z)."""
    f = []
    for r in range(n - 1):
        for c in range(n - 1):
            a, b, d, e = r * n + c, r * n + c + 1, (r + 1) * n + c, (r + 1) * n + c + 1
            f += [[a, b, e], [a, e, d]]
    return np.asarray(f)


MESHES = {
    "icosphere": np.asarray(trimesh.creation.icosphere(subdivisions=2).faces),  # closed, 162 v
    "grid": grid_patch(7),  # open, 49 v
}


def graph_distance(faces):
    n = faces.max() + 1
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    adj = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return shortest_path(adj, unweighted=True, directed=False).astype(int)


def one_ring(faces, v):
    return set(faces[(faces == v).any(1)].ravel().tolist()) - {v}


def oriented_triples(faces):
    """All (a, b, c) such that a face reads a -> b -> c in its winding (cyclic rotations)."""
    return {tuple(t[k:] + t[:k]) for t in faces.tolist() for k in range(3)}


def is_boundary(faces, v):
    und = {}
    for t in faces[(faces == v).any(1)].tolist():
        for a, b in zip(t, t[1:] + t[:1], strict=True):
            if v in (a, b):
                key = frozenset((a, b))
                und[key] = und.get(key, 0) + 1
    return any(c == 1 for c in und.values())


@pytest.mark.parametrize("name", list(MESHES))
def test_rings_are_bfs_layers_in_order(name):
    faces = MESHES[name]
    L = 30
    s = spiral_indices(faces, L)
    dist = graph_distance(faces)
    assert s.shape == (faces.max() + 1, L) and s.dtype == np.int64
    for v in range(len(s)):
        row = s[v]
        assert row[0] == v
        assert len(set(row.tolist())) == L  # no duplicates
        d = dist[v, row]
        assert np.all(np.diff(d) >= 0), "spiral must go outwards ring by ring"
        # Every ring is complete except possibly the last one reached.
        last = d[-1]
        assert set(np.flatnonzero(dist[v] < last).tolist()) <= set(row.tolist())
        # First ring = the 1-ring computed from the faces.
        assert set(row[d == 1].tolist()) == one_ring(faces, v)


@pytest.mark.parametrize("name", list(MESHES))
def test_first_ring_follows_the_winding(name):
    faces = MESHES[name]
    s = spiral_indices(faces, 30)
    tri = oriented_triples(faces)
    for v in range(len(s)):
        ring = s[v, 1:1 + len(one_ring(faces, v))].tolist()
        pairs = list(zip(ring, ring[1:], strict=False))
        if is_boundary(faces, v):
            # Open fan, listed from its first neighbour: nothing precedes ring[0].
            assert not any((v, x, ring[0]) in tri for x in ring)
        else:
            pairs.append((ring[-1], ring[0]))
            assert ring[0] == min(ring), "interior rings start at the lowest-id neighbour"
        for a, b in pairs:
            assert (v, a, b) in tri, "consecutive ring members must form a face with v, in winding"


def test_second_ring_continues_rotation_on_a_regular_grid():
    # On an interior vertex of a regular grid the 2-ring (12 vertices) is one loop around v:
    # consecutive entries are neighbours, and it turns the same way as the first ring.
    n = 9
    faces = grid_patch(n)
    v = 4 * n + 4
    s = spiral_indices(faces, 19)[v]
    ring2 = s[7:19].tolist()
    dist = graph_distance(faces)
    assert all(dist[a, b] == 1 for a, b in zip(ring2, ring2[1:], strict=False))
    xy = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="xy"), -1).reshape(-1, 2)
    ang = np.unwrap(np.arctan2(*(xy[ring2] - xy[v]).T[::-1]))
    assert np.all(np.diff(ang) > 0), "2-ring must turn counter-clockwise like the faces"


@pytest.mark.parametrize("name", list(MESHES))
def test_independent_of_face_storage_order(name):
    faces = MESHES[name]
    rng = np.random.default_rng(1)
    shuffled = faces[rng.permutation(len(faces))]
    shifts = rng.integers(0, 3, len(faces))
    shuffled = np.array([np.roll(t, k) for t, k in zip(shuffled, shifts, strict=True)])
    np.testing.assert_array_equal(spiral_indices(faces, 20), spiral_indices(shuffled, 20))
    np.testing.assert_array_equal(spiral_indices(faces, 20), spiral_indices(faces, 20))


@pytest.mark.parametrize("name", list(MESHES))
def test_relabelling_is_equivariant(name):
    faces = MESHES[name]
    n = faces.max() + 1
    L = 25
    p = np.random.default_rng(2).permutation(n)  # new id of old vertex v is p[v]
    s_new = spiral_indices(p[faces], L)
    pinv = np.argsort(p)
    for v in range(n):
        got = s_new[p[v]]
        # Rings as sets are always equivariant.
        ring = one_ring(faces, v)
        assert set(got[1:1 + len(ring)].tolist()) == set(p[list(ring)].tolist())
        # Exactly equivariant once the first ring starts at the same (relabelled) neighbour:
        # the relabelled mesh starts at its lowest new id (interior) or at the fan's head.
        start = None if is_boundary(faces, v) else int(pinv[min(p[list(ring)])])
        np.testing.assert_array_equal(got, p[vertex_spiral(faces, v, L, start=start)])


def test_vertex_spiral_matches_table_and_start_rotates_first_ring():
    faces = MESHES["icosphere"]
    table = spiral_indices(faces, 13)
    np.testing.assert_array_equal(vertex_spiral(faces, 17, 13), table[17])
    deg = len(one_ring(faces, 17))
    other = int(table[17, 3])
    rot = vertex_spiral(faces, 17, 13, start=other)
    first = table[17, 1:1 + deg].tolist()
    i = first.index(other)
    assert rot[1:1 + deg].tolist() == first[i:] + first[:i]
    with pytest.raises(ValueError, match="not a neighbour"):
        vertex_spiral(faces, 17, 13, start=int(table[17, -1]))


def test_dilation_takes_every_kth():
    faces = MESHES["icosphere"]
    np.testing.assert_array_equal(spiral_indices(faces, 9, dilation=3),
                                  spiral_indices(faces, 27)[:, ::3])


def test_tiny_meshes_fallback():
    tet = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    s = spiral_indices(tet, 6)
    for v in range(4):
        assert sorted(s[v, :4].tolist()) == [0, 1, 2, 3] and s[v, 0] == v
        np.testing.assert_array_equal(s[v, 4:], s[v, :2])  # repeats cyclically from the start
    ico = trimesh.creation.icosahedron().faces  # 12 vertices: dilation runs out, no duplicates
    s = spiral_indices(ico, 9, dilation=2)
    full = spiral_indices(ico, 12)
    for v in range(12):
        assert len(set(s[v].tolist())) == 9
        np.testing.assert_array_equal(s[v, :6], full[v, ::2])
    # An isolated trailing vertex repeats itself.
    s = spiral_indices(tet, 3, num_vertices=5)
    np.testing.assert_array_equal(s[4], [4, 4, 4])


def test_spiral_errors():
    faces = MESHES["grid"]
    with pytest.raises(ValueError, match="length"):
        spiral_indices(faces, 0)
    with pytest.raises(ValueError, match="dilation"):
        spiral_indices(faces, 9, dilation=0)
    with pytest.raises(ValueError, match=r"shape \(F, 3\)"):
        spiral_indices(faces[:, :2], 9)
    flipped = faces.copy()
    flipped[0] = flipped[0, ::-1]
    with pytest.raises(ValueError, match="inconsistent orientation"):
        spiral_indices(flipped, 9)
    with pytest.raises(ValueError, match="num_vertices"):
        spiral_indices(faces, 9, num_vertices=3)


def test_rotational_neighbours_of_a_corner():
    # Corner 0 of the grid has neighbours 1 (right), n+1 (diagonal), n (up), in that winding.
    n = 7
    assert rotational_neighbours(grid_patch(n))[0] == [1, n + 1, n]


# ----------------------------------------------------------------------------------------------
# SpiralConv
# ----------------------------------------------------------------------------------------------
def test_spiralconv_equals_numpy_gather_linear():
    faces = MESHES["icosphere"]
    idx = spiral_indices(faces, 9)
    torch.manual_seed(0)
    conv = SpiralConv(5, 7, idx)
    x = torch.randn(3, idx.shape[0], 5)
    out = conv(x).detach().numpy()
    w = conv.linear.weight.detach().numpy().astype(np.float64)
    b = conv.linear.bias.detach().numpy().astype(np.float64)
    xn = x.numpy().astype(np.float64)
    ref = np.empty((3, idx.shape[0], 7))
    for v in range(idx.shape[0]):
        feat = np.concatenate([xn[:, j] for j in idx[v]], axis=1)  # neighbour-major (B, L*Cin)
        ref[:, v] = feat @ w.T + b
    np.testing.assert_allclose(out, ref, rtol=1e-5, atol=1e-5)


def test_spiralconv_init_buffer_and_grad():
    idx = spiral_indices(MESHES["grid"], 9)
    conv = SpiralConv(4, 6, idx)
    assert torch.all(conv.linear.bias == 0)
    bound = np.sqrt(6.0 / (4 * 9 + 6))
    assert conv.linear.weight.abs().max() <= bound
    assert conv.linear.weight.std() > 0.3 * bound  # Xavier-uniform, not zeros
    assert "indices" in dict(conv.named_buffers()) and "indices" not in conv.state_dict()
    assert conv.indices.dtype == torch.long
    conv = conv.to(torch.float64)  # .to keeps the index buffer usable
    x = torch.randn(2, 49, 4, dtype=torch.float64, requires_grad=True)
    conv(x).sum().backward()
    assert x.grad is not None and x.grad.shape == x.shape
    assert conv.linear.weight.grad.abs().sum() > 0


def test_spiralconv_shape_errors():
    idx = spiral_indices(MESHES["grid"], 9)
    conv = SpiralConv(4, 6, idx)
    with pytest.raises(ValueError, match=r"expects input \(B, 49, 4\) or \(49, 4\), got \(2, 48"):
        conv(torch.zeros(2, 48, 4))
    assert conv(torch.zeros(49, 4)).shape == (49, 6)  # one mesh, unbatched (issue 54)
    with pytest.raises(ValueError, match=r"got \(49, 5\)"):
        conv(torch.zeros(49, 5))
    with pytest.raises(ValueError, match=r"indices must have shape \(V, L\)"):
        SpiralConv(4, 6, idx[0])
    with pytest.raises(ValueError, match="indices must lie in"):
        SpiralConv(4, 6, idx[:10])
    with pytest.raises(ValueError, match="integers"):
        SpiralConv(4, 6, idx.astype(float))


SPIRALNET = Path(__file__).parent / "fixtures" / "spiralnet_spirals.npz"


@pytest.mark.parametrize("mesh", ["icosphere", "grid"])
@pytest.mark.parametrize(("length", "dilation"), [(9, 1), (12, 2)])
def test_spiralnet_convention_equals_their_construction(mesh, length, dilation):
    """convention="spiralnet" equals SpiralNet++'s own extract_spirals (run on OpenMesh by
    tools/spiralnet_reference.py) row for row; the library's default differs on every row, and
    its first ring is theirs read in the other direction from another start."""
    with np.load(SPIRALNET) as z:
        faces, ref = z[f"{mesh}_faces"], z[f"{mesh}_L{length}_d{dilation}"].astype(np.int64)
    got = spiral_indices(faces, length, dilation, convention="spiralnet")
    np.testing.assert_array_equal(got, ref)
    ours = spiral_indices(faces, length, dilation)
    assert (ours != ref).any(1).all()
    if dilation == 1:
        ring = rotational_neighbours(faces)
        for v in range(len(ring)):
            theirs = ref[v, 1:1 + len(ring[v])].tolist()
            k = theirs.index(ring[v][0])
            assert (theirs[k:] + theirs[:k])[::-1] == ring[v][1:] + ring[v][:1], v


def test_spiralnet_convention_depends_on_face_order_and_refuses_bad_input():
    faces = trimesh.creation.icosphere(subdivisions=1).faces
    a = spiral_indices(faces, 9, convention="spiralnet")
    b = spiral_indices(faces[::-1], 9, convention="spiralnet")
    deg = [len(r) for r in rotational_neighbours(faces)]
    assert (a != b).any()  # other starts, the same rings
    assert all(set(x[:1 + k]) == set(y[:1 + k]) for x, y, k in zip(a, b, deg, strict=True))
    np.testing.assert_array_equal(spiral_indices(faces, 9), spiral_indices(faces[::-1], 9))
    with pytest.raises(ValueError, match="convention must be one of"):
        spiral_indices(faces, 9, convention="openmesh")
    bowtie = np.array([[0, 1, 2], [0, 3, 4]])  # vertex 0: two open fans
    with pytest.raises(ValueError, match="vertex 0 is not manifold"):
        spiral_indices(bowtie, 3, convention="spiralnet")
