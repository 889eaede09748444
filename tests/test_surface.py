"""Tests of handmesh_tutorial.metrics.surface: roughness and flipped faces against a naive per-edge
loop,
and their invariances."""

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

from handmesh_tutorial.metrics import surface
from handmesh_tutorial.nn import smoothing


def _naive_roughness(pred, gt, faces):
    """Per-edge loop: signed dihedral angle of every edge with exactly two faces, in degrees."""
    edges = {}
    for fi, f in enumerate(faces):
        for k in range(3):
            a, b = int(f[k]), int(f[(k + 1) % 3])
            edges.setdefault((min(a, b), max(a, b)), []).append((fi, a, b))

    def normal(v, f):
        n = np.cross(v[f[1]] - v[f[0]], v[f[2]] - v[f[0]])
        return n / np.linalg.norm(n)

    def angle(v, f1, f2, a, b):
        n1, n2 = normal(v, faces[f1]), normal(v, faces[f2])
        d = (v[b] - v[a]) / np.linalg.norm(v[b] - v[a])
        return np.arctan2(np.dot(np.cross(n1, n2), d), np.dot(n1, n2))

    diffs = []
    for users in edges.values():
        if len(users) != 2:
            continue
        (f1, a, b), (f2, _, _) = users
        d = abs(angle(pred, f1, f2, a, b) - angle(gt, f1, f2, a, b))
        diffs.append(min(d, 2 * np.pi - d))
    return np.degrees(np.mean(diffs))


def _naive_flipped(pred, gt, faces):
    """Similarity alignment without reflection (Umeyama), then a loop over faces."""
    p, g = pred - pred.mean(0), gt - gt.mean(0)
    u, s, vt = np.linalg.svd(g.T @ p)
    d = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag([1, 1, d]) @ vt
    scale = (s[0] + s[1] + d * s[2]) / (p ** 2).sum()
    aligned = scale * p @ rot.T + gt.mean(0)
    flipped = 0
    for f in faces:
        n_p = np.cross(aligned[f[1]] - aligned[f[0]], aligned[f[2]] - aligned[f[0]])
        n_g = np.cross(gt[f[1]] - gt[f[0]], gt[f[2]] - gt[f[0]])
        flipped += np.dot(n_p, n_g) < 0
    return flipped / len(faces)


@pytest.fixture(scope="module")
def meshes():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    box = trimesh.creation.box(extents=(1.0, 2.0, 0.5))
    grid_v = np.stack(np.meshgrid(np.arange(5.0), np.arange(4.0), indexing="ij"), -1)
    grid_v = np.concatenate([grid_v.reshape(-1, 2), np.zeros((20, 1))], axis=1)
    quads = [(i * 4 + j, (i + 1) * 4 + j, i * 4 + j + 1) for i in range(4) for j in range(3)]
    quads += [((i + 1) * 4 + j, (i + 1) * 4 + j + 1, i * 4 + j + 1) for i in range(4)
              for j in range(3)]
    return {"sphere": (np.asarray(sphere.vertices), np.asarray(sphere.faces)),
            "box": (np.asarray(box.vertices), np.asarray(box.faces)),
            "grid": (grid_v, np.array(quads))}


@pytest.mark.parametrize("name", ["sphere", "box", "grid"])
def test_metrics_match_a_naive_loop(meshes, name):
    v, f = meshes[name]
    rng = np.random.default_rng(1)
    edge = np.linalg.norm(v[f[:, 1]] - v[f[:, 0]], axis=1).mean()
    gt = np.stack([v + 0.05 * edge * rng.normal(size=v.shape) for _ in range(3)])
    pred = gt + 0.4 * edge * rng.normal(size=gt.shape)
    rough = surface.roughness_deg(pred, gt, f)
    flip = surface.flipped_face_fraction(pred, gt, f)
    assert rough.shape == flip.shape == (3,)
    for i in range(3):
        np.testing.assert_allclose(rough[i], _naive_roughness(pred[i], gt[i], f), rtol=1e-10)
        np.testing.assert_allclose(flip[i], _naive_flipped(pred[i], gt[i], f), atol=1e-12)
    assert rough.min() > 1.0 and flip.max() > 0.0  # the noise is large enough to register


def test_grid_boundary_edges_are_left_out(meshes):
    _, f = meshes["grid"]
    edges, pairs, _ = surface.interior_edges(f)
    # 5 x 4 vertices, 12 quads: 12 diagonals + 2 inner rows of 4 edges + 3 inner columns of 3
    assert len(edges) == 12 + 2 * 4 + 3 * 3
    assert np.all(pairs[:, 0] != pairs[:, 1])
    # three faces on one edge (non-manifold): that edge is not interior
    f3 = np.vstack([f, [[4, 1, 19]]])  # a third face on the diagonal (1, 4)
    e3 = {tuple(sorted(e)) for e in surface.interior_edges(f3)[0]}
    assert (1, 4) not in e3 and len(e3) == len(edges) - 1


def test_identity_rigid_motion_and_scale_give_zero(meshes):
    v, f = meshes["sphere"]
    rng = np.random.default_rng(0)
    gt = v[None] + 0.05 * rng.normal(size=(4, *v.shape))
    rot = Rotation.random(4, random_state=rng).as_matrix()
    moved = 2.5 * np.einsum("bij,bvj->bvi", rot, gt) + rng.normal(size=(4, 1, 3))
    for pred in (gt, moved):
        np.testing.assert_allclose(surface.roughness_deg(pred, gt, f), 0.0, atol=1e-9)
        np.testing.assert_array_equal(surface.flipped_face_fraction(pred, gt, f), 0.0)
    # roughness needs no alignment; the flipped count without alignment sees the rotation
    assert surface.flipped_face_fraction(moved, gt, f, align=False).max() > 0.3


def test_torch_and_single_mesh_inputs(meshes):
    v, f = meshes["box"]
    gt = v + 0.01
    pred = v + np.random.default_rng(0).normal(scale=0.1, size=v.shape)
    ref = surface.roughness_deg(pred[None], gt[None], f)
    got = surface.roughness_deg(torch.tensor(pred, dtype=torch.float64, requires_grad=True),
                                torch.from_numpy(gt), torch.from_numpy(f))
    np.testing.assert_allclose(got, ref)
    assert got.shape == (1,)
    with pytest.raises(ValueError, match="differ"):
        surface.roughness_deg(pred[None], np.stack([gt, gt]), f)
    with pytest.raises(ValueError, match="face ids"):
        surface.flipped_face_fraction(pred, gt, f + 100)


def test_mirrored_copy(meshes):
    from handmesh_tutorial.hand import HandModel

    hand = HandModel("right")
    gt = hand(pose=None).vertices[0].double().numpy()
    mirrored = gt * np.array([-1.0, 1.0, 1.0])
    # a mirror flips the sign of every bending angle: difference 2|a|, wrapped to [0, pi]
    two_a = 2 * np.abs(surface.dihedral_angles(gt, hand.faces))
    np.testing.assert_allclose(surface.roughness_deg(mirrored, gt, hand.faces),
                               np.degrees(np.minimum(two_a, 2 * np.pi - two_a).mean()),
                               rtol=1e-9)
    # a proper rotation cannot undo the mirror of a chiral hand: most faces point the wrong way
    assert surface.flipped_face_fraction(mirrored, gt, hand.faces)[0] > 0.3
    # with reflections allowed the alignment undoes it exactly
    np.testing.assert_allclose(
        surface.flipped_face_fraction(mirrored, gt, hand.faces, allow_reflection=True), 0.0)
    # a flat sheet mirrored in its plane: every face turns over (without alignment)
    grid, faces = meshes["grid"]
    np.testing.assert_array_equal(
        surface.flipped_face_fraction(grid * [-1, 1, 1], grid, faces, align=False), 1.0)


def test_smoothing_matrix_and_steps(meshes):
    v, f = meshes["sphere"]
    s1 = smoothing.smoothing_matrix(f, 1)
    # one step: half the value stays, half is the mean of the 1-ring (loop over vertices)
    dense = s1.toarray()
    for i in range(len(v)):
        ring = {int(x) for face in f if i in face for x in face} - {i}
        want = np.zeros(len(v))
        want[i] = 0.5
        want[list(ring)] += 0.5 / len(ring)
        np.testing.assert_allclose(dense[i], want)
    s3 = smoothing.smoothing_matrix(f, 3)
    np.testing.assert_allclose(s3.toarray(), np.linalg.matrix_power(dense, 3), atol=1e-12)
    np.testing.assert_allclose(np.asarray(s3.sum(1)).ravel(), 1.0)
    assert (smoothing.smoothing_matrix(f, 0) != smoothing.smoothing_matrix(f, 0).T).nnz == 0
    np.testing.assert_array_equal(smoothing.smoothing_matrix(f, 0).toarray(), np.eye(len(v)))
    # an isolated vertex keeps its value
    iso = smoothing.smoothing_matrix(f, 2, num_vertices=len(v) + 1).toarray()
    assert iso[-1, -1] == 1.0 and iso[-1].sum() == 1.0
    e = smoothing.mean_edge_length(v, f)
    assert smoothing.smoothing_steps(v, f, 0.0) == 0
    assert smoothing.smoothing_steps(v, f, e) == 2
    assert smoothing.smoothing_steps(v, f, 2 * e) == 8
    assert smoothing.smoothing_steps(2 * v, f, 2 * e) == 2  # a length, not a step count
    with pytest.raises(ValueError, match="steps"):
        smoothing.smoothing_matrix(f, -1)
