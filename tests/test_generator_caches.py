"""The generator's per-layout caches and fast paths give bitwise what the plain computations give.

Each fast path (issue 14: less work per scene, same bytes) is compared with an independent
computation written here the slow, obvious way.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from handmesh_tutorial import hand as H
from handmesh_tutorial.collision import Cylinders, hand_cylinders
from handmesh_tutorial.hand._common import _boundary_loop
from handmesh_tutorial.hand.appearance import labelled_skin_colors
from handmesh_tutorial.scenes.contact import _MeshSDF, _sum_rows_by
from handmesh_tutorial.scenes.rig import _Rig, _tree_tables


def _boundary_loop_by_sets(faces):
    """The boundary loop from a set of half-edges (the obvious way)."""
    # half-edges (0,1) of every face, then (1,2), then (2,0): the loop starts at the first
    # twinless one in this order
    e = [(f[i], f[(i + 1) % 3]) for i in range(3) for f in faces.tolist()]
    key = set(e)
    nxt = dict((a, b) for a, b in e if (b, a) not in key)
    start = next(a for a, b in e if (b, a) not in key)
    loop = [start]
    while nxt[loop[-1]] != start:
        loop.append(nxt[loop[-1]])
    return loop


def test_boundary_loop_matches_the_set_walk_on_open_meshes():
    disc = trimesh.creation.icosphere(2)
    keep = disc.vertices[disc.faces].mean(1)[:, 2] < 0.3            # a sphere with a hole
    faces = disc.faces[keep]
    assert _boundary_loop(faces).tolist() == _boundary_loop_by_sets(faces)
    model = H.HandModel("right")
    skin = model.faces[~np.asarray(model.template.cap_faces, bool)]
    assert _boundary_loop(skin).tolist() == _boundary_loop_by_sets(skin)
    with pytest.raises(ValueError, match="one boundary loop"):
        two_holes = disc.faces[(disc.vertices[disc.faces].mean(1)[:, 2] < 0.3)
                               & (disc.vertices[disc.faces].mean(1)[:, 2] > -0.3)]
        _boundary_loop(two_holes)


def test_sum_rows_by_equals_add_at_bitwise():
    rng = np.random.default_rng(0)
    idx = rng.integers(0, 50, 3000)
    rows = rng.normal(size=(3000, 3)) * 10.0 ** rng.integers(-8, 3, (3000, 1))
    want = np.zeros((60, 3))
    np.add.at(want, idx, rows)
    got = _sum_rows_by(idx, rows, 60)
    assert got.shape == (60, 3) and np.array_equal(got, want)
    assert np.array_equal(_sum_rows_by(idx[:0], rows[:0], 4), np.zeros((4, 3)))


def _normals_with_add_at(v, f):
    """Angle-weighted vertex normals and edge pseudo-normals with np.add.at, corner by corner."""
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    fn /= np.linalg.norm(fn, axis=1, keepdims=True) + 1e-30
    vn = np.zeros_like(v)
    for i in range(3):
        e1 = v[f[:, (i + 1) % 3]] - v[f[:, i]]
        e2 = v[f[:, (i + 2) % 3]] - v[f[:, i]]
        cosang = (e1 * e2).sum(1) / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
                                     + 1e-30)
        np.add.at(vn, f[:, i], np.arccos(np.clip(cosang, -1, 1))[:, None] * fn)
    e = np.sort(np.stack([f[:, [1, 2]], f[:, [2, 0]], f[:, [0, 1]]], 1), axis=2)
    _, inv = np.unique(e[..., 0] * len(v) + e[..., 1], return_inverse=True)
    inv = inv.reshape(-1)
    en = np.zeros((inv.max() + 1, 3))
    np.add.at(en, inv, np.repeat(fn, 3, axis=0))
    return vn, en, inv.reshape(-1, 3)


@pytest.mark.parametrize("which", ["hand", "box"])
def test_mesh_sdf_normals_are_bitwise_the_add_at_ones(which):
    if which == "hand":
        model = H.HandModel("left")
        v = model.template_vertices.astype(float) + 0.01
        f = np.asarray(model.faces, np.int64)
    else:
        box = trimesh.creation.box((0.02, 0.03, 0.05))
        v, f = np.asarray(box.vertices, float), np.asarray(box.faces, np.int64)
    for _ in range(2):   # the second build takes the edge ids from the cache
        sdf = _MeshSDF(v, f)
        vn, en, edge_of = _normals_with_add_at(v, f)
        assert np.array_equal(sdf.vn, vn) and np.array_equal(sdf.en, en)
        assert np.array_equal(sdf.edge_of, edge_of)
    assert not sdf.edge_of.flags.writeable   # shared by every mesh of this layout


def test_unchecked_cylinders_equal_the_checked_ones():
    rng = np.random.default_rng(1)
    p0, p1 = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    r = rng.uniform(0.01, 0.02, 5)
    adj = np.array([[0, 1], [1, 2]], np.int64)
    for kw in ({}, {"names": tuple("abcde"), "parts": np.arange(5), "adjacent": adj}):
        a, b = Cylinders(p0, p1, r, **kw), Cylinders._unchecked(p0, p1, r, **kw)
        assert a.names == b.names and len(a) == len(b) == 5
        for name in ("p0", "p1", "radius", "parts", "adjacent"):
            x, y = getattr(a, name), getattr(b, name)
            assert x.dtype == y.dtype and np.array_equal(x, y), name


def test_rigs_of_one_layout_share_tree_tables_equal_to_a_fresh_build():
    model = H.HandModel("right")
    out = model()
    cyl = hand_cylinders(out, model=model)
    parents = np.asarray(model.parents, int)
    attach = np.array([0] * 5 + list(range(1, 16)), int)
    first = _tree_tables(parents, attach, cyl.adjacent)
    assert _tree_tables(parents, attach, cyl.adjacent) is first          # cached
    subtree, moved, self_pairs = first
    with pytest.raises(ValueError):                                      # shared: read-only
        moved[1][0] = 0
    # independent: a cylinder moves with node k when its node is k or below k
    for k in range(len(parents)):
        below = {k}
        for m in range(len(parents)):
            a = m
            while a != -1 and a not in below:
                a = parents[a] if a > 0 else -1
            if a in below:
                below.add(m)
        assert set(subtree[k].tolist()) == below
        assert moved[k].tolist() == [c for c in range(len(attach)) if attach[c] in below]
        adj = {tuple(x) for x in cyl.adjacent.tolist()}
        want = [(a, b) for a in moved[k] for b in range(len(attach))
                if b not in moved[k] and (min(a, b), max(a, b)) not in adj]
        im, st = self_pairs[k]
        assert [(moved[k][i], s) for i, s in zip(im, st, strict=True)] == want
    # another adjacency is another layout
    other = _tree_tables(parents, attach, cyl.adjacent[:3])
    assert other is not first and len(other[2][1][0]) > len(self_pairs[1][0])
    rig = _Rig(model.rest_joints, parents, np.tile(np.eye(3), (15, 1, 1)), -np.ones((15, 3)),
               np.ones((15, 3)), cyl, attach)
    assert rig.moved is moved and rig.self_pairs is self_pairs


@pytest.mark.parametrize("tone", [0, 3, 5])
def test_vertex_colors_from_the_cached_layout_equal_labelled_skin_colors(tone):
    model = H.HandModel("left")
    for seed in (0, 7):   # the first call builds the layout, the second reuses it
        got = model.vertex_colors(tone, rng=seed)
        want = labelled_skin_colors(model.template_vertices, model.faces, model.rest_joints,
                                      model.palmar, model.template.nail, tone, seed)
        assert got.dtype == np.float32 and np.array_equal(got, want)
    assert not np.array_equal(model.vertex_colors(tone, rng=1), got)   # the noise is not cached
