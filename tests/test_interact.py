"""Tests of the interaction generator (handmesh_tutorial.scenes and its submodules)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

import handmesh_tutorial as hmt
from handmesh_tutorial import data as dataset
from handmesh_tutorial import scenes as interact
from handmesh_tutorial import visibility

torch.set_num_threads(1)
S = 64  # image side of the rendered samples in these tests


@pytest.fixture(scope="module")
def scenes():
    """One scene per kind (with its step history)."""
    return {k: interact.build_scene(k, 7, record=True) for k in interact.KINDS}


@pytest.fixture(scope="module")
def samples():
    """One rendered sample per kind."""
    return {k: interact.make_sample(11, k, S) for k in interact.KINDS}


# ---------------------------------------------------------------------------------------------
# geometry helpers, checked against independent computations
# ---------------------------------------------------------------------------------------------
def test_closest_points_on_triangles_matches_dense_sampling():
    rng = np.random.default_rng(0)
    a, b, c = rng.normal(size=(3, 3))
    p = rng.normal(size=(200, 3)) * 2
    q, region = interact.closest_points_on_triangles(p, a, b, c)
    u, v = np.meshgrid(np.linspace(0, 1, 301), np.linspace(0, 1, 301))
    ok = u + v <= 1
    dense = a + u[ok, None] * (b - a) + v[ok, None] * (c - a)  # points of the triangle
    best = np.sqrt(((p[:, None] - dense[None]) ** 2).sum(-1)).min(1)
    d = np.linalg.norm(q - p, axis=1)
    assert np.all(d <= best + 1e-12)               # never worse than any triangle point
    assert np.all(best - d < 0.02)                 # and the grid gets within its spacing
    assert set(np.unique(region)) <= set(range(7))
    corner = {4: a, 5: b, 6: c}
    for code, pt in corner.items():
        assert np.allclose(q[region == code], pt)


def test_signed_distance_matches_trimesh_on_a_hand():
    model = hmt.hand.HandModel("right")
    # (a pinch: plain LBS folds the skin of a tight fist into itself, where "inside" is ill-posed)
    out = model(pose=torch.as_tensor(hmt.hand.example_pose("pinch")[None]))
    v, f = out.vertices[0].numpy().astype(float), model.faces
    rng = np.random.default_rng(1)
    pts = v[rng.integers(len(v), size=300)] + rng.normal(size=(300, 3)) * 0.004
    mine = interact.signed_distance(pts, v, f)
    ref = trimesh.proximity.signed_distance(trimesh.Trimesh(v, f, process=False), pts)
    # trimesh: positive inside; ours: negative inside. Signs agree everywhere, and our exact
    # search is never farther than trimesh's closest point
    assert np.array_equal(np.sign(mine), -np.sign(ref))
    assert np.all(np.abs(mine) <= np.abs(ref) + 1e-12)
    assert np.abs(np.abs(mine) - np.abs(ref)).max() < 1e-4
    assert (mine < 0).sum() > 50  # the test covers inside points


def _sdf_test_points(v, rng):
    """Query points that reach every branch: on vertices, face centroids and edge midpoints,
    just off the surface, inside, and far away."""
    span = v.max(0) - v.min(0)
    return np.concatenate([v, v + rng.normal(size=v.shape) * 1e-4,
                           v + rng.normal(size=v.shape) * 3e-3,
                           rng.uniform(v.min(0) - 0.3 * span, v.max(0) + 0.3 * span, (600, 3)),
                           v.mean(0) + rng.normal(size=(50, 3)) * 0.5])


def _sdf_test_meshes():
    model = hmt.hand.HandModel("right")
    rng = np.random.default_rng(3)
    meshes = []
    for pose in (hmt.hand.example_pose("pinch")[None], rng.normal(0, 0.3, (1, 15, 3))):
        out = model(pose=torch.as_tensor(pose, dtype=torch.float32))
        meshes.append((out.vertices[0].numpy().astype(float), np.asarray(model.faces)))
    for kind in hmt.objects.OBJECT_KINDS:   # objects have large flat faces (another branch)
        body = hmt.objects.make_object(kind, rng=5)
        meshes.append((np.asarray(body.vertices, float), np.asarray(body.faces)))
    return meshes


def test_signed_distance_backends_agree():
    pytest.importorskip("numba")
    rng = np.random.default_rng(2)
    tested = inside = 0
    for v, f in _sdf_test_meshes():
        sdf = interact.contact._MeshSDF(v, f)
        pts = np.concatenate([_sdf_test_points(v, rng), v[f].mean(1),
                              0.5 * (v[f[:, 0]] + v[f[:, 1]])])
        ref, fast = sdf(pts, "numpy"), sdf(pts, "numba")
        assert np.array_equal(np.abs(ref), np.abs(fast)), np.abs(np.abs(ref) - np.abs(fast)).max()
        # a point on an edge (|d| ~ 1e-18 m) lies on two faces that tie; the two paths may break
        # the tie differently and so report either sign: there the sign means nothing
        on_surface = np.abs(ref) < 1e-15
        assert np.array_equal(ref[~on_surface], fast[~on_surface])
        tested, inside = tested + len(pts), inside + int((ref < 0).sum())
    assert inside > 500 and tested > 20000          # both signs, every mesh
    assert interact.signed_distance(pts[:5], v, f, backend="numba").shape == (5,)


@pytest.mark.parametrize("kind", interact.KINDS)
def test_scenes_are_the_same_with_either_backend(kind, monkeypatch):
    """The compiled kernels (cylinder test and the settle step's signed distances) change the
    generator's speed, never its scenes."""
    pytest.importorskip("numba")
    built = {}
    for backend in ("numpy", "numba"):
        monkeypatch.setattr(hmt.collision, "BACKEND", backend)
        sc = interact.build_scene(kind, 21)
        built[backend] = [(b.vertices.copy(), b.faces.copy()) for b in sc.bodies], sc.stats
    (ref, ref_stats), (fast, fast_stats) = built["numpy"], built["numba"]
    assert ref_stats == fast_stats
    for (v0, f0), (v1, f1) in zip(ref, fast, strict=True):
        assert np.array_equal(v0, v1) and np.array_equal(f0, f1)


def test_scene_hands_know_their_skin_tone():
    sample, scene = interact.make_sample(11, "hand-hand", S, return_scene=True)
    assert np.array_equal(sample["image"], interact.make_sample(11, "hand-hand", S)["image"])
    for body in scene.bodies:
        assert body.kind == "hand" and 0 <= body.tone < len(hmt.hand.SKIN_TONES)
        # the colours were made from that tone: the back of the hand (no palm, knuckle or nail
        # label) has the tone's colour up to the +-4 % blotches
        model = hmt.hand.HandModel(body.side)
        plain = ((model.palmar < 0.01) & (model.template.nail < 0.01)
                 & (hmt.hand.appearance.knuckle_weights(model.template_vertices,
                                                        model.rest_joints, model.palmar) < 0.01))
        back = np.median(body.colors[plain], axis=0)
        nearest = np.argmin(np.abs(np.asarray(hmt.hand.SKIN_TONES) - back).sum(1))
        assert nearest == body.tone
    _, obj_scene = interact.make_sample(11, "hand-object", S, return_scene=True)
    assert [b.tone is None for b in obj_scene.bodies] == [b.kind != "hand"
                                                          for b in obj_scene.bodies]


@pytest.mark.parametrize("kind", interact.KINDS)
def test_forearms_continue_their_hands_and_turn_with_the_camera(scenes, kind):
    scene = scenes[kind]
    rot = Rotation.from_rotvec([0.3, -0.5, 0.2]).as_matrix()
    t = np.array([0.01, -0.02, 0.4])
    meshes = {m[3]: m for m in scene.render_meshes(rot, t)}
    scenery = {s[3]: s for s in scene.scenery_meshes(rot, t)}
    for body in scene.bodies:
        if body.kind != "hand":
            assert body.forearm is None and body.normals is None and meshes[body.label][4] is None
            assert body.label not in scenery
            continue
        loop = hmt.hand.HandModel(body.side).wrist_loop
        fv, ff, fc, fn = body.forearm
        L = len(loop)
        np.testing.assert_allclose(fv[:L], body.vertices[loop], atol=1e-15)   # glued at the wrist
        np.testing.assert_array_equal(fc[:L], body.colors[loop])      # no colour step there
        np.testing.assert_array_equal(fn[:L], body.normals[loop])     # nor a shading step
        v, _, _, label, n = meshes[body.label]
        np.testing.assert_allclose(v, body.vertices @ rot.T + t, atol=1e-15)
        np.testing.assert_allclose(n, body.normals @ rot.T, atol=1e-15)
        sv, _, _, owner, sn = scenery[body.label]
        assert owner == label == body.label
        np.testing.assert_allclose(sn[:L], n[loop], atol=1e-15)
        np.testing.assert_allclose(sv[:L], v[loop], atol=1e-15)


def test_signed_distance_backend_is_checked():
    v = np.asarray(trimesh.creation.box().vertices)
    f = np.asarray(trimesh.creation.box().faces)
    with pytest.raises(ValueError, match="backend must be"):
        interact.signed_distance(np.zeros((1, 3)), v, f, backend="cuda")


def test_mesh_contact_of_two_spheres():
    s = trimesh.creation.icosphere(4, radius=0.02)
    v, f = np.asarray(s.vertices), np.asarray(s.faces)
    apart = interact.mesh_contact(v, f, v + [0.043, 0, 0], f)
    assert apart["penetration_mm"] == 0 and apart["inside"] == 0
    assert apart["contact_mm"] == pytest.approx(3.0, abs=0.1)  # 43 - 2 * 20 mm
    deep = interact.mesh_contact(v, f, v + [0.036, 0, 0], f)
    assert deep["contact_mm"] == 0 and deep["inside"] > 0
    assert deep["penetration_mm"] == pytest.approx(4.0, abs=0.1)  # 40 - 36 mm
    shifted = interact.mesh_contact(v, f, v + [0.036, 0, 0], f, a_shift=[-0.007, 0, 0])
    assert shifted["contact_mm"] == pytest.approx(3.0, abs=0.1)


# ---------------------------------------------------------------------------------------------
# scenes
# ---------------------------------------------------------------------------------------------
def _independent_contact(a, b):
    """Mesh gap and penetration (mm) of two bodies with trimesh only (all vertices near b)."""
    mb = trimesh.Trimesh(b.vertices, b.faces, process=False)
    lo, hi = b.vertices.min(0) - 0.01, b.vertices.max(0) + 0.01
    pts = a.vertices[((a.vertices >= lo) & (a.vertices <= hi)).all(1)]
    sd = trimesh.proximity.signed_distance(mb, pts)  # positive inside
    return -sd.max(), max(sd.max(), 0.0)


@pytest.mark.parametrize("kind", interact.KINDS)
def test_scene_is_a_close_interaction(scenes, kind):
    sc = scenes[kind]
    assert [b.label for b in sc.bodies] == [1, 2]
    a, b = sc.bodies
    gap1, pen1 = _independent_contact(a, b)
    gap2, pen2 = _independent_contact(b, a)
    gap_mm, pen_mm = 1e3 * min(gap1, gap2), 1e3 * max(pen1, pen2)
    assert gap_mm <= 3.0, f"{kind}: bodies {gap_mm:.2f} mm apart, expected contact"
    assert pen_mm <= 2.0, f"{kind}: meshes interpenetrate by {pen_mm:.2f} mm"
    # the stats report the same numbers (ours are exact, trimesh's closest point is not)
    assert sc.stats["penetration_mm"] == pytest.approx(pen_mm, abs=0.05)
    assert sc.stats["contact_mm"] <= max(gap_mm, 0) + 0.05
    assert sc.stats["stop"] in interact.STOP_REASONS
    assert 1 <= sc.stats["rounds"] <= interact.InteractionConfig().max_rounds


@pytest.mark.parametrize("kind", interact.KINDS)
def test_hand_cylinders_follow_the_hand_model(scenes, kind):
    """The generator's fast rig (numpy FK) agrees with the torch hand model's joints."""
    for b in scenes[kind].bodies:
        if b.kind != "hand":
            continue
        for f in range(5):
            for s in range(3):
                k = 3 * f + s
                assert np.allclose(b.cylinders.p0[k], b.joints[1 + 4 * f + s], atol=2e-5)
                # fingertips are skinned mesh vertices (blended), joints are rigid: 1 mm
                tol = 1e-3 if s == 2 else 2e-5
                assert np.allclose(b.cylinders.p1[k], b.joints[2 + 4 * f + s], atol=tol)


def test_hand_angles_respect_the_limits(scenes):
    assert interact.InteractionConfig().limits == "anatomical"  # natural poses by default
    lo, hi = hmt.lcs.hand_joint_limits("anatomical")
    for kind, sc in scenes.items():
        for b in sc.bodies:
            if b.kind == "hand":
                assert hmt.lcs.within_limits(b.angles, lo, hi), kind
    # natural hands: every finger's DIP follows its PIP (flexion only, 2/3 of it)
    ratio = hmt.lcs.DIP_PIP_RATIO
    flexed = 0
    for sc in scenes.values():
        for b in sc.bodies:
            if b.kind == "hand":
                for dip, pip in hmt.lcs.DIP_FOLLOWS_PIP.items():
                    np.testing.assert_allclose(b.angles[dip - 1], [0, ratio * b.angles[pip - 1, 1],
                                                                   0], atol=1e-12)
                    flexed += b.angles[pip - 1, 1] > np.deg2rad(10)
    assert flexed > 0
    sc = interact.build_scene("hand-hand", 3, limits="paper")  # the paper's ±60° box
    for b in sc.bodies:
        assert np.abs(b.angles).max() <= np.deg2rad(60) + 1e-9
    assert max(np.abs(b.angles).max() for b in sc.bodies) > np.deg2rad(20)
    # ... with independent DIPs
    assert any(abs(b.angles[dip - 1, 1] - ratio * b.angles[pip - 1, 1]) > 1e-3
               for b in sc.bodies for dip, pip in hmt.lcs.DIP_FOLLOWS_PIP.items())


def _finger_flexion(scene_list) -> np.ndarray:
    """(hands, 4, 2) MCP and PIP flexion (degrees) of every hand of the scenes."""
    idx = np.array(hmt.lcs.FINGER_JOINTS)[:, :2] - 1
    return np.rad2deg(np.array([b.angles[idx, 1] for sc in scene_list for b in sc.bodies
                                if b.kind == "hand"]))


def test_poses_follow_the_limits_and_the_paper_rule_is_one_setting_away():
    assert interact.InteractionConfig().poses == "natural"
    assert interact.InteractionConfig(limits="paper").poses == "uniform"
    assert interact.InteractionConfig(limits="paper", poses="natural").poses == "natural"
    # the limits shortcut selects the paper's whole generator: its limits and its uniform rule
    a = interact.build_scene("hand-object", 5, limits="paper")
    b = interact.build_scene("hand-object", 5, interact.InteractionConfig(limits="paper",
                                                                         poses="uniform"))
    for x, y in zip(a.bodies, b.bodies, strict=True):
        assert np.array_equal(x.vertices, y.vertices)
    with pytest.raises(ValueError, match="poses must be"):
        interact.InteractionConfig(poses="random")
    with pytest.raises(ValueError, match="grasp_closure"):
        interact.InteractionConfig(grasp_closure=(0.9, 0.2))


def test_natural_poses_flex_in_synergies_unlike_the_uniform_rule():
    def batch(**kw):  # 6 scenes per kind (a rejected seed is skipped, as the dataset does)
        out = []
        for kind in ("hand-hand", "hand-object"):
            have = 0
            for i in range(20):
                if have == 6:
                    break
                try:
                    out.append(interact.build_scene(kind, dataset.sample_seed(4, i), **kw))
                    have += 1
                except interact.InteractionError:
                    continue
        return out

    natural, uniform = batch(), batch(poses="uniform")
    assert len(natural) == len(uniform) == 12
    fn, fu = _finger_flexion(natural), _finger_flexion(uniform)
    def corr(f):  # a finger's MCP and PIP flexion, over all fingers
        return float(np.corrcoef(f[..., 0].ravel(), f[..., 1].ravel())[0, 1])
    # measured over seed batches 4-6: natural 0.71-0.75, uniform 0.22-0.47
    assert corr(fn) > 0.6 > 0.5 > corr(fu)
    # the four fingers of a natural hand flex more alike: per-hand spread of the PIPs, measured over
    # seed batches 4-6 since the hinges' +-10 degree play (0.3.0): natural 9.9-11.4, uniform
    # 12.0-13.3 degrees (ratio 0.77-0.94; 0.77 on this batch)
    assert fn[..., 1].std(1).mean() < 0.85 * fu[..., 1].std(1).mean()
    # the natural scenes are still close interactions (the settle step's tolerances)
    for sc in natural:
        assert sc.stats["contact_mm"] <= 1.5 + 1e-6 and sc.stats["penetration_mm"] <= 1.5 + 1e-6


def test_no_self_collision_of_the_hands(scenes):
    for sc in scenes.values():
        for b in sc.bodies:
            if b.kind == "hand":
                # the settle step only translates, so the final cylinders are collision-free
                assert len(hmt.collision.self_collisions(b.cylinders)[0]) == 0


def test_history_records_the_steps(scenes):
    steps = [h["step"] for h in scenes["hand-hand"].history]
    assert steps[:3] == ["1", "2", "3"] and steps[-1] == "5b" and "4" in steps
    assert set(scenes["hand-hand"].history[2]["bodies"]) == {1, 2}


def test_scene_is_deterministic():
    a = interact.build_scene("hand-chain", 5)
    b = interact.build_scene("hand-chain", 5)
    c = interact.build_scene("hand-chain", 6)
    for x, y in zip(a.bodies, b.bodies, strict=True):
        assert np.array_equal(x.vertices, y.vertices)
    assert a.stats == b.stats
    assert not np.array_equal(a.bodies[0].vertices, c.bodies[0].vertices)


def test_impossible_configuration_raises_a_clear_error():
    # an aim point 1 m outside the hand: the second hand always misses the centre body
    with pytest.raises(interact.InteractionError, match=r"'hand-object'.*seed 4.*missed"):
        interact.build_scene("hand-object", 4, lateral_offset=1.0, max_attempts=3)
    with pytest.raises(ValueError, match="kind must be one of"):
        interact.build_scene("hand-foot", 0)
    with pytest.raises(ValueError, match="unknown InteractionConfig fields"):
        interact.build_scene("hand-hand", 0, speed=3)
    with pytest.raises(ValueError, match="limits must be"):
        interact.InteractionConfig(limits="none")


# ---------------------------------------------------------------------------------------------
# rendered samples
# ---------------------------------------------------------------------------------------------
def test_sample_bytes_are_deterministic(samples):
    again = interact.make_sample(11, "hand-object", S)
    assert dataset.encode_sample(again) == dataset.encode_sample(samples["hand-object"])
    other = interact.make_sample(12, "hand-object", S)
    assert dataset.encode_sample(other) != dataset.encode_sample(again)


def test_photo_prob_changes_only_the_background_draw(samples):
    base = samples["hand-object"]
    explicit = interact.make_sample(11, "hand-object", S, photo_prob=0.75)   # render_scene's
    assert dataset.encode_sample(explicit) == dataset.encode_sample(base)
    photo = interact.make_sample(11, "hand-object", S, photo_prob=1.0)
    textures = interact.make_sample(11, "hand-object", S, photo_prob=0.0)
    assert not np.array_equal(photo["image"], textures["image"])
    for smp in (photo, textures):   # the same scene, camera and visibility either way
        assert np.array_equal(smp["scene_mask"], base["scene_mask"])
        assert np.array_equal(smp["K"], base["K"])
        for lab in base["joints"]:
            assert np.array_equal(smp["joints"][lab], base["joints"][lab])
        assert smp["vr"] == base["vr"]
    with pytest.raises(ValueError, match="photo_prob"):
        interact.make_sample(11, "hand-object", S, photo_prob=1.5)


@pytest.mark.parametrize("kind", interact.KINDS)
def test_vr_masks_and_joints(samples, kind, tmp_path):
    smp = samples[kind]
    dataset.write_sample(tmp_path / "s", smp)
    back = dataset.read_sample(tmp_path / "s")
    assert back["kind"] == kind
    for lab, alone in back["alone_masks"].items():
        visible = back["scene_mask"] == lab
        assert not (visible & ~alone).any()        # visible pixels lie inside the alone mask
        assert back["vr"][lab] == visible.sum() / alone.sum()  # VR by counting pixels
        assert back["vr"][lab] == visibility.visibility_ratio(back["scene_mask"], alone, lab)
    t = back["target"]
    assert back["sides"][t] in ("left", "right")
    if kind == "hand-hand":
        assert back["sides"][t] == "left" and back["names"][t] == "left_hand"
    j = back["joints"][t] @ back["K"].T
    uv = j[:, :2] / j[:, 2:]
    assert (j[:, 2] > 0).all()
    assert (uv >= -0.5).all() and (uv <= S - 0.5).all()  # the target hand is in the image
    # the target's mesh projects where its alone mask is (silhouette vertices may fall in the
    # pixel next to the mask: dilate by one pixel)
    from scipy.ndimage import binary_dilation

    v = back["meshes"][t][0] @ back["K"].T
    px = np.round(v[:, :2] / v[:, 2:]).astype(int)
    mask = binary_dilation(back["alone_masks"][t], iterations=1)
    inside = mask[px[:, 1].clip(0, S - 1), px[:, 0].clip(0, S - 1)]
    assert inside.mean() > 0.99


@pytest.mark.parametrize("kind", interact.KINDS)
def test_target_hand_is_framed_like_a_freihand_crop(kind):
    """Over 20 seeds: >= 95 % of the target's 21 joints at least 8 % of the side inside the
    image, and its bounding box (alone mask) 40-80 % of the image side, as in FreiHAND."""
    from handmesh_tutorial.render import framing

    tested = 0
    for i in range(20):
        try:
            smp = interact.make_sample(dataset.sample_seed(3, i), kind, S)
        except interact.InteractionError:
            continue
        tested += 1
        t = smp["target"]
        joints = framing(smp["joints"][t], smp["K"], S, margin=0.08)
        assert joints["inside"] >= 0.95, (kind, i, joints)
        ys, xs = np.nonzero(smp["alone_masks"][t])
        share = max(np.ptp(xs) + 1, np.ptp(ys) + 1) / S
        assert 0.40 <= share <= 0.80, (kind, i, share)
        # by construction: every vertex inside the margin, the box 45-75 % of the side
        verts = framing(smp["meshes"][t][0], smp["K"], S, margin=0.08)
        assert verts["inside"] == 1.0
        assert 0.45 - 1e-6 <= verts["share"] <= 0.75 + 1e-6
        assert verts["share"] == pytest.approx(smp["stats"]["target_share"])
        # principal point at the image centre (within 1 %), a crop-like focal length
        np.testing.assert_allclose(smp["K"][:2, 2], (S - 1) / 2, atol=0.01 * S + 1e-9)
        assert 1.6 * S <= smp["K"][0, 0] <= 4.2 * S
    assert tested >= 16           # a few seeds are rejected (SampleRejected), not mis-framed


def test_frame_camera_geometry():
    rng = np.random.default_rng(0)
    hand = rng.normal(size=(300, 3)) * [0.06, 0.03, 0.015] + [0.2, -0.1, 0.05]
    for seed in range(30):
        R, t, K = interact.frame_camera(hand, seed, 224)
        assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
        cam = hand @ R.T + t
        fr = hmt.render.framing(cam, K, 224, margin=0.08)
        assert fr["inside"] == 1.0 and 0.45 - 1e-9 <= fr["share"] <= 0.75 + 1e-9
        again = interact.frame_camera(hand, seed, 224)
        assert all(np.array_equal(a, b) for a, b in zip((R, t, K), again, strict=True))
    # a wished share and a given side: the camera sits on that side of the hand
    toward = np.array([0.0, 0.0, 1.0])
    R, t, K = interact.frame_camera(hand, 1, 224, toward=toward, spread=0.0, share=(0.6, 0.6))
    centre = 0.5 * (hand.min(0) + hand.max(0))
    assert (-R.T @ t - centre) @ toward > 0.1
    assert hmt.render.framing(hand @ R.T + t, K, 224)["share"] == pytest.approx(0.6)
    with pytest.raises(ValueError, match="share"):
        interact.frame_camera(hand, 0, 224, share=(0.5, 0.9))


def test_scene_lights_are_the_renderers():
    # one copy: the generator lights its scenes with render.scene_lights (tested in test_render)
    from handmesh_tutorial import render

    assert interact.scene_lights is render.scene_lights


def test_mixed_kind_is_drawn_from_the_seed():
    kinds = {interact.sample._choose_kind(s) for s in range(40)}
    assert kinds == set(interact.KINDS)
    assert interact.sample._choose_kind(123) == interact.sample._choose_kind(123)


def test_make_sample_rejects_bad_arguments():
    with pytest.raises(ValueError, match="kind must be one of"):
        interact.make_sample(0, "hand-chair", S)
    with pytest.raises(ValueError, match="renderer is 64x64"):
        interact.make_sample(0, "hand-hand", 32, renderer=interact.get_renderer(S))


def test_interaction_error_survives_pickling():
    import pickle

    err = pickle.loads(pickle.dumps(interact.InteractionError("hand-chain", 7, "no contact")))
    assert isinstance(err, interact.InteractionError)
    assert (err.kind, err.seed, err.reason) == ("hand-chain", 7, "no contact")
    assert "seed 7" in str(err)


def test_thumb_zero_elevation_turns_generated_thumbs_towards_the_palm_plane():
    """The default counts the thumb's angles from a thumb near the palm plane; ``None`` keeps the
    template's rest thumb (35° out of the palm) as zero, the generator before the option."""
    def elevations(cfg):
        out = []
        for seed in range(6):
            sc = interact.build_scene("hand-object", seed, cfg, settle=False)
            for b in sc.bodies:
                if b.kind == "hand":
                    out.append(hmt.lcs.thumb_elevation(b.joints, b.side))
        return np.array(out)

    new = elevations(interact.InteractionConfig())
    old = elevations(interact.InteractionConfig(thumb_zero_elevation=None))
    assert len(new) == len(old) == 6
    # same seeds and targets, only the thumb's zero differs (by 30 degrees; contacts stop the
    # grasping thumb at other angles, so the measured gap varies from hand to hand)
    assert np.all(old > new) and 12.0 < np.mean(old - new) < 35.0
    with pytest.raises(ValueError, match="thumb_zero_elevation"):
        interact.InteractionConfig(thumb_zero_elevation=90.0)
