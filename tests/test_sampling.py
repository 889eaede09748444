"""Mesh hierarchy: vertex subsets, 0/1 down matrices, barycentric up matrices, manifold levels."""

from __future__ import annotations

import importlib.util
import json
import math
import os
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import trimesh

import handmesh_tutorial as hmt
from handmesh_tutorial.nn.hierarchy import (
    barycentric_upsampling,
    decimate,
    default_cache_dir,
    mesh_hierarchy,
    selection_matrix,
    to_torch_sparse,
    vertex_quadrics,
)

HAVE_HAND = importlib.util.find_spec("handmesh_tutorial.hand") is not None


def grid_patch(n: int = 12, seed: int = 0):
    """Open, planar, counter-clockwise (normal +z) triangulated n x n grid, slightly jittered."""
    rng = np.random.default_rng(seed)
    xs, ys = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="xy")
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n)], axis=1)
    v[:, :2] += rng.uniform(-0.15, 0.15, size=(n * n, 2))
    f = []
    for r in range(n - 1):
        for c in range(n - 1):
            a, b, d, e = r * n + c, r * n + c + 1, (r + 1) * n + c, (r + 1) * n + c + 1
            f += [[a, b, e], [a, e, d]]
    return v, np.asarray(f)


@pytest.fixture(scope="module")
def sphere():
    m = trimesh.creation.icosphere(subdivisions=3)  # 642 vertices, unit radius
    return np.asarray(m.vertices), np.asarray(m.faces)


@pytest.fixture(scope="module")
def sphere_hier(sphere):
    return mesh_hierarchy(*sphere, use_cache=False)


def edge_face_counts(faces):
    """Undirected edge -> number of faces, and directed edge -> count (independent of the lib)."""
    und, dire = Counter(), Counter()
    for a, b, c in np.asarray(faces).tolist():
        for x, y in ((a, b), (b, c), (c, a)):
            und[frozenset((x, y))] += 1
            dire[(x, y)] += 1
    return und, dire


def assert_manifold(vertices, faces, closed: bool):
    und, dire = edge_face_counts(faces)
    assert max(dire.values()) == 1, "a directed edge appears twice: orientation broken"
    assert set(und.values()) <= ({2} if closed else {1, 2}), "non-manifold edge"
    assert len({frozenset(t) for t in faces.tolist()}) == len(faces), "duplicate face"
    assert np.array_equal(np.unique(faces), np.arange(len(vertices))), "unused vertex"
    # Each vertex has a single fan (no pinched vertices): its link is one cycle or one path.
    for v in range(len(vertices)):
        link = [(b, c) for a, b, c in
                (np.roll(t, -list(t).index(v)) for t in faces[(faces == v).any(1)])]
        succ = dict(link)
        start = next((x for x in succ if x not in succ.values()), link[0][0])
        seen, x = [start], succ.get(start)
        while x is not None and x != start:
            seen.append(x)
            x = succ.get(x)
        assert len(set(seen)) == len(set(succ) | set(succ.values())), f"vertex {v} is pinched"
    if closed:
        m = trimesh.Trimesh(vertices, faces, process=False)
        assert m.is_watertight and m.is_winding_consistent
        assert m.volume > 0


# ----------------------------------------------------------------------------------------------
# Hierarchy on the icosphere
# ----------------------------------------------------------------------------------------------
def test_counts_halve_with_ceil(sphere_hier):
    assert sphere_hier.num_vertices == [642, 321, 161, 81, 41]
    for a, b in zip(sphere_hier.num_vertices, sphere_hier.num_vertices[1:], strict=False):
        assert b == math.ceil(a / 2)
    assert sphere_hier.num_levels == 5
    assert len(sphere_hier.down) == len(sphere_hier.up) == 4


def test_coarse_vertices_are_exact_rows_of_finer(sphere_hier):
    for l in range(4):
        fine, coarse = sphere_hier.vertices[l], sphere_hier.vertices[l + 1]
        rows = {tuple(r) for r in fine.tolist()}
        assert all(tuple(r) in rows for r in coarse.tolist())
        assert np.array_equal(coarse, fine[sphere_hier.kept[l]])  # bit-exact, not approximate
        assert np.all(np.diff(sphere_hier.kept[l]) > 0)  # kept ids are sorted, distinct
    orig = sphere_hier.original_index(4)
    assert np.array_equal(sphere_hier.vertices[4], sphere_hier.vertices[0][orig])


def test_down_is_a_selection(sphere_hier):
    for l, d in enumerate(sphere_hier.down):
        assert d.shape == (sphere_hier.num_vertices[l + 1], sphere_hier.num_vertices[l])
        dense = d.toarray()
        assert set(np.unique(dense)) == {0.0, 1.0}
        assert np.all((dense == 1).sum(1) == 1)
        assert np.all((dense == 1).sum(0) <= 1)
        assert np.array_equal(d @ sphere_hier.vertices[l], sphere_hier.vertices[l + 1])


def test_up_rows_are_barycentric(sphere_hier):
    for l, u in enumerate(sphere_hier.up):
        assert u.shape == (sphere_hier.num_vertices[l], sphere_hier.num_vertices[l + 1])
        assert u.data.min() >= 0.0
        np.testing.assert_allclose(np.asarray(u.sum(1)).ravel(), 1.0, atol=1e-12)
        assert np.diff(u.indptr).max() <= 3
        # The non-zeros of a row are corners of one coarse triangle.
        faces = {frozenset(t) for t in sphere_hier.faces[l + 1].tolist()}
        for r in range(u.shape[0]):
            cols = set(u.indices[u.indptr[r]:u.indptr[r + 1]].tolist())
            assert len(cols) == 1 or any(cols <= t for t in faces)


def test_kept_vertices_map_to_themselves(sphere_hier):
    for l, (u, kept) in enumerate(zip(sphere_hier.up, sphere_hier.kept, strict=True)):
        rows = u[kept].toarray()
        np.testing.assert_array_equal(rows, np.eye(sphere_hier.num_vertices[l + 1]))


def test_up_equals_closest_point_from_trimesh(sphere_hier):
    # Independent check: trimesh's rtree-based closest point on the coarse surface.
    for l in range(4):
        fine = sphere_hier.vertices[l]
        coarse = trimesh.Trimesh(sphere_hier.vertices[l + 1], sphere_hier.faces[l + 1],
                                 process=False)
        closest, dist, _ = trimesh.proximity.closest_point(coarse, fine)
        ours = sphere_hier.up[l] @ sphere_hier.vertices[l + 1]
        np.testing.assert_allclose(np.linalg.norm(ours - fine, axis=1), dist, atol=1e-9)
        np.testing.assert_allclose(ours, closest, atol=1e-7)


def test_up_is_translation_equivariant(sphere_hier):
    t = np.array([0.3, -2.0, 5.0])
    for l, u in enumerate(sphere_hier.up):
        x = sphere_hier.vertices[l + 1]
        np.testing.assert_allclose(u @ (x + t), u @ x + t, atol=1e-12)


def test_reconstruction_error_is_bounded(sphere_hier):
    errs = sphere_hier.reconstruction_errors()
    assert len(errs) == 4
    for l, (mean, mx) in enumerate(errs):
        v, f = sphere_hier.vertices[l + 1], sphere_hier.faces[l + 1]
        edge = np.linalg.norm(v[f] - v[np.roll(f, 1, axis=1)], axis=2).mean()
        assert 0 < mean <= mx < 0.5 * edge  # a fine vertex is within half an edge of the surface
        # Independent: the error is the distance to the coarse surface.
        coarse = trimesh.Trimesh(v, f, process=False)
        _, dist, _ = trimesh.proximity.closest_point(coarse, sphere_hier.vertices[l])
        assert mean == pytest.approx(dist.mean(), abs=1e-9)


def test_levels_stay_closed_manifolds(sphere_hier):
    for v, f in zip(sphere_hier.vertices, sphere_hier.faces, strict=True):
        assert_manifold(v, f, closed=True)
        assert trimesh.Trimesh(v, f, process=False).euler_number == 2


def test_deterministic(sphere, sphere_hier):
    again = mesh_hierarchy(*sphere, use_cache=False)
    for a, b in zip(sphere_hier.faces, again.faces, strict=True):
        assert np.array_equal(a, b)
    for a, b in zip(sphere_hier.up, again.up, strict=True):
        assert (a != b).nnz == 0


def test_to_torch_sparse_matches_dense(sphere_hier):
    import torch

    u = sphere_hier.up[2]
    t = to_torch_sparse(u)
    x = np.random.default_rng(0).normal(size=(u.shape[1], 5))
    got = torch.sparse.mm(t, torch.from_numpy(x).float()).numpy()
    np.testing.assert_allclose(got, u @ x, rtol=1e-5, atol=1e-5)


# ----------------------------------------------------------------------------------------------
# Open meshes, custom factors, pieces
# ----------------------------------------------------------------------------------------------
def test_open_grid_stays_manifold_and_oriented():
    v, f = grid_patch(12)
    h = mesh_hierarchy(v, f, factors=(2, 2, 2), use_cache=False)
    assert h.num_vertices == [144, 72, 36, 18]
    for vl, fl in zip(h.vertices, h.faces, strict=True):
        assert_manifold(vl, fl, closed=False)
        tri = vl[fl]
        nz = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2]
        assert np.all(nz > 0), "a face flipped"
    for l, u in enumerate(h.up):
        np.testing.assert_allclose(np.asarray(u.sum(1)).ravel(), 1.0, atol=1e-12)
        # In the plane every fine vertex inside the coarse patch is reproduced exactly.
        err = np.linalg.norm(u @ h.vertices[l + 1] - h.vertices[l], axis=1)
        assert np.median(err) < 1e-9


def test_custom_factors():
    m = trimesh.creation.icosphere(subdivisions=2)  # 162 vertices
    h = mesh_hierarchy(m.vertices, m.faces, factors=(3, 4), use_cache=False)
    assert h.num_vertices == [162, 54, 14]


def test_decimate_and_matrices_alone(sphere):
    v, f = sphere
    kept, cf = decimate(v, f, 100)
    assert len(kept) == 100 and cf.max() == 99
    d = selection_matrix(kept, len(v))
    u = barycentric_upsampling(v, v[kept], cf, kept=kept)
    np.testing.assert_array_equal((u @ d).diagonal()[kept], 1.0)


def test_vertex_quadrics_measure_squared_plane_distances(sphere):
    v, f = sphere
    q = vertex_quadrics(v, f)
    x = np.random.default_rng(3).normal(size=3)
    h = np.append(x, 1.0)
    for vid in (0, 17, 400):
        d2 = 0.0
        for tri in v[f[(f == vid).any(1)]]:
            n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
            d2 += (np.dot(x - tri[0], n) / np.linalg.norm(n)) ** 2
        assert h @ q[vid] @ h == pytest.approx(d2, rel=1e-10)
        assert v[vid] @ q[vid][:3, :3] @ v[vid] + 2 * q[vid][3, :3] @ v[vid] + q[vid][3, 3] \
            == pytest.approx(0.0, abs=1e-12)  # a vertex lies on all its planes


# ----------------------------------------------------------------------------------------------
# Cache
# ----------------------------------------------------------------------------------------------
def test_cache_roundtrip(tmp_path, sphere, sphere_hier):
    h1 = mesh_hierarchy(*sphere, cache_dir=tmp_path)
    files = list(tmp_path.glob("hierarchy_*.npz"))
    assert len(files) == 1 and not list(tmp_path.glob("*.tmp"))
    with np.load(files[0], allow_pickle=False) as z:  # plain arrays only
        assert "vertices_0" in z.files and "kept_3" in z.files
    h2 = mesh_hierarchy(*sphere, cache_dir=tmp_path)
    for a, b in zip(h1.up + h1.down, h2.up + h2.down, strict=True):
        assert (a != b).nnz == 0
    for a, b in zip(sphere_hier.faces, h2.faces, strict=True):
        assert np.array_equal(a, b)
    assert h2.factors == (2.0, 2.0, 2.0, 2.0)
    # A different key (factors) is a different file.
    mesh_hierarchy(*sphere, factors=(2, 2), cache_dir=tmp_path)
    assert len(list(tmp_path.glob("hierarchy_*.npz"))) == 2


def test_cache_rebuilds_a_corrupt_file(tmp_path, sphere):
    h1 = mesh_hierarchy(*sphere, factors=(2,), cache_dir=tmp_path)
    (path,) = tmp_path.glob("hierarchy_*.npz")
    path.write_bytes(b"not an npz file")
    with pytest.warns(UserWarning, match=r"not a readable npz .*; rebuilding it"):
        h2 = mesh_hierarchy(*sphere, factors=(2,), cache_dir=tmp_path)
    assert np.array_equal(h1.faces[1], h2.faces[1])
    with np.load(path, allow_pickle=False) as z:
        assert "faces_1" in z.files



def _plant(arrays: dict, key: str, how: str, redigest: bool) -> dict:
    a = {k: v.copy() for k, v in arrays.items()}
    if how == "drop":
        del a[key]
    elif how == "swap_in_row":  # two weights of one 3-entry row swapped: rows still sum to 1
        indptr = a["up_indptr_1"]
        r = int(np.flatnonzero(np.diff(indptr) == 3)[0])
        i = indptr[r]
        d = a["up_data_1"]
        d[i], d[i + 1] = d[i + 1], d[i]
        assert d[i] != d[i + 1]
    else:
        how(a[key])
    if redigest:  # a planted file that also forges the digest: the structural checks catch it
        from handmesh_tutorial.nn.hierarchy.hierarchy import _digest

        a["digest"] = np.asarray(_digest(a))
    return a


def _set(i, value):
    def f(x):
        x[i] = value
    return f


@pytest.mark.parametrize("key, how, redigest, reason", [
    # issue 43 item 3: only level 0 was checked; these crashed scipy (SIGSEGV in `evaluate`),
    # changed the network's output silently, or put a NaN in it
    ("up_indices_1", _set(0, 10**6), True, r"up_indices_1 holds ids in \[.*1000000\]"),
    ("up_indices_2", _set(1, -7), True, r"up_indices_2 holds ids in \[-7"),
    ("up_data_1", lambda d: d.__imul__(0.5), True, r"up level 1: row \d+ sums to 0\.5"),
    ("up_data_2", _set(0, np.nan), True, r"up_data_2 holds weights outside \[0, 1\]"),
    ("up_data_2", lambda d: d.__imul__(0.5), False, r"digest does not match"),
    ("up_data_1", "swap_in_row", False, r"digest does not match"),
    ("up_indptr_1", lambda p: p.__setitem__(slice(-1, None), 10**6), True, r"up_indptr_1 must"),
    ("kept_1", lambda k: k.__setitem__(1, k[0]), True, r"kept_1 must hold distinct ids"),
    ("kept_2", _set(0, 10**6), True, r"kept_2 must hold distinct ids in \[0, \d+\)"),
    ("vertices_3", lambda v: v.__iadd__(1.0), True, r"vertices_3 are not the kept vertices"),
    ("faces_2", _set((0, 0), 10**6), True, r"faces_2: faces reference vertex ids"),
    ("factors", lambda f: f.__imul__(1.5), True, r"built for factors"),
    ("faces_4", "drop", False, r"missing arrays \['faces_4'\]"),
])
def test_cache_checks_every_level_and_rebuilds_a_planted_file_with_a_warning(
        tmp_path, sphere, sphere_hier, key, how, redigest, reason):
    mesh_hierarchy(*sphere, cache_dir=tmp_path)
    (path,) = tmp_path.glob("hierarchy_*.npz")
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    np.savez(path, **_plant(arrays, key, how, redigest))
    with pytest.warns(UserWarning, match=r"mesh-hierarchy cache .*hierarchy_\w+\.npz is not a "
                                         r"valid hierarchy of this mesh \(.*" + reason):
        h = mesh_hierarchy(*sphere, cache_dir=tmp_path)
    for a, b in zip(h.up + h.down, sphere_hier.up + sphere_hier.down, strict=True):
        assert np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)
        assert np.array_equal(a.data, b.data)
    for l in range(h.num_levels):
        assert np.array_equal(h.faces[l], sphere_hier.faces[l])
        assert np.array_equal(h.vertices[l], sphere_hier.vertices[l])
    with np.load(path, allow_pickle=False) as z:  # the file was rebuilt and overwritten
        assert np.array_equal(z["up_data_1"], sphere_hier.up[1].data)
        assert np.array_equal(z["faces_4"], sphere_hier.faces[4])
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the rebuilt file loads without a warning
        mesh_hierarchy(*sphere, cache_dir=tmp_path)


def _no_cache_env(monkeypatch, home):
    monkeypatch.delenv("HANDMESH_CACHE", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setenv("HOME", str(home))


def test_default_cache_dir_follows_handmesh_cache_then_xdg_then_home(tmp_path, monkeypatch,
                                                                     sphere):
    _no_cache_env(monkeypatch, tmp_path / "home")
    (tmp_path / "home").mkdir()
    assert default_cache_dir() == tmp_path / "home" / ".cache" / "handmesh_tutorial"
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_cache_dir() == tmp_path / "xdg" / "handmesh_tutorial"
    monkeypatch.setenv("HANDMESH_CACHE", str(tmp_path / "mine"))
    assert default_cache_dir() == tmp_path / "mine"
    mesh_hierarchy(*sphere, factors=(2,))  # the default cache is the chosen folder
    assert len(list((tmp_path / "mine").glob("hierarchy_*.npz"))) == 1
    assert not (tmp_path / "xdg").exists() and not any((tmp_path / "home").iterdir())
    monkeypatch.setenv("HANDMESH_CACHE", "")  # empty = unset
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/path")  # not absolute: ignored (XDG spec)
    assert default_cache_dir() == tmp_path / "home" / ".cache" / "handmesh_tutorial"


def test_a_missing_home_is_never_created_the_cache_falls_back_to_memory(tmp_path, monkeypatch,
                                                                         sphere):
    _no_cache_env(monkeypatch, tmp_path / "nonexistent" / "x")
    with pytest.raises(RuntimeError, match="does not exist"):
        default_cache_dir()
    with pytest.warns(UserWarning, match="cannot write the mesh-hierarchy cache"):
        h = mesh_hierarchy(*sphere, factors=(2,))
    assert len(h.vertices) == 2 and not (tmp_path / "nonexistent").exists()


def _unwritable_cache(tmp_path, how):
    if how == "under_a_file":  # mkdir fails even for root
        (tmp_path / "a_file").write_text("not a folder")
        return tmp_path / "a_file" / "cache"
    folder = tmp_path / "read_only"
    folder.mkdir()
    folder.chmod(0o500)
    if os.access(folder, os.W_OK):  # root ignores the mode bits
        folder.chmod(0o700)
        pytest.skip("running as root: chmod cannot make a folder unwritable")
    return folder / "cache"


@pytest.mark.parametrize("how", ["under_a_file", "read_only_folder"])
def test_unwritable_cache_falls_back_to_memory_with_a_warning(tmp_path, monkeypatch, sphere,
                                                              sphere_hier, how):
    _no_cache_env(monkeypatch, tmp_path / "home")
    bad = _unwritable_cache(tmp_path, how)
    try:
        monkeypatch.setenv("HANDMESH_CACHE", str(bad))
        with pytest.warns(UserWarning, match="cannot write the mesh-hierarchy cache"):
            h = mesh_hierarchy(*sphere)
        for a, b in zip(sphere_hier.up + sphere_hier.down, h.up + h.down, strict=True):
            assert (a != b).nnz == 0
        assert not bad.exists()
        with pytest.warns(UserWarning, match="cannot write"):  # an explicit folder as well
            mesh_hierarchy(*sphere, factors=(2,), cache_dir=bad)
        # an unwritable home (no HANDMESH_CACHE, no XDG_CACHE_HOME): the shipped network loads
        monkeypatch.delenv("HANDMESH_CACHE")
        monkeypatch.setenv("HOME", str(bad))
        with pytest.warns(UserWarning, match="cannot write"):
            net = hmt.pretrained.pretrained()
        assert net.template.shape[0] == hmt.hand.HandModel("right").num_vertices
    finally:
        if how == "read_only_folder":
            bad.parent.chmod(0o700)


def test_no_cache_writes_nothing(tmp_path, sphere):
    mesh_hierarchy(*sphere, factors=(2,), cache_dir=tmp_path, use_cache=False)
    assert not any(tmp_path.iterdir())


# ----------------------------------------------------------------------------------------------
# Errors
# ----------------------------------------------------------------------------------------------
def test_bad_inputs(sphere):
    v, f = sphere
    with pytest.raises(ValueError, match=r"vertices must have shape \(V, 3\)"):
        mesh_hierarchy(v[:, :2], f, use_cache=False)
    with pytest.raises(ValueError, match=r"faces must have shape \(F, 3\)"):
        mesh_hierarchy(v, f[:, :2], use_cache=False)
    with pytest.raises(ValueError, match="faces reference vertex ids"):
        mesh_hierarchy(v[:10], f, use_cache=False)
    with pytest.raises(ValueError, match="factor"):
        mesh_hierarchy(v, f, factors=(2, 1), use_cache=False)
    with pytest.raises(ValueError, match="not used by any face"):
        mesh_hierarchy(np.vstack([v, [[9.0, 9.0, 9.0]]]), f, use_cache=False)
    with pytest.raises(ValueError, match="integer"):
        mesh_hierarchy(v, f.astype(float), use_cache=False)
    with pytest.raises(ValueError, match="num_vertices"):
        decimate(v, f, 0)


def test_tetrahedron_cannot_shrink():
    m = trimesh.creation.icosahedron()
    with pytest.raises(RuntimeError, match="decimation stuck"):
        mesh_hierarchy(m.vertices, m.faces, factors=(2, 2, 2), use_cache=False)  # 12 -> 6 -> 3


# ----------------------------------------------------------------------------------------------
# The library's hand template
# ----------------------------------------------------------------------------------------------
@pytest.mark.skipif(not HAVE_HAND, reason="handmesh_tutorial.hand (HandModel) not present yet")
def test_hand_template_hierarchy(tmp_path):
    hand = hmt.hand.HandModel("right")
    v = np.asarray(hand.template_vertices, dtype=np.float64)
    f = np.asarray(hand.faces)
    h = mesh_hierarchy(v, f, cache_dir=tmp_path)
    n = [len(v)]
    for _ in range(4):
        n.append(math.ceil(n[-1] / 2))
    assert h.num_vertices == n
    if len(v) == 778:
        assert h.num_vertices == [778, 389, 195, 98, 49]
    closed = trimesh.Trimesh(v, f, process=False).is_watertight
    for l in range(5):
        assert_manifold(h.vertices[l], h.faces[l], closed=closed)
    for l in range(4):
        assert np.array_equal(h.down[l] @ h.vertices[l], h.vertices[l + 1])
        np.testing.assert_allclose(np.asarray(h.up[l].sum(1)).ravel(), 1.0, atol=1e-12)
    for mean, mx in h.reconstruction_errors():
        assert mean < 0.004 and mx < 0.02  # metres: 4 mm mean, 2 cm max at the coarsest step


HAND_HIERARCHY = Path(__file__).parent / "fixtures" / "hand_hierarchy_fingerprint.json"


def _hand_hierarchy_arrays() -> dict:
    """The right hand's hierarchy as a network builds it (template, default factors) and its
    spirals: what the shipped weights were trained on, level by level."""
    from handmesh_tutorial.nn.spiral import spiral_indices

    hand = hmt.hand.HandModel("right")
    h = mesh_hierarchy(np.asarray(hand.template_vertices, np.float64), np.asarray(hand.faces),
                       use_cache=False)
    arrays = {}
    for l, faces in enumerate(h.faces):
        arrays[f"faces/{l}"] = np.asarray(faces, np.int64)
        arrays[f"spiral/{l}"] = np.asarray(spiral_indices(faces, 9), np.int64)
    for l, (down, up) in enumerate(zip(h.down, h.up, strict=True)):
        arrays[f"down/{l}"] = np.asarray(down.indices, np.int64)
        arrays[f"up_columns/{l}"] = np.asarray(up.indices, np.int64)
        arrays[f"up_rows/{l}"] = np.asarray(up.indptr, np.int64)
        arrays[f"up_weights/{l}"] = np.asarray(up.data, np.float64)
    return arrays


@pytest.mark.recorded
def test_the_hand_hierarchy_is_the_recorded_one_on_every_cpu():
    """The shipped network's mesh levels are rebuilt on each machine, not stored: the decimation's
    choices (faces, kept vertices, closest triangles, spirals) must be the recorded ones exactly
    on any CPU, the barycentric weights to float rounding (8e-7 apart across kernel paths;
    1e-5 of their norm allowed)."""
    from fingerprints import differences, fingerprint

    recorded = json.loads(HAND_HIERARCHY.read_text())
    problems = differences(fingerprint(_hand_hierarchy_arrays()), recorded, 1e-5)
    assert not problems, "; ".join(problems[:5])
