"""Tests for handmesh_tutorial.lcs: local coordinate systems, angle conventions and limits."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from handmesh_tutorial import lcs as L

torch.set_num_threads(1)
MIRROR = np.diag([-1.0, 1.0, 1.0])  # any reflection works for the generic test
FLIP_Y = np.diag([1.0, -1.0, 1.0])


def rodrigues(axis, angle):
    """Independent rotation matrix about a unit axis (explicit formula)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


def toy_chain():
    """A bent 3-link chain with an end point; flexion points on the +x side of each link."""
    joints = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.5, 1.8]])
    end = np.array([0.0, 1.2, 2.2])
    children = np.array([joints[1], joints[2], end])
    flex = joints + np.array([[0.3, 0.1, 0.2], [0.4, -0.2, 0.1], [0.2, 0.05, -0.1]])
    return joints, children, flex


def assert_rotations(frames, atol=1e-9):
    eye = np.broadcast_to(np.eye(3), frames.shape)
    np.testing.assert_allclose(np.swapaxes(frames, -1, -2) @ frames, eye, atol=atol)
    np.testing.assert_allclose(np.linalg.det(frames), 1.0, atol=atol)


# ------------------------------------------------------------------------------ generic API
def test_local_frames_analytic_case():
    frames = L.local_frames([[1.0, 2.0, 3.0]], [[1.0, 2.0, 5.0]], [[4.0, 2.0, 8.0]])
    np.testing.assert_allclose(frames[0], np.eye(3), atol=1e-12)  # x=(1,0,0), y=(0,1,0), z


def test_local_frames_toy_chain_against_gram_schmidt():
    joints, children, flex = toy_chain()
    frames = L.local_frames(joints, children, flex)
    assert frames.shape == (3, 3, 3)
    assert_rotations(frames)
    for i in range(3):
        z = (children[i] - joints[i]) / np.linalg.norm(children[i] - joints[i])
        # independent: x = z × ((v - j) × z), normalised (the triple product form of projection)
        xv = np.cross(z, np.cross(flex[i] - joints[i], z))
        x = xv / np.linalg.norm(xv)
        np.testing.assert_allclose(frames[i][:, 2], z, atol=1e-12)
        np.testing.assert_allclose(frames[i][:, 0], x, atol=1e-12)
        np.testing.assert_allclose(frames[i][:, 1], np.cross(z, x), atol=1e-12)
        assert (flex[i] - joints[i]) @ frames[i][:, 0] > 0  # x on the flexion point's side
    # children given as indices into joints is the same as positions
    idx = L.local_frames(joints[:2], np.array([1, 0]), flex[:2])
    np.testing.assert_allclose(idx[0], frames[0], atol=1e-12)


def test_local_frames_errors():
    with pytest.raises(ValueError, match="zero length"):
        L.local_frames([[0, 0, 0]], [[0, 0, 0]], [[1, 0, 0]])
    with pytest.raises(ValueError, match="projected off z"):
        L.local_frames([[0, 0, 0]], [[0, 0, 1]], [[0, 0, 3]])
    with pytest.raises(ValueError, match=r"flexion_points must have shape \(1, 3\)"):
        L.local_frames([[0, 0, 0]], [[0, 0, 1]], [[1, 0, 0], [1, 0, 0]])


def test_select_flexion_vertices_rule():
    joints, child, target = [[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]]
    verts = np.array([[0.5, 0.1, 0.0],     # near the cross-section, close to the target
                      [1.0, 0.0, 0.5],     # exactly the target direction but far along z
                      [-1.0, 0.0, 0.0],    # opposite side
                      [0.3, 0.3, 0.1]])
    assert L.select_flexion_vertices(verts, joints, child, target).tolist() == [0]
    assert L.select_flexion_vertices(verts, joints, child, target, slab=0.6).tolist() == [1]
    # skinning restriction: only vertices owned by the joint (1) or its parent (0) qualify
    weights = np.eye(3)[[2, 2, 1, 1]]
    got = L.select_flexion_vertices(verts, joints, child, target, weights=weights,
                                    joint_ids=[1], parents=np.array([-1, 0, 1]), slab=0.6)
    assert got.tolist() == [3]
    with pytest.raises(ValueError, match="joint_ids and parents"):
        L.select_flexion_vertices(verts, joints, child, target, weights=weights)


def test_angle_axes_and_signs():
    joints, children, flex = toy_chain()
    frames = L.local_frames(joints, children, flex)
    x, y, z = frames[1].T
    theta = 0.4
    for axis, a_idx, moved, want in [
        ("y flexes z towards x", 1, z, np.cos(theta) * z + np.sin(theta) * x),
        ("x swings z towards -y", 0, z, np.cos(theta) * z - np.sin(theta) * y),
        ("z spins x towards y", 2, x, np.cos(theta) * x + np.sin(theta) * y),
    ]:
        angles = np.zeros((3, 3))
        angles[1, a_idx] = theta
        rot = L.rotation_from_lcs_angles(frames, angles)[1]
        np.testing.assert_allclose(rot @ moved, want, atol=1e-12, err_msg=axis)
        np.testing.assert_allclose(rot, rodrigues(frames[1][:, a_idx], theta), atol=1e-12)


def test_composition_order_is_y_then_x_then_z():
    frames = np.eye(3)[None]
    a = np.array([[0.3, -0.7, 0.2]])
    want = rodrigues([0, 1, 0], -0.7) @ rodrigues([1, 0, 0], 0.3) @ rodrigues([0, 0, 1], 0.2)
    np.testing.assert_allclose(L.rotation_from_lcs_angles(frames, a)[0], want, atol=1e-12)


def test_pose_round_trip_and_matrix_agreement():
    rng = np.random.default_rng(0)
    joints, children, flex = toy_chain()
    frames = L.local_frames(joints, children, flex)
    angles = rng.uniform(-1.4, 1.4, size=(20, 3, 3))
    angles[:, :, 1] = rng.uniform(-2.0, 2.0, size=(20, 3))  # flexion beyond 90 degrees
    pose = L.lcs_angles_to_pose(frames, angles)
    np.testing.assert_allclose(Rotation.from_rotvec(pose.reshape(-1, 3)).as_matrix(),
                               L.rotation_from_lcs_angles(frames, angles).reshape(-1, 3, 3),
                               atol=1e-12)
    np.testing.assert_allclose(L.pose_to_lcs_angles(frames, pose), angles, atol=1e-9)


def test_forward_kinematics_toy_chain():
    joints, children, flex = toy_chain()
    # chain with the end point as a 4th (unarticulated) joint
    rest = np.vstack([joints, children[2]])
    parents = np.array([-1, 0, 1, 2])
    frames = L.local_frames(joints, children, flex)
    angles = np.zeros((3, 3))
    angles[1, 1] = 0.5                   # flex the middle joint
    angles[2, 0] = -0.3                  # abduct the last one
    local = np.tile(np.eye(3), (4, 1, 1))
    local[:3] = L.rotation_from_lcs_angles(frames, angles)
    got = L.forward_kinematics(rest, parents, local)
    # independent: rotate about world axes through the joints, distal joint first
    r2 = rodrigues(frames[2][:, 0], -0.3)
    r1 = rodrigues(frames[1][:, 1], 0.5)
    end = joints[2] + r2 @ (rest[3] - joints[2])
    end = joints[1] + r1 @ (end - joints[1])
    j2 = joints[1] + r1 @ (joints[2] - joints[1])
    np.testing.assert_allclose(got[2], j2, atol=1e-12)
    np.testing.assert_allclose(got[3], end, atol=1e-12)
    np.testing.assert_allclose(got[:2], rest[:2], atol=1e-12)
    # flexing joint 1 keeps joint 2 in the plane through joint 1 perpendicular to y_1
    assert abs((got[2] - joints[1]) @ frames[1][:, 1]) < 1e-12
    assert (got[2] - joints[2]) @ frames[1][:, 0] > 0


def test_mirrored_chain_gives_mirrored_frames_and_poses():
    joints, children, flex = toy_chain()
    right = L.local_frames(joints, children, flex)
    left = L.local_frames(joints @ MIRROR, children @ MIRROR, flex @ MIRROR)
    assert_rotations(left)
    np.testing.assert_allclose(left, MIRROR @ right @ FLIP_Y, atol=1e-12)
    a = np.random.default_rng(1).uniform(-0.8, 0.8, size=(3, 3))
    rot_r = L.rotation_from_lcs_angles(right, a)
    rot_l = L.rotation_from_lcs_angles(left, L.mirror_angles(a))
    np.testing.assert_allclose(rot_l, MIRROR @ rot_r @ MIRROR, atol=1e-12)


def test_clip_and_within_limits():
    lower = np.deg2rad([[-10, 0, -5]] * 2)
    upper = np.deg2rad([[10, 90, 5]] * 2)
    a = np.deg2rad([[[20, -30, 0], [0, 45, 4]], [[-1, 1, 1], [0, 0, 0]]])
    assert L.within_limits(a, lower, upper).tolist() == [False, True]
    clipped = L.clip_angles(a, lower, upper)
    assert L.within_limits(clipped, lower, upper).all()
    np.testing.assert_allclose(np.rad2deg(clipped[0, 0]), [10, 0, 0])
    # fresh probe of issue 43: swapped limits clipped everything to `upper`, a negative or NaN
    # tolerance narrowed or emptied the test silently (Articulation.with_limits refuses them)
    for lo, hi in ((upper, lower), (lower * np.nan, upper)):
        with pytest.raises(ValueError, match="limits must be lower <= upper"):
            L.clip_angles(a, lo, hi)
        with pytest.raises(ValueError, match="limits must be lower <= upper"):
            L.within_limits(a, lo, hi)
    for atol in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match=f"atol must be a finite number of radians >= 0, "
                                             f"got {atol}"):
            L.within_limits(a, lower, upper, atol)
    assert not L.within_limits(a * np.nan, lower, upper).any()


def make_articulation(limits=None):
    joints, children, flex = toy_chain()
    frames = L.local_frames(joints, children, flex)
    lower, upper = limits if limits is not None else (np.full((3, 3), -0.5), np.full((3, 3), 0.5))
    return L.Articulation(names=("a", "b", "c"), joints=joints, frames=frames, lower=lower,
                          upper=upper, child_points=children, flexion_points=flex)


def test_random_angles_respect_limits_and_seed():
    lower = np.deg2rad([[-15, -20, -5], [0, 0, 0], [0, 10, 0]])
    upper = np.deg2rad([[15, 90, 5], [0, 110, 0], [0, 80, 0]])
    art = make_articulation((lower, upper))
    a = art.random_angles(np.random.default_rng(3), n=500)
    assert a.shape == (500, 3, 3) and art.within_limits(a).all()
    assert np.all(a[:, 1, [0, 2]] == 0)                      # zero-width ranges stay 0
    assert a[:, 0, 1].min() < 0 < a[:, 0, 1].max()           # uses both sides of the range
    b = art.random_angles(3, n=500)
    assert a.tobytes() == b.tobytes()
    half = art.random_angles(4, n=500, scale=0.5)
    assert art.within_limits(half).all()
    assert np.abs(half[:, 0, 1]).max() <= np.deg2rad(45) + 1e-12
    # a range not containing 0 shrinks towards its nearest end, never outside
    assert np.all(art.random_angles(5, n=50, scale=0.0)[:, 2, 1] == lower[2, 1])
    pose = art.random_pose(6, n=10)
    assert pose.dtype == np.float32 and art.within_limits(art.from_pose(pose), atol=1e-5).all()
    with pytest.raises(ValueError, match="scale"):
        art.random_angles(0, scale=1.5)


def test_paper_and_named_limits():
    lower, upper = L.hand_joint_limits("paper")
    np.testing.assert_allclose(np.rad2deg(upper), 60.0)
    np.testing.assert_allclose(np.rad2deg(lower), -60.0)
    lo, hi = L.hand_joint_limits("anatomical")
    assert lo.shape == hi.shape == (15, 3) and np.all(lo <= 0) and np.all(hi >= 0)
    np.testing.assert_allclose(np.rad2deg(hi[1]), [10, 110, 10])  # index PIP: a hinge, +-10 play
    np.testing.assert_allclose(np.rad2deg(lo[:, [0, 2]]), -np.rad2deg(hi[:, [0, 2]]))
    paper = make_articulation().with_limits("paper")
    assert paper.limits_name == "paper"
    np.testing.assert_allclose(np.rad2deg(paper.upper), 60.0)
    with pytest.raises(ValueError, match="15 hand joints"):
        make_articulation().with_limits("anatomical")
    with pytest.raises(ValueError, match="'paper' or 'anatomical'"):
        L.hand_joint_limits("loose")


# --------------------------------------------------------------------------------- hand
@pytest.fixture(scope="module")
def hand():
    return pytest.importorskip("handmesh_tutorial.hand")


@pytest.fixture(scope="module")
def right(hand):
    model = hand.HandModel("right")
    return model, L.hand_lcs(model)


@pytest.fixture(scope="module")
def left(hand):
    model = hand.HandModel("left")
    return model, L.hand_lcs(model)


def np_(x):
    return x.detach().cpu().numpy().astype(np.float64)


def test_hand_frames(right):
    model, art = right
    assert art.frames.shape == (15, 3, 3) and art.num_joints == 15
    assert_rotations(art.frames, atol=1e-9)
    z = art.frames[:, :, 2]
    to_child = art.child_points - art.joints
    np.testing.assert_allclose(z, to_child / np.linalg.norm(to_child, axis=1, keepdims=True),
                               atol=1e-9)
    verts = np.asarray(model.template_vertices, dtype=np.float64)
    v = verts[art.flexion_vertex_ids]
    assert np.all(np.einsum("ja,ja->j", v - art.joints, art.frames[:, :, 0]) > 0)
    # fingers: x is close to the palm normal (the vertex is on the palmar side)
    out = model()
    n = L.palm_normal(np_(out.joints[0]), "right")
    cos = art.frames[:12, :, 0] @ n
    assert cos.min() > 0.7, cos
    assert len(set(art.flexion_vertex_ids.tolist())) == 15


def test_positive_flexion_curls_towards_palm(right):
    model, art = right
    out0 = model()
    n = L.palm_normal(np_(out0.joints[0]), "right")
    j_rest = np_(out0.joints_mano[0])
    for k in (1, 4, 7, 10):                     # finger MCPs: child = PIP (next MANO joint)
        angles = np.zeros((15, 3))
        angles[k - 1, 1] = np.deg2rad(40)
        pose = torch.as_tensor(art.to_pose(angles))[None]
        posed = np_(model(pose=pose).joints_mano[0])
        x, y, _ = art.frames[k - 1].T
        moved = posed[k + 1] - j_rest[k]
        predicted = art.rotations(angles)[k - 1] @ (j_rest[k + 1] - j_rest[k])
        np.testing.assert_allclose(moved, predicted, atol=1e-5)
        assert abs(moved @ y) < 1e-5                # stays in the plane ⟂ flexion axis
        assert (posed[k + 1] - j_rest[k + 1]) @ n > 0    # towards the palm
        assert (posed[k + 1] - j_rest[k + 1]) @ x > 0
        np.testing.assert_allclose(posed[: k + 1], j_rest[: k + 1], atol=1e-6)


def test_distal_flexion_moves_fingertip_in_plane(right):
    model, art = right
    zero = np.zeros((15, 3))
    out0 = model(pose=torch.as_tensor(art.to_pose(zero))[None])   # the hand at zero angles
    tips0, joints0 = np_(out0.joints[0]), np_(out0.joints_mano[0])
    local0 = art.rotations(zero)
    parents = np.asarray(model.parents)
    # DIP of index, middle, pinky, ring and the thumb's IP (MANO order) -> FreiHAND tip keypoint
    for k, tip_id in ((3, 8), (6, 12), (9, 20), (12, 16), (15, 4)):
        G = np.eye(3)            # the parent's world rotation at zero angles (the thumb's CMC's
        p = parents[k]           # zero rotation carries its IP's frame along)
        while p > 0:
            G = local0[p - 1] @ G
            p = parents[p]
        angles = zero.copy()
        angles[k - 1, 1] = np.deg2rad(50)
        out = model(pose=torch.as_tensor(art.to_pose(angles))[None])
        tip = np_(out.joints[0])[tip_id]
        x, y, _ = (G @ art.frames[k - 1]).T
        rest_rel = tips0[tip_id] - joints0[k]
        rel = tip - joints0[k]
        assert abs(rel @ y) < 1e-5                   # in the plane ⟂ the flexion axis
        np.testing.assert_allclose(rel, G @ art.rotations(angles)[k - 1] @ G.T @ rest_rel,
                                   atol=1e-4)
        moved = (tip - tips0[tip_id]) @ x             # towards the flexion side by ~L sin 50°
        assert moved > 0.9 * np.sin(np.deg2rad(50)) * np.linalg.norm(rest_rel)


def test_random_pose_valid_for_hand(right):
    model, art = right
    for limits in ("paper", "anatomical"):
        poses = L.random_pose(art, np.random.default_rng(0), n=16, limits=limits)
        lim = art.with_limits(limits)
        assert poses.shape == (16, 15, 3) and poses.dtype == np.float32
        assert lim.within_limits(lim.from_pose(poses), atol=1e-5).all()
        out = model(pose=torch.as_tensor(poses))
        assert torch.isfinite(out.vertices).all()
    a = L.random_pose(model, 7, n=2)
    b = L.random_pose(model, 7, n=2)
    assert a.tobytes() == b.tobytes()


def test_within_limits_default_tolerance_accepts_float32_round_trips(right, left):
    """A float32 pose read back as angles is off by ~1e-7 rad; the default tolerance (1e-5 rad)
    accepts it for every random pose, while a pose 0.01 rad or even 1e-4 rad outside a limit
    stays out, and ``atol=0`` keeps the exact test."""
    for _, art in (right, left):
        assert art.within_limits(art.from_pose(art.random_pose(0)))
        for limits in ("paper", "anatomical"):
            lim = art.with_limits(limits)
            back = lim.from_pose(lim.random_pose(1, n=500))
            assert lim.within_limits(back).all(), limits
            worst = np.maximum(lim.lower - back, back - lim.upper).max()
            assert worst < 1e-6, worst  # the round trip's own error, far below the tolerance
            angles = lim.random_angles(2, n=4)
            for outside in (1e-2, 1e-4):
                over = angles.copy()
                over[:, 3, 1] = lim.upper[3, 1] + outside        # flexion past its limit
                under = angles.copy()
                under[:, 0, 0] = lim.lower[0, 0] - outside
                for bad in (over, under):
                    assert not lim.within_limits(lim.from_pose(lim.to_pose(bad))).any()
                    assert not L.within_limits(bad, lim.lower, lim.upper).any()
            assert L.within_limits(angles, lim.lower, lim.upper).all()
    art = right[1]
    at_limits = np.where(np.random.default_rng(3).random((50, 15, 3)) < 0.5, art.lower, art.upper)
    exact = art.from_pose(art.to_pose(at_limits))
    assert not art.within_limits(exact, atol=0.0).all()  # the float32 error is there
    assert art.within_limits(exact).all()


def test_left_frames_mirror_right(hand, right, left):
    (rmodel, rart), (lmodel, lart) = right, left
    mirror = np.diag(hand.mirror_points(np.ones(3)))   # the library's left = right mirrored
    rv = np.asarray(rmodel.template_vertices, dtype=np.float64)
    lv = np.asarray(lmodel.template_vertices, dtype=np.float64)
    np.testing.assert_allclose(lv, rv @ mirror, atol=1e-6)
    np.testing.assert_allclose(lart.frames, mirror @ rart.frames @ FLIP_Y, atol=1e-5)
    assert lart.flexion_vertex_ids.tolist() == rart.flexion_vertex_ids.tolist()
    # equal flexion, mirrored abduction/twist -> mirrored pose (hand.mirror_axis_angle)
    a = rart.random_angles(0, n=3)
    pr = rart.to_pose(a)
    pl = lart.to_pose(L.mirror_angles(a))
    np.testing.assert_allclose(pl, hand.mirror_axis_angle(pr), atol=1e-5)
    out_r = rmodel(pose=torch.as_tensor(pr))
    out_l = lmodel(pose=torch.as_tensor(pl))
    np.testing.assert_allclose(np_(out_l.vertices), np_(out_r.vertices) @ mirror, atol=1e-5)


# ------------------------------------------------------------------------------ synergy prior
def _finger_flexion_deg(angles):
    """(n, 4, 3) flexion (y) of MCP, PIP, DIP per finger (index, middle, ring, little), degrees."""
    idx = np.array(L.FINGER_JOINTS) - 1
    return np.rad2deg(np.asarray(angles)[..., idx, 1])


def test_natural_hand_angles_limits_seed_and_dip_coupling():
    lower, upper = L.hand_joint_limits("anatomical")
    a = np.stack([L.natural_hand_angles(s) for s in range(200)])
    assert a.shape == (200, 15, 3)
    assert (a >= lower - 1e-12).all() and (a <= upper + 1e-12).all()
    assert L.natural_hand_angles(7).tobytes() == L.natural_hand_angles(7).tobytes()
    assert L.natural_hand_angles(7).tobytes() != L.natural_hand_angles(8).tobytes()
    for dip, pip in L.DIP_FOLLOWS_PIP.items():
        np.testing.assert_allclose(a[:, dip - 1, 1], L.DIP_PIP_RATIO * a[:, pip - 1, 1])


def test_natural_hand_angles_move_in_synergies_unlike_uniform_angles(right):
    _, art = right
    nat = _finger_flexion_deg([L.natural_hand_angles(s) for s in range(400)])
    uni = _finger_flexion_deg(art.with_limits("anatomical").random_angles(0, n=400))
    def corr(x, y):
        return float(np.corrcoef(x, y)[0, 1])
    # MCP and PIP of a finger flex together; neighbouring fingers alike
    assert min(corr(nat[:, f, 0], nat[:, f, 1]) for f in range(4)) > 0.8
    assert min(corr(nat[:, f, 1], nat[:, f + 1, 1]) for f in range(1, 3)) > 0.7
    assert max(abs(corr(uni[:, f, 0], uni[:, f, 1])) for f in range(4)) < 0.2
    # a "claw" (straight knuckle, bent middle joint) is rare; uniform angles make it often
    def claws(x):
        return float(((x[..., 1] > 60) & (x[..., 0] < 10)).mean())
    assert claws(nat) < 0.02 < 0.10 < claws(uni)


def test_natural_hand_angles_closure_opens_and_closes_the_hand():
    open_ = _finger_flexion_deg([L.natural_hand_angles(s, closure=0.0, point_prob=0.0)
                                 for s in range(100)])
    fist = _finger_flexion_deg([L.natural_hand_angles(s, closure=1.0, point_prob=0.0)
                                for s in range(100)])
    assert np.median(open_[..., 1]) < 15 and np.median(fist[..., 1]) > 80
    assert np.median(fist[..., 0]) > 60 > 10 > np.median(open_[..., 0])
    # the relaxed cascade: the little finger is more flexed than the index on average
    mid = _finger_flexion_deg([L.natural_hand_angles(s, closure=0.5, point_prob=0.0)
                               for s in range(300)])
    assert mid[:, 3, 1].mean() > mid[:, 0, 1].mean() + 5


def test_natural_hand_angles_left_hand_is_the_mirror_image(hand, right, left):
    (rmodel, rart), (lmodel, lart) = right, left
    mirror = np.diag(hand.mirror_points(np.ones(3)))
    for seed in range(3):
        ra = L.natural_hand_angles(seed, side="right")
        la = L.natural_hand_angles(seed, side="left")
        rj = np_(rmodel(pose=torch.as_tensor(rart.to_pose(ra))[None]).joints[0])
        lj = np_(lmodel(pose=torch.as_tensor(lart.to_pose(la))[None]).joints[0])
        np.testing.assert_allclose(lj, rj @ mirror, atol=2e-5)


@pytest.mark.parametrize("kwargs, match", [
    ({"closure": 1.5}, "closure"), ({"closure": (0.8, 0.2)}, "closure"),
    ({"side": "middle"}, "side"), ({"sigma": -1.0}, "sigma")])
def test_natural_hand_angles_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        L.natural_hand_angles(0, **kwargs)


# ------------------------------------------------------------------ the thumb's zero angles
def _thumb_dir_and_normal(joints21, side):
    d = joints21[4] - joints21[1]
    return d / np.linalg.norm(d), L.palm_normal(joints21, side)


@pytest.mark.parametrize("side", ["right", "left"])
def test_zero_angles_put_the_thumb_near_the_palm_plane(hand, side):
    model = hand.HandModel(side)
    art = L.hand_lcs(model)
    rest = np_(model().joints[0])
    d, n = _thumb_dir_and_normal(rest, side)
    # the template's rest thumb stands about 35 degrees out of the palm (independent of hand_lcs)
    assert np.rad2deg(np.arcsin(d @ n)) == pytest.approx(34.6, abs=0.5)
    pose0 = art.to_pose(np.zeros((15, 3)))
    assert np.abs(np.delete(pose0, 12, axis=0)).max() == 0.0      # only the thumb's CMC turns
    zero = np_(model(pose=torch.as_tensor(pose0)[None]).joints[0])
    d0, n0 = _thumb_dir_and_normal(zero, side)
    np.testing.assert_allclose(n0, n, atol=1e-6)                   # the palm does not move
    assert np.rad2deg(np.arcsin(d0 @ n0)) == pytest.approx(L.THUMB_ZERO_ELEVATION_DEG, abs=0.01)
    # the turn swings the thumb straight towards the palm plane: its axis is d x n, so the
    # thumb's direction stays in the plane spanned by d and n
    assert abs(d0 @ np.cross(d, n)) < 1e-6
    assert L.thumb_elevation(zero, side) == pytest.approx(L.THUMB_ZERO_ELEVATION_DEG, abs=0.01)
    # the other fingers are where they were
    np.testing.assert_allclose(zero[5:], rest[5:], atol=1e-6)


def test_thumb_zero_elevation_none_keeps_the_rest_pose_as_zero(right):
    model, art = right
    plain = L.hand_lcs(model, thumb_zero_elevation=None)
    assert plain.zero_rotations is None
    assert np.abs(plain.to_pose(np.zeros((15, 3)))).max() == 0.0
    np.testing.assert_array_equal(plain.frames, art.frames)        # same rest LCS either way
    # a custom elevation lands where asked
    art20 = L.hand_lcs(model, thumb_zero_elevation=20.0)
    j = np_(model(pose=torch.as_tensor(art20.to_pose(np.zeros((15, 3))))[None]).joints[0])
    assert L.thumb_elevation(j, "right") == pytest.approx(20.0, abs=0.01)


def test_thumb_zero_rotation_is_relative_to_the_rest_thumb(right):
    """to_pose(a) of the re-based joint is the zero rotation applied after the rest LCS turn."""
    model, art = right
    plain = L.hand_lcs(model, thumb_zero_elevation=None)
    a = L.natural_hand_angles(7)
    O = art.zero_rotations[12]
    turned = Rotation.from_matrix(O) * Rotation.from_rotvec(plain.to_pose(a)[12].astype(float))
    np.testing.assert_allclose(art.to_pose(a)[12], turned.as_rotvec(), atol=1e-6)
    np.testing.assert_array_equal(art.to_pose(a)[:12], plain.to_pose(a)[:12])
    np.testing.assert_array_equal(art.to_pose(a)[13:], plain.to_pose(a)[13:])


@pytest.mark.parametrize("side", ["right", "left"])
def test_re_based_angles_round_trip_and_agree_with_rotations(hand, side):
    art = L.hand_lcs(hand.HandModel(side))
    rng = np.random.default_rng(3)
    a = np.stack([L.natural_hand_angles(rng, side=side) for _ in range(8)])
    pose = art.to_pose(a)
    np.testing.assert_allclose(art.from_pose(pose), a, atol=1e-6)
    rotvec = Rotation.from_matrix(art.rotations(a).reshape(-1, 3, 3)).as_rotvec()
    np.testing.assert_allclose(rotvec.reshape(pose.shape), pose, atol=1e-6)


def test_re_based_left_hand_is_the_mirror_of_the_right(hand):
    right_art = L.hand_lcs(hand.HandModel("right"))
    left_art = L.hand_lcs(hand.HandModel("left"))
    a = L.natural_hand_angles(11)
    np.testing.assert_allclose(hand.mirror_axis_angle(right_art.to_pose(a)),
                               left_art.to_pose(L.mirror_angles(a)), atol=1e-6)


def test_the_module_functions_round_trip_with_the_articulation_s_zero_rotations(right, left):
    # issue 43 item 14: pose_to_lcs_angles(art.frames, art.to_pose(a)) was 0.41 rad off at the
    # thumb's CMC (the module functions knew nothing of its re-based zero)
    for _, art in (right, left):
        assert art.zero_rotations is not None
        z = art.zero_rotations
        for limits in ("anatomical", "paper"):
            a = art.with_limits(limits).random_angles(11, n=400)
            pose = L.lcs_angles_to_pose(art.frames, a, z)
            np.testing.assert_array_equal(pose.astype(np.float32), art.to_pose(a))
            back = L.pose_to_lcs_angles(art.frames, pose, z)
            np.testing.assert_allclose(back, a, atol=1e-9)
            np.testing.assert_allclose(L.pose_to_lcs_angles(art.frames, art.to_pose(a), z), a,
                                       atol=1e-5)  # through float32, as art.from_pose
            np.testing.assert_allclose(art.from_pose(pose), a, atol=1e-9)
            np.testing.assert_allclose(L.rotation_from_lcs_angles(art.frames, a, z),
                                       Rotation.from_rotvec(pose.reshape(-1, 3)).as_matrix()
                                       .reshape(*a.shape, 3), atol=1e-12)
        # without zero_rotations the thumb's CMC is read from the rest pose: documented, so test
        off = np.abs(L.pose_to_lcs_angles(art.frames, art.to_pose(a)) - a).max(axis=0)
        assert off[12].max() > 0.1 and off[np.arange(15) != 12].max() < 1e-5
    with pytest.raises(ValueError, match=r"zero_rotations must be \(15, 3, 3\)"):
        L.lcs_angles_to_pose(art.frames, a, np.eye(3))
    bad = np.tile(np.eye(3), (15, 1, 1))
    bad[4] *= 2
    with pytest.raises(ValueError, match=r"zero_rotations\[4\] is not a rotation"):
        L.pose_to_lcs_angles(art.frames, pose, bad)


def test_the_library_s_own_poses_are_within_the_anatomical_limits(hand):
    # issue 43 item 13: example_pose("point"/"pinch"/"fist"/"spread") and every
    # hand.random_pose(max_flexion_deg=30, max_spread_deg=0) were refused: the hinges' sideways
    # and twist ranges were exactly 0 while a flexion about an axis a few degrees off the
    # vertex-defined LCS y reads as 0.5-7 degrees there
    for side in ("right", "left"):
        art = L.hand_lcs(hand.HandModel(side))
        for name in ("flat", "fist", "point", "pinch", "spread"):
            assert art.within_limits(art.from_pose(hand.example_pose(name, side))), (side, name)
        for spread in (0.0, 5.0, 10.0):
            poses = hand.random_pose(0, 500, side=side, max_flexion_deg=30,
                                     max_spread_deg=spread)
            assert art.within_limits(art.from_pose(poses)).all(), (side, spread)
        natural = np.stack([L.natural_hand_angles(s, side=side) for s in range(100)])
        assert art.within_limits(art.from_pose(art.to_pose(natural))).all()
        assert art.within_limits(art.from_pose(L.random_pose(art, 1, 200))).all()
