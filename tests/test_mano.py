"""Tests for handmesh_tutorial.hand.mano: restricted unpickling and the MANO forward pass.

No MANO file is available, so every test writes its own MANO-format fixture: random arrays with
the real keys and shapes. The LBS reference below is an independent float64 numpy computation.
"""

from __future__ import annotations

import os
import pickle
import sys
import types

import numpy as np
import pytest
import scipy.sparse as sp
import torch
from scipy.spatial.transform import Rotation

from handmesh_tutorial.hand import mano as M
from handmesh_tutorial.testing import mano_format_params, write_mano_pickle

torch.set_num_threads(1)

MANO_PARENTS = [-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14]


def fake_mano_params(seed: int = 0) -> dict:
    """Random arrays with the keys, shapes and types of an official MANO pickle."""
    rng = np.random.default_rng(seed)
    nv = 778
    weights = rng.dirichlet(np.full(16, 0.3), size=nv)
    jreg = np.zeros((16, nv))
    for j in range(16):  # each joint averages a few vertices, rows sum to 1
        ids = rng.choice(nv, size=12, replace=False)
        jreg[j, ids] = rng.dirichlet(np.ones(12))
    kintree = np.stack([np.array(MANO_PARENTS, dtype=np.int64) % 2**32, np.arange(16)])
    comps = np.linalg.qr(rng.normal(size=(45, 45)))[0].T
    return {
        "v_template": rng.normal(scale=0.04, size=(nv, 3)),
        "shapedirs": rng.normal(scale=0.003, size=(nv, 3, 10)),
        "posedirs": rng.normal(scale=0.002, size=(nv, 3, 135)),
        "J_regressor": sp.csc_matrix(jreg),
        "weights": weights,
        "kintree_table": kintree.astype(np.uint32),
        "f": rng.integers(0, nv, size=(1538, 3)).astype(np.uint32),
        "hands_components": comps,
        "hands_mean": rng.normal(scale=0.2, size=45),
        "hands_coeffs": rng.normal(size=(20, 12)),
        "bs_style": "lbs",
        "bs_type": "lrotmin",
        "J": jreg @ rng.normal(size=(nv, 3)),
    }


def write_pickle(path, obj, protocol=2) -> str:
    with open(path, "wb") as fh:
        pickle.dump(obj, fh, protocol=protocol)
    return str(path)


def numpy_lbs(params, pose45, betas, global_orient, transl, fix_left=False):
    """Reference MANO forward in float64 numpy, joint by joint (independent of mano.py)."""
    shapedirs = np.array(params["shapedirs"], dtype=float)
    if fix_left:
        shapedirs[:, 0, :] *= -1
    v_shaped = params["v_template"] + shapedirs @ betas
    jreg = params["J_regressor"].toarray()
    joints = jreg @ v_shaped
    full = np.concatenate([global_orient, pose45]).reshape(16, 3)
    rots = Rotation.from_rotvec(full).as_matrix()
    feat = np.concatenate([(rots[k] - np.eye(3)).ravel() for k in range(1, 16)])
    v_posed = v_shaped + params["posedirs"] @ feat
    glob = []
    for k in range(16):
        local = np.eye(4)
        local[:3, :3] = rots[k]
        parent = MANO_PARENTS[k]
        local[:3, 3] = joints[k] - (joints[parent] if parent >= 0 else 0)
        glob.append(local if parent < 0 else glob[parent] @ local)
    verts = np.zeros_like(v_posed)
    for k in range(16):
        moved = (glob[k][:3, :3] @ (v_posed - joints[k]).T).T + glob[k][:3, 3]
        verts += params["weights"][:, k:k + 1] * moved
    posed_joints = np.array([g[:3, 3] for g in glob])
    return verts + transl, posed_joints + transl


@pytest.fixture(scope="module")
def params():
    return fake_mano_params()


@pytest.fixture(scope="module")
def right_file(tmp_path_factory, params):
    return write_pickle(tmp_path_factory.mktemp("mano") / "MANO_RIGHT.pkl", params)


# ------------------------------------------------------------------ restricted unpickling
@pytest.mark.parametrize("protocol", [0, 2, 4, 5])
def test_plain_arrays_round_trip(tmp_path, params, protocol):
    path = write_pickle(tmp_path / "m.pkl", params, protocol)
    got = M.read_mano_pickle(path)
    assert set(got) == set(params)
    for key, value in params.items():
        if sp.issparse(value):
            assert sp.issparse(got[key])
            np.testing.assert_array_equal(got[key].toarray(), value.toarray())
        elif isinstance(value, np.ndarray):
            np.testing.assert_array_equal(got[key], value)
            assert got[key].dtype == value.dtype
        else:
            assert got[key] == value


@pytest.fixture
def fake_chumpy():
    """A module named like chumpy whose classes pickle like chumpy's (state = __dict__ with x/a)."""
    ch_mod = types.ModuleType("chumpy.ch")
    re_mod = types.ModuleType("chumpy.reordering")
    pkg = types.ModuleType("chumpy")

    class Ch:
        def __init__(self, x):
            self.x = np.asarray(x, dtype=np.float64)
            self._dirty_vars = {"x"}
            self._itr = None
            self._depends_on_deps = {}
            self._make_dense = False
            self._make_sparse = False

        def __getstate__(self):
            return dict(self.__dict__)

    class Select:
        def __init__(self, a, idxs, preferred_shape):
            self.a, self.idxs, self.preferred_shape = a, idxs, preferred_shape
            self._dirty_vars = set()

    Ch.__module__, Ch.__qualname__ = "chumpy.ch", "Ch"
    Select.__module__, Select.__qualname__ = "chumpy.reordering", "Select"
    ch_mod.Ch, re_mod.Select, pkg.ch, pkg.reordering = Ch, Select, ch_mod, re_mod
    names = ("chumpy", "chumpy.ch", "chumpy.reordering")
    assert not any(n in sys.modules for n in names), "a real chumpy must not be imported"
    sys.modules.update({"chumpy": pkg, "chumpy.ch": ch_mod, "chumpy.reordering": re_mod})
    try:
        yield types.SimpleNamespace(Ch=Ch, Select=Select)
    finally:
        for n in names:
            sys.modules.pop(n, None)


@pytest.mark.parametrize("protocol", [0, 2])
def test_chumpy_objects_become_arrays(tmp_path, params, fake_chumpy, protocol):
    wrapped = dict(params)
    wrapped["shapedirs"] = fake_chumpy.Ch(params["shapedirs"])
    wrapped["v_template"] = fake_chumpy.Ch(params["v_template"])
    flat = params["weights"].ravel()
    perm = np.random.default_rng(1).permutation(flat.size)
    inverse = np.argsort(perm)  # Select(a=permuted, idxs=inverse) gives the original back
    wrapped["weights"] = fake_chumpy.Select(fake_chumpy.Ch(flat[perm]), inverse, (778, 16))
    path = write_pickle(tmp_path / "MANO_RIGHT.pkl", wrapped, protocol)
    for n in ("chumpy", "chumpy.ch", "chumpy.reordering"):
        sys.modules.pop(n)  # loading must not need (or import) chumpy
    got = M.read_mano_pickle(path)
    assert "chumpy" not in sys.modules
    for key in ("shapedirs", "v_template", "weights"):
        assert type(got[key]) is np.ndarray, key
        np.testing.assert_array_equal(got[key], params[key])
    model = M.load_mano(path)
    out = model()
    np.testing.assert_allclose(out.vertices[0].numpy(), params["v_template"], atol=1e-6)


class Evil:
    """A harmless class the loader has never heard of."""

    def __init__(self):
        self.payload = 1


class RunsCommand:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_refuses_os_system_without_running_it(tmp_path, params):
    marker = tmp_path / "was_executed"
    bad = dict(params, J=RunsCommand(marker))
    path = write_pickle(tmp_path / "MANO_RIGHT.pkl", bad)
    with pytest.raises(M.UnsafePickleError, match=r"(posix|os|nt)\.system") as info:
        M.load_mano(path)
    assert "MANO_RIGHT.pkl" in str(info.value)
    assert isinstance(info.value, pickle.UnpicklingError)
    assert isinstance(info.value, ValueError)
    assert not marker.exists()


def test_refuses_unknown_class(tmp_path, params):
    path = write_pickle(tmp_path / "m.pkl", dict(params, extra=Evil()))
    with pytest.raises(M.UnsafePickleError, match=r"test_mano\.Evil"):
        M.read_mano_pickle(path)


@pytest.mark.parametrize("payload, name", [
    (b"cbuiltins\neval\n(S'1+1'\ntR.", "builtins.eval"),
    (b"c__builtin__\ngetattr\n(c__builtin__\nobject\nS'x'\ntR.", "builtins.getattr"),
])
def test_refuses_raw_globals(tmp_path, payload, name):
    path = tmp_path / "raw.pkl"
    path.write_bytes(payload)
    with pytest.raises(M.UnsafePickleError, match=name.replace(".", r"\.")):
        M.read_mano_pickle(path)


@pytest.mark.parametrize("payload, what", [
    (b"cnumpy.core.multiarray\n_reconstruct\n(cnumpy\nndarray\n(I8000000000\ntS'b'\ntR.",
     "numpy _reconstruct"),
    (b"cnumpy\nndarray\n((I100000\nI100000\ntS'f8'\ntR.", "numpy.ndarray"),
])
def test_refuses_a_huge_array_before_allocating_it(tmp_path, payload, what):
    path = tmp_path / "huge.pkl"
    path.write_bytes(payload)
    with pytest.raises(M.UnsafePickleError, match=f"refusing {what} of shape .*elements"):
        M.read_mano_pickle(path)
    # the same opcodes with a sane shape inside a dict still load
    small = payload.replace(b"I8000000000", b"I8").replace(b"I100000\nI100000", b"I2\nI3")
    path.write_bytes(b"(dp0\nS'a'\n" + small[:-1] + b"s.")
    got = M.read_mano_pickle(path)["a"]
    assert isinstance(got, np.ndarray) and got.size in (8, 6)


def test_reconstructor_only_builds_stand_ins(tmp_path):
    # copyreg._reconstructor is whitelisted for Python-2 pickles, but only for stand-in classes.
    path = tmp_path / "raw.pkl"
    path.write_bytes(b"ccopy_reg\n_reconstructor\n(c__builtin__\nset\nc__builtin__\nobject\nNtR.")
    with pytest.raises(M.UnsafePickleError, match="_reconstructor"):
        M.read_mano_pickle(path)


def test_missing_file_and_bad_contents(tmp_path, params):
    with pytest.raises(FileNotFoundError, match="nope.pkl"):
        M.read_mano_pickle(tmp_path / "nope.pkl")
    with pytest.raises(ValueError, match="expected a pickled dict"):
        M.read_mano_pickle(write_pickle(tmp_path / "list.pkl", [1, 2]))
    bad = dict(params)
    del bad["posedirs"]
    with pytest.raises(ValueError, match="missing key 'posedirs'"):
        M.load_mano(write_pickle(tmp_path / "MANO_RIGHT.pkl", bad))
    bad = dict(params, weights=params["weights"][:, :15])
    with pytest.raises(ValueError, match=r"'weights' has shape \(778, 15\), expected 778x16"):
        M.load_mano(write_pickle(tmp_path / "MANO_RIGHT.pkl", bad))
    with pytest.raises(ValueError, match="cannot infer the side"):
        M.load_mano(write_pickle(tmp_path / "hand.pkl", params))


# ------------------------------------------------------------------------ forward pass
def test_zero_pose_is_template(right_file, params):
    model = M.load_mano(right_file)
    assert model.side == "right" and model.num_vertices == 778 and model.num_joints == 16
    out = model(pose=torch.zeros(2, 15, 3), shape=torch.zeros(2, 10))
    assert out.vertices.shape == (2, 778, 3) and out.joints.shape == (2, 21, 3)
    assert out.joints_mano.shape == (2, 16, 3) and out.transforms.shape == (2, 16, 4, 4)
    assert out.vertices.dtype == torch.float32
    np.testing.assert_allclose(out.vertices[1].numpy(), params["v_template"], atol=1e-6)


def test_joints_are_regressed_from_shaped_vertices(right_file, params):
    model = M.load_mano(right_file)
    betas = torch.tensor(np.random.default_rng(4).normal(size=(3, 10)), dtype=torch.float32)
    out = model(shape=betas)
    jreg = params["J_regressor"].toarray()
    for b in range(3):
        v = out.vertices[b].double().numpy()
        np.testing.assert_allclose(out.joints_mano[b].numpy(), jreg @ v, atol=1e-6)
        # 21 keypoints = the same joints (FreiHAND order) plus fingertip vertices.
        np.testing.assert_allclose(out.joints[b].numpy(), model.joint_regressor @ v, atol=1e-6)


@pytest.mark.parametrize("joint", [1, 5, 14])
def test_single_joint_rotation_matches_numpy_lbs(right_file, params, joint):
    model = M.load_mano(right_file)
    rng = np.random.default_rng(joint)
    pose = np.zeros(45)
    pose[3 * (joint - 1): 3 * joint] = rng.normal(size=3) * 0.6
    betas = rng.normal(size=10)
    go = rng.normal(size=3) * 0.3
    tr = rng.normal(size=3) * 0.1
    want_v, want_j = numpy_lbs(params, pose, betas, go, tr)
    out = model(pose=torch.tensor(pose).reshape(1, 15, 3), shape=torch.tensor(betas)[None],
                global_orient=torch.tensor(go)[None], transl=torch.tensor(tr)[None])
    np.testing.assert_allclose(out.vertices[0].numpy(), want_v, atol=2e-6)
    np.testing.assert_allclose(out.joints_mano[0].numpy(), want_j, atol=2e-6)
    np.testing.assert_allclose(out.transforms[0, :, :3, 3].numpy(), want_j, atol=2e-6)


def test_full_random_pose_matches_numpy_lbs(right_file, params):
    model = M.load_mano(right_file)
    rng = np.random.default_rng(7)
    pose = rng.normal(size=(2, 45)) * 0.4
    outs = model(pose=torch.tensor(pose), global_orient=torch.zeros(1, 3))  # batch broadcast
    for b in range(2):
        want_v, _ = numpy_lbs(params, pose[b], np.zeros(10), np.zeros(3), np.zeros(3))
        np.testing.assert_allclose(outs.vertices[b].numpy(), want_v, atol=2e-6)


def test_pca_and_hand_mean(right_file, params):
    full = M.load_mano(right_file)
    pca = M.load_mano(right_file, use_pca=True, num_pca_comps=6)
    coeffs = np.random.default_rng(5).normal(size=(2, 6))
    pose = coeffs @ params["hands_components"][:6]
    np.testing.assert_allclose(pca(pose=torch.tensor(coeffs)).vertices.numpy(),
                               full(pose=torch.tensor(pose)).vertices.numpy(), atol=1e-6)
    with pytest.raises(ValueError, match=r"\(B,6\)"):
        pca(pose=torch.zeros(1, 15, 3))
    mean = M.load_mano(right_file, flat_hand_mean=False)
    np.testing.assert_allclose(
        mean().vertices.numpy(),
        full(pose=torch.tensor(params["hands_mean"])[None]).vertices.numpy(), atol=1e-6)
    assert not np.allclose(mean().vertices.numpy(), params["v_template"], atol=1e-3)


@pytest.mark.parametrize("convention", ["smplx", "manopth"])
@pytest.mark.parametrize("side", ["right", "left"])
def test_fingertip_conventions(tmp_path, params, convention, side):
    path = write_pickle(tmp_path / f"MANO_{side.upper()}.pkl", params)
    model = M.load_mano(path, fingertips=convention)
    tips = M.FINGERTIP_VERTEX_IDS[convention][side]
    out = model(pose=torch.tensor(np.random.default_rng(0).normal(size=(1, 45)) * 0.3))
    tip_rows = out.joints[0, [4, 8, 12, 16, 20]].numpy()  # FreiHAND thumb..pinky tips
    np.testing.assert_array_equal(tip_rows, out.vertices[0, list(tips)].numpy())
    assert tuple(model.fingertip_vertex_ids) == tips
    if convention == "manopth":
        assert tips[2] == (444 if side == "right" else 445)


def test_left_shapedirs_fix(tmp_path, params):
    path = write_pickle(tmp_path / "MANO_LEFT.pkl", params)
    left = M.load_mano(path)
    raw = M.load_mano(path, fix_left_shapedirs=False)
    right = M.load_mano(path, side="right")
    assert left.side == "left" and left.fix_left_shapedirs and not right.fix_left_shapedirs
    betas = np.random.default_rng(6).normal(size=(1, 10))
    want_v, _ = numpy_lbs(params, np.zeros(45), betas[0], np.zeros(3), np.zeros(3),
                          fix_left=True)
    np.testing.assert_allclose(left(shape=torch.tensor(betas)).vertices[0].numpy(), want_v,
                               atol=1e-6)
    # Only x moves: y and z of the fixed and unfixed left hand agree, x offsets are opposite.
    a = left(shape=torch.tensor(betas)).vertices[0].numpy() - params["v_template"]
    b = raw(shape=torch.tensor(betas)).vertices[0].numpy() - params["v_template"]
    np.testing.assert_allclose(a[:, 1:], b[:, 1:], atol=1e-6)
    np.testing.assert_allclose(a[:, 0], -b[:, 0], atol=1e-6)


def test_bad_inputs(right_file):
    model = M.load_mano(right_file)
    with pytest.raises(ValueError, match=r"pose must have shape"):
        model(pose=torch.zeros(1, 16, 3))
    with pytest.raises(ValueError, match=r"k <= 10"):
        model(shape=torch.zeros(1, 11))
    with pytest.raises(ValueError, match="inconsistent batch sizes"):
        model(pose=torch.zeros(2, 15, 3), transl=torch.zeros(3, 3))
    with pytest.raises(ValueError, match="fingertips must be one of"):
        M.load_mano(right_file, fingertips="mediapipe")


def test_same_interface_as_hand_model(right_file):
    hand = pytest.importorskip("handmesh_tutorial.hand")
    model = M.load_mano(right_file)
    ref = hand.HandModel("right")
    out, ref_out = model(), ref()
    assert type(out) is type(ref_out)
    for attr in ("faces", "template_vertices", "skinning_weights", "rest_joints", "parents",
                 "fingertip_vertex_ids", "joint_regressor", "num_vertices"):
        assert hasattr(model, attr) and hasattr(ref, attr), attr
    np.testing.assert_array_equal(model.parents[1:], np.asarray(hand.MANO_PARENTS)[1:])
    assert model.joint_regressor.shape == (21, 778)


@pytest.mark.parametrize("side", ["right", "left"])
def test_open_hand_in_mano_format_matches_hand_model(tmp_path, side):
    hand = pytest.importorskip("handmesh_tutorial.hand")
    from handmesh_tutorial import lcs

    ref = hand.HandModel(side)
    # the library's MANO-format writer (handmesh_tutorial.testing), as a user's test would use it
    path = write_mano_pickle(tmp_path / f"MANO_{side.upper()}.pkl", side)
    model = M.load_mano(path, fingertips=tuple(ref.fingertip_vertex_ids))
    assert model.side == side and model.num_vertices == 778 == ref.num_vertices - 1
    skin = ref.faces[~ref.template.cap_faces]   # the hand without its wrist cap: MANO-like
    np.testing.assert_array_equal(model.faces, skin)
    rng = np.random.default_rng(2)
    pose = torch.tensor(rng.normal(size=(3, 15, 3)) * 0.3, dtype=torch.float32)
    go = torch.tensor(rng.normal(size=(3, 3)) * 0.5, dtype=torch.float32)
    tr = torch.tensor(rng.normal(size=(3, 3)) * 0.1, dtype=torch.float32)
    shape = torch.tensor(rng.normal(size=(3, ref.num_shape_params)), dtype=torch.float32)
    kw = dict(pose=pose, global_orient=go, transl=tr, shape=shape)
    a, b = model(**kw), ref(**kw)
    # the same hand, shape space included (the left file's shapedirs quirk undone by default)
    np.testing.assert_allclose(a.vertices.numpy(), b.vertices.numpy()[:, :778], atol=2e-6)
    for name in ("joints", "joints_mano", "transforms"):
        np.testing.assert_allclose(getattr(a, name).numpy(), getattr(b, name).numpy(),
                                   atol=2e-6, err_msg=name)
    # the LCS construction only needs the HandModel interface
    np.testing.assert_allclose(lcs.hand_lcs(model).frames, lcs.hand_lcs(ref).frames, atol=1e-5)
    np.testing.assert_allclose(model.rest_keypoints, ref.rest_keypoints, atol=1e-6)
    # estimated limb radii vs the open hand's capsule radii (independent construction)
    np.testing.assert_allclose(model.bone_radii, ref.bone_radii, rtol=0.15)
    colors = model.vertex_colors(tone=2, rng=0)
    assert colors.shape == (model.num_vertices, 3) and 0 <= colors.min() <= colors.max() <= 1


def test_mano_format_params_have_the_official_layout():
    """The testing module's MANO-format arrays: every key the loader needs with the official
    files' shapes and types (sparse J_regressor, uint32 faces, 2**32 - 1 as the root parent),
    and the left file's shapedirs quirk (x column negated against the true left hand)."""
    right, left = mano_format_params("right"), mano_format_params("left")
    for key, shape in M.MANO_KEYS.items():
        want = tuple(778 if e == "V" else e for e in shape)
        got = right[key].shape
        assert all(w is None or w == g for w, g in zip(want, got, strict=True)), (key, got)
    assert sp.issparse(right["J_regressor"]) and right["f"].dtype == np.uint32
    assert right["kintree_table"][0, 0] == 2**32 - 1 and right["shapedirs"].shape[2] == 10
    ref = pytest.importorskip("handmesh_tutorial.hand").HandModel("left").template
    np.testing.assert_allclose(left["shapedirs"][:, 1:, :6], ref.shape_dirs[:778, 1:], atol=1e-7)
    np.testing.assert_allclose(left["shapedirs"][:, 0, :6], -ref.shape_dirs[:778, 0], atol=1e-7)
    with pytest.raises(ValueError, match="side must be"):
        mano_format_params("both")
