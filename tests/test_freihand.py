"""Tests of handmesh_tutorial.data.freihand on tiny fixtures in the official FreiHAND layout."""

import json
import zipfile

import numpy as np
import pytest
from PIL import Image

from handmesh_tutorial import metrics
from handmesh_tutorial.data import freihand as fh

N = 3  # unique samples in the fixture


def write_json(path, data):
    with open(path, "w") as f:
        json.dump(data, f)


@pytest.fixture
def data(tmp_path):
    """A 3-sample FreiHAND tree: training (4 versions -> 12 images, 3 masks) and evaluation."""
    rng = np.random.default_rng(0)
    arrays = {}
    for split, n_images in (("training", 4 * N), ("evaluation", N)):
        K = np.tile(np.array([[500.0, 0, 112], [0, 500.0, 112], [0, 0, 1]]), (N, 1, 1))
        K[:, 0, 0] += np.arange(N)  # distinguishable per sample
        xyz = rng.normal(size=(N, 21, 3)) * 0.03 + [0, 0, 0.6]
        verts = rng.normal(size=(N, 778, 3)) * 0.03 + [0, 0, 0.6]
        mano = rng.normal(size=(N, 1, 61))  # official nesting [[...61]]
        scale = rng.uniform(0.02, 0.04, size=N)
        arrays[split] = dict(K=K, xyz=xyz, verts=verts, mano=mano, scale=scale)
        for key, arr in arrays[split].items():
            write_json(tmp_path / f"{split}_{key}.json", arr.tolist())
        (tmp_path / split / "rgb").mkdir(parents=True)
        for i in range(n_images):
            img = np.full((8, 10, 3), i * 10, dtype=np.uint8)  # image id encoded in the pixels
            Image.fromarray(img).save(tmp_path / split / "rgb" / f"{i:08d}.jpg", quality=100)
    (tmp_path / "training" / "mask").mkdir()
    for i in range(N):
        Image.fromarray(np.full((8, 10), 255, np.uint8)).save(
            tmp_path / "training" / "mask" / f"{i:08d}.jpg")
    return tmp_path, arrays


@pytest.fixture
def root(data):
    return data[0]


def image_id(sample):
    return round(float(sample["image"].mean()) / 10)


def test_training_indexing_uses_annotation_i_mod_n(data):
    root, arrays = data
    ds = fh.FreiHAND(root, "training")
    assert len(ds) == 4 * N
    a = arrays["training"]
    for i in range(len(ds)):
        s = ds[i]
        assert image_id(s) == i  # image file i ...
        assert s["annotation_index"] == i % N  # ... shows unique sample i % N
        assert s["version"] == fh.SAMPLE_VERSIONS[i // N]
        np.testing.assert_array_equal(s["joints"], a["xyz"][i % N])
        np.testing.assert_array_equal(s["vertices"], a["verts"][i % N])
        np.testing.assert_array_equal(s["K"], a["K"][i % N])
        np.testing.assert_array_equal(s["mano"], a["mano"][i % N, 0])
        assert s["scale"] == a["scale"][i % N]
        assert s["image"].dtype == np.uint8 and s["image"].shape == (8, 10, 3)
    assert ds[-1]["index"] == len(ds) - 1
    with pytest.raises(IndexError, match="out of range"):
        ds[len(ds)]


def test_version_subset_and_shapes(root):
    ds = fh.FreiHAND(root, "training", versions=("hom", "auto"))
    assert len(ds) == 2 * N
    assert image_id(ds[0]) == N and image_id(ds[N]) == 3 * N  # hom block, then auto block
    s = ds[1]
    assert s["joints"].shape == (21, 3) and s["vertices"].shape == (778, 3)
    assert s["mano"].shape == (61,) and s["K"].shape == (3, 3)
    assert ds.load_mask(N + 1).shape == (8, 10)
    with pytest.raises(ValueError, match="versions"):
        fh.FreiHAND(root, "training", versions=("sepia",))


def test_evaluation_split_and_optional_files(root):
    ds = fh.FreiHAND(root, "evaluation")
    assert len(ds) == N and image_id(ds[2]) == 2
    (root / "evaluation_verts.json").unlink()
    (root / "evaluation_mano.json").unlink()
    (root / "evaluation_xyz.json").unlink()
    s = fh.FreiHAND(root, "evaluation")[0]  # v1 release: K and scale only
    assert s["vertices"] is None and s["mano"] is None and s["joints"] is None
    assert s["K"].shape == (3, 3)
    with pytest.raises(ValueError, match="only for the training split"):
        ds.mask_path(0)
    with pytest.raises(ValueError, match="versions"):
        fh.FreiHAND(root, "evaluation", versions=("hom",))


def test_annotations_are_loaded_once(root, monkeypatch):
    ds = fh.FreiHAND(root, "training")
    calls = []
    real = fh._read_json
    monkeypatch.setattr(fh, "_read_json", lambda p: calls.append(p.name) or real(p))
    for i in range(len(ds)):
        ds[i]
    assert sorted(calls) == sorted(f"training_{k}.json" for k in ("K", "xyz", "verts", "mano",
                                                                  "scale"))


def test_missing_required_file_is_named(root):
    (root / "training_xyz.json").unlink()
    with pytest.raises(FileNotFoundError, match="training_xyz.json"):
        fh.FreiHAND(root, "training")
    with pytest.raises(FileNotFoundError, match="root directory"):
        fh.FreiHAND(root / "nope", "training")
    with pytest.raises(ValueError, match="split"):
        fh.FreiHAND(root, "test")


def test_missing_image_is_named(root):
    (root / "training" / "rgb" / "00000005.jpg").unlink()
    with pytest.raises(FileNotFoundError, match="00000005.jpg"):
        fh.FreiHAND(root, "training")[5]
    (root / "training" / "rgb" / "00000004.jpg").write_bytes(b"not a jpeg")
    with pytest.raises(ValueError, match="00000004.jpg.*decode"):
        fh.FreiHAND(root, "training")[4]


def test_truncated_json_is_named(root):
    path = root / "training_verts.json"
    path.write_text(path.read_text()[:1000])
    ds = fh.FreiHAND(root, "training")
    with pytest.raises(ValueError, match="training_verts.json.*not valid JSON"):
        ds[0]


def test_wrong_shape_names_file_sample_and_expected_shape(data):
    root, arrays = data
    xyz = arrays["training"]["xyz"].tolist()
    xyz[2] = xyz[2][:20]  # sample 2 has 20 keypoints
    write_json(root / "training_xyz.json", xyz)
    with pytest.raises(ValueError, match=r"training_xyz.json: sample 2 has shape \(20, 3\), "
                                         r"expected \(21, 3\)"):
        fh.FreiHAND(root, "training")[0]


@pytest.mark.parametrize("key, index, value, pattern", [
    ("xyz", (1, 4, 2), float("nan"), r"training_xyz\.json: sample 1 holds NaN or infinity"),
    ("verts", (2, 7, 0), float("inf"), r"training_verts\.json: sample 2 holds NaN or infinity"),
    ("xyz", (0, 0, 0), 1e308, r"training_xyz\.json: sample 0 holds 1e\+308, beyond"),
    ("K", (2, 1, 1), 0.0, r"training_K\.json: sample 2 has a singular intrinsic matrix"),
])
def test_non_finite_absurd_or_singular_values_are_named(data, key, index, value, pattern):
    root, arrays = data
    arr = np.array(arrays["training"][key], dtype=np.float64)
    arr[index] = value
    (root / f"training_{key}.json").write_text(json.dumps(arr.tolist()))  # NaN/Infinity tokens
    with pytest.raises(ValueError, match=pattern):
        fh.FreiHAND(root, "training")[0]


def test_length_mismatch_between_files(root):
    write_json(root / "training_scale.json", [0.03] * (N + 1))
    with pytest.raises(ValueError, match="training_scale.json has 4 samples.*training_K.json"):
        fh.FreiHAND(root, "training")[0]


def test_project_matches_manual_pinhole():
    K = np.array([[500.0, 0, 100], [0, 400.0, 50], [0, 0, 1]])
    pts = np.array([[0.1, -0.2, 0.5], [0.0, 0.0, 2.0]])
    expect = np.array([[500 * 0.1 / 0.5 + 100, 400 * -0.2 / 0.5 + 50], [100, 50]])
    np.testing.assert_allclose(fh.project(pts, K), expect)
    import torch

    out = fh.project(torch.tensor(pts[None]), torch.tensor(K[None]))
    assert isinstance(out, torch.Tensor) and out.shape == (1, 2, 2)
    np.testing.assert_allclose(out[0].numpy(), expect)
    with pytest.raises(ValueError, match="K"):
        fh.project(pts, np.eye(4))


def test_prediction_round_trip_and_official_format(tmp_path):
    rng = np.random.default_rng(1)
    j, v = rng.normal(size=(N, 21, 3)), rng.normal(size=(N, 778, 3))
    path = fh.write_predictions(tmp_path / "pred.json", j, v.astype(np.float32))
    raw = json.loads(path.read_text())
    # [xyz_list, verts_list], per sample a list of [x, y, z]
    assert len(raw) == 2 and len(raw[0]) == N and len(raw[1]) == N
    assert len(raw[0][0]) == 21 and raw[0][0][0] == list(j[0, 0])
    assert len(raw[1][0]) == 778 and len(raw[1][0][0]) == 3
    j2, v2 = fh.load_predictions(path)
    np.testing.assert_array_equal(j2, j)  # float64 survives JSON exactly
    np.testing.assert_array_equal(v2, v.astype(np.float32).astype(np.float64))
    assert not list(tmp_path.glob("*.tmp"))  # atomic write leaves no temp file
    zpath = fh.zip_predictions(path)
    with zipfile.ZipFile(zpath) as zf:
        assert zf.namelist() == ["pred.json"]


def test_prediction_errors(tmp_path):
    with pytest.raises(ValueError, match=r"joints must have shape \(N,21,3\)"):
        fh.write_predictions(tmp_path / "p.json", np.zeros((2, 20, 3)), np.zeros((2, 778, 3)))
    with pytest.raises(ValueError, match="2 samples but vertices has 3"):
        fh.write_predictions(tmp_path / "p.json", np.zeros((2, 21, 3)), np.zeros((3, 778, 3)))
    assert not (tmp_path / "p.json").exists()
    bad = tmp_path / "bad.json"
    write_json(bad, [[np.zeros((21, 3)).tolist()]])
    with pytest.raises(ValueError, match="list of two lists"):
        fh.load_predictions(bad)
    write_json(bad, [[np.zeros((21, 3)).tolist()], [np.zeros((778, 2)).tolist()]])
    with pytest.raises(ValueError, match="expected \\(V, 3\\)"):
        fh.load_predictions(bad)
    bad.write_text("[[[0.1, 0.2")
    with pytest.raises(ValueError, match="bad.json.*not valid JSON"):
        fh.load_predictions(bad)
    with pytest.raises(FileNotFoundError, match="missing.json"):
        fh.load_predictions(tmp_path / "missing.json")


@pytest.mark.parametrize("num_vertices", [779, 777, 49])
def test_write_predictions_refuses_a_non_mano_vertex_count(tmp_path, num_vertices):
    """Our template has 779 vertices; FreiHAND's evaluation expects MANO's 778 and could not
    score such a file: refuse it, saying why, and write nothing."""
    with pytest.raises(ValueError, match=rf"{num_vertices} vertices.*MANO's 778"):
        fh.write_predictions(tmp_path / "pred.json", np.zeros((2, 21, 3)),
                             np.zeros((2, num_vertices, 3)))
    assert not any(tmp_path.iterdir())
    fh.write_predictions(tmp_path / "pred.json", np.zeros((2, 21, 3)), np.zeros((2, 778, 3)))


def test_a_779_vertex_refusal_says_what_to_do_instead(tmp_path):
    """The library's own hand (779 vertices) cannot be submitted; the message names the way:
    a MANO template for training, or joints-only scoring, and why dropping the cap is no fix."""
    with pytest.raises(ValueError) as err:
        fh.write_predictions(tmp_path / "pred.json", np.zeros((1, 21, 3)), np.zeros((1, 779, 3)))
    msg = str(err.value)
    assert "--template MANO_RIGHT.pkl" in msg and "pred_verts=None" in msg
    assert "wrist-cap vertex gives 778 vertices, not MANO's" in msg


def test_evaluate_predictions_equals_freihand_scores(data, tmp_path):
    root, arrays = data
    a = arrays["evaluation"]
    rng = np.random.default_rng(2)
    pj = a["xyz"] + rng.normal(size=a["xyz"].shape) * 0.005
    pv = a["verts"] + rng.normal(size=a["verts"].shape) * 0.005
    path = fh.write_predictions(tmp_path / "pred.json", pj, pv)
    got = fh.evaluate_predictions(path, root)
    expect = metrics.freihand_scores(pred_joints=pj, gt_joints=a["xyz"], pred_verts=pv,
                                     gt_verts=a["verts"])
    assert got == expect
    assert got["pa_mpjpe"] > 1.0  # mm: the noise is visible
    fh.write_predictions(tmp_path / "short.json", pj[:2], pv[:2])
    with pytest.raises(ValueError, match="2 samples"):
        fh.evaluate_predictions(tmp_path / "short.json", root)


def _jpeg_declaring(width, height):
    """A valid small JPEG whose frame header (SOF0) declares ``width`` x ``height``."""
    import io
    import struct

    buf = io.BytesIO()
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(buf, format="JPEG")
    data = bytearray(buf.getvalue())
    sof = data.index(b"\xff\xc0")
    data[sof + 5:sof + 9] = struct.pack(">HH", height, width)
    return bytes(data)


@pytest.mark.parametrize("side, pattern", [(20_000, "DecompressionBombError|exceeds limit"),
                                           (10_000, "could be decompression bomb"),
                                           (5_000, "5000 x 5000 pixels, over 4096 a side")])
def test_a_jpeg_bomb_is_refused_before_decoding_and_named(root, side, pattern):
    from handmesh_tutorial.data import MAX_IMAGE_SIZE, torch_views

    assert fh._MAX_IMAGE_SIDE == MAX_IMAGE_SIZE  # one limit for both readers
    path = root / "training" / "rgb" / "00000001.jpg"
    path.write_bytes(_jpeg_declaring(side, side))
    with pytest.raises(ValueError, match=f"00000001.jpg.*({pattern})"):
        fh.FreiHAND(root, "training")[1]
    ds = torch_views.FreiHANDTorchDataset(root, image_size=16, train=False)
    bad = torch_views.find_bad_items(ds)  # --skip-bad: named by the image's id
    assert [(b["position"], b["sample"]) for b in bad] == [(1, "00000001")]
