"""Tests of handmesh_tutorial.data.augment: crops, K, mirroring, augmentation, normalisation."""

import functools
import json

import numpy as np
import pytest
import torch
from PIL import Image

from handmesh_tutorial.data import InterSHDataset, generate_dataset
from handmesh_tutorial.data import augment as A
from handmesh_tutorial.data import torch_views as TV
from handmesh_tutorial.render.camera import project
from handmesh_tutorial.testing import toy_sample

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def toy_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("toy_intersh")
    generate_dataset(root, functools.partial(toy_sample, image_size=96), num=4, seed=3,
                     kind="hand-hand", progress=False, durable=False)
    return root


def _raw(seed=0, side="right", size=160):
    s = toy_sample(seed, image_size=size, side=side)
    t = s["target"]
    return s["image"], s["K"], s["meshes"][t][0], s["joints"][t], s["sides"][t], s["vr"][t]


def _disc(size, center, radius=5.0):
    """Anti-aliased disc (H, W) in [0, 1] centred at a sub-pixel (u, v)."""
    v, u = np.mgrid[0:size, 0:size].astype(np.float64)
    d = np.hypot(u - center[0], v - center[1])
    return np.clip(radius - d + 0.5, 0.0, 1.0)


def _centroid(channel):
    w = channel.astype(np.float64)
    v, u = np.mgrid[0:w.shape[0], 0:w.shape[1]]
    return np.array([(w * u).sum() / w.sum(), (w * v).sum() / w.sum()])


def test_normalisation_matches_paper_and_round_trips():
    img = np.random.default_rng(0).integers(0, 256, (5, 7, 3), dtype=np.uint8)
    t = A.normalize_image(img)
    assert t.shape == (3, 5, 7) and t.dtype == torch.float32
    np.testing.assert_allclose(t.numpy(), img.transpose(2, 0, 1) / 255.0 - 0.5, atol=1e-7)
    assert np.array_equal(A.denormalize_image(t), img)
    batch = A.normalize_image(np.stack([img, img]))
    assert batch.shape == (2, 3, 5, 7)
    with pytest.raises(ValueError, match="image must be"):
        A.normalize_image(np.zeros((5, 7)))


def test_flip_intrinsics_reprojects_mirrored_points_with_skew():
    rng = np.random.default_rng(1)
    K = np.array([[210.0, 3.5, 61.3], [0.0, 190.0, 47.9], [0.0, 0.0, 1.0]])
    pts = np.c_[rng.uniform(-0.1, 0.1, (30, 2)), rng.uniform(0.3, 0.8, 30)]
    W = 128
    uv = project(pts, K)
    uv_f = project(pts * [-1, 1, 1], A.flip_intrinsics(K, W))
    np.testing.assert_allclose(uv_f[:, 0], W - 1 - uv[:, 0], atol=1e-9)
    np.testing.assert_allclose(uv_f[:, 1], uv[:, 1], atol=1e-9)
    Kf = A.flip_intrinsics(K, W)
    assert Kf[0, 2] == pytest.approx(W - 1 - 61.3) and Kf[0, 1] == pytest.approx(-3.5)
    np.testing.assert_allclose(A.flip_intrinsics(Kf, W), K, atol=1e-12)


def test_crop_transform_maps_box_edges_to_crop_edges():
    a = A.crop_transform((40.0, 30.0), 20.0, 64)
    lo = a @ [30.0, 20.0, 1.0]
    hi = a @ [50.0, 40.0, 1.0]
    np.testing.assert_allclose(lo[:2], [-0.5, -0.5])
    np.testing.assert_allclose(hi[:2], [63.5, 63.5])
    with pytest.raises(ValueError, match="positive"):
        A.crop_transform((0, 0), 0.0, 8)


def test_warp_identity_and_integer_shift_are_exact():
    img = torch.rand(3, 12, 12, generator=torch.Generator().manual_seed(0))
    same = A.warp_image(img, np.eye(3), 12)
    torch.testing.assert_close(same, img, atol=1e-6, rtol=0)
    shift = np.array([[1.0, 0, -3], [0, 1.0, -2], [0, 0, 1.0]])  # output (u, v) = src - (3, 2)
    out = A.warp_image(img, shift, 6)
    torch.testing.assert_close(out, img[:, 2:8, 3:9], atol=1e-6, rtol=0)
    # shrinking by 2 with 2x supersampling = 2x2 block means
    half = A.warp_image(img, A.crop_transform((5.5, 5.5), 12, 6), 6)
    torch.testing.assert_close(half, torch.nn.functional.avg_pool2d(img[None], 2)[0],
                               atol=1e-6, rtol=0)
    with pytest.raises(ValueError, match="affine"):
        A.warp_image(img, np.ones((3, 3)), 4)


@pytest.mark.parametrize("side", ["right", "left"])
def test_markers_at_projected_joints_stay_at_projection_after_augmentation(side):
    image, K, verts, joints, _, vr = _raw(seed=5, side=side, size=256)
    markers = (0, 9, 20)  # wrist, middle MCP, pinky tip: one colour channel each
    uv = project(joints[list(markers)], K)
    canvas = np.stack([_disc(256, uv[c]) for c in range(3)], -1)
    img = (255 * canvas).round().astype(np.uint8)
    ds = TV.HandCropDataset(image_size=64, augment=A.AugmentConfig.geometric())
    checked = 0
    for seed in range(6):
        item = ds.make_item(img, K, verts, joints, side, vr, np.random.default_rng(seed))
        out = A.denormalize_image(item["image"])
        kc = item["K"].double().numpy()
        assert kc[1, 0] == 0 and kc[2, 0] == 0 and kc[2, 1] == 0 and kc[2, 2] == 1
        proj = project((item["joints"] + item["root"]).double().numpy(), kc)
        for c, j in enumerate(markers):
            if not (4 <= proj[j]).all() or not (proj[j] <= 59).all():
                continue  # the shift moved this marker off the crop
            np.testing.assert_allclose(_centroid(out[..., c]), proj[j], atol=0.3)
            checked += 1
    assert checked >= 12
    assert bool(item["mirrored"]) == (side == "left")


def test_3d_targets_are_a_rotation_about_the_optical_axis_and_round_trip():
    image, K, verts, joints, side, vr = _raw(seed=2, side="left")
    ds = TV.HandCropDataset(image_size=48)
    item = ds.make_item(image, K, verts, joints, side, vr, np.random.default_rng(7))
    R = item["R"].double()
    torch.testing.assert_close(R @ R.T, torch.eye(3, dtype=torch.float64), atol=1e-6, rtol=0)
    assert R[2, 2] == pytest.approx(1.0) and torch.linalg.det(R) == pytest.approx(1.0)
    assert abs(R[0, 1]) > 1e-3  # a real rotation was drawn
    cam = (item["joints"] + item["root"]).double().numpy()
    np.testing.assert_allclose(cam[:, 2], joints[:, 2], atol=1e-6)  # z is untouched
    np.testing.assert_allclose(item["joints"][9].numpy(), 0.0, atol=1e-7)
    back_j = A.to_camera(item["joints"][None], {k: item[k][None] for k in ("root", "R",
                                                                           "mirrored")})
    back_v = A.to_camera(item["vertices"], item)
    np.testing.assert_allclose(back_j[0].numpy(), joints, atol=1e-6)
    np.testing.assert_allclose(back_v.numpy(), verts, atol=1e-6)


def test_left_target_equals_independently_flipped_right_target():
    image, K, verts, joints, _, vr = _raw(seed=4, side="left", size=120)
    W = image.shape[1]
    K_flip = K.copy()
    K_flip[0, 2] = W - 1 - K[0, 2]  # independent: fx, fy, cy unchanged, no skew here
    ds = TV.HandCropDataset(image_size=40, train=False)
    left = ds.make_item(image, K, verts, joints, "left", vr, None)
    right = ds.make_item(image[:, ::-1], K_flip, verts * [-1, 1, 1], joints * [-1, 1, 1],
                         "right", vr, None)
    assert bool(left["mirrored"]) and not bool(right["mirrored"])
    for key in ("image", "vertices", "joints", "root", "K"):
        torch.testing.assert_close(left[key], right[key], atol=1e-5, rtol=1e-6)
    np.testing.assert_allclose(A.unmirror(left["vertices"] + left["root"], True).numpy(), verts,
                               atol=1e-6)


def test_unmirror_per_sample_flags():
    p = torch.ones(3, 4, 3)
    out = A.unmirror(p, torch.tensor([True, False, True]))
    assert (out[0, :, 0] == -1).all() and (out[1, :, 0] == 1).all() and (out[2, :, 0] == -1).all()
    assert (out[..., 1:] == 1).all()
    assert torch.equal(A.unmirror(out, torch.tensor([True, False, True])), p)
    with pytest.raises(ValueError, match="flags"):
        A.unmirror(p, torch.tensor([True]))


def test_color_jitter_identity_grey_and_luma():
    img = torch.rand(3, 8, 8, generator=torch.Generator().manual_seed(1)) * 0.8 + 0.1
    torch.testing.assert_close(A.color_jitter(img), img)
    grey = A.color_jitter(img, saturation=0.0)
    torch.testing.assert_close(grey[0], grey[1]) and torch.testing.assert_close(grey[1], grey[2])
    luma = torch.tensor([0.299, 0.587, 0.114])[:, None, None]
    hued = A.color_jitter(img, hue=0.1)
    assert not torch.allclose(hued, img, atol=1e-3)
    # a hue rotation keeps the luma (Y of YIQ) where nothing clipped
    inside = ((hued > 0) & (hued < 1)).all(0)
    torch.testing.assert_close((hued * luma).sum(0)[inside], (img * luma).sum(0)[inside],
                               atol=1e-5, rtol=0)
    torch.testing.assert_close(A.color_jitter(img, brightness=0.5), img * 0.5)


def test_dataset_on_disk_items_determinism_and_collate(toy_root):
    raw = InterSHDataset(toy_root)
    ds = TV.InterSHTorchDataset(toy_root, image_size=32, seed=1)
    assert len(ds) == 4
    a, b = ds[2], TV.InterSHTorchDataset(toy_root, image_size=32, seed=1)[2]
    for k in a:
        assert torch.equal(a[k], b[k]), k
    ds.set_epoch(1)
    c = ds[2]
    assert not torch.equal(a["image"], c["image"]) and not torch.equal(a["R"], c["R"])
    ds.set_epoch(0)
    assert torch.equal(ds[2]["image"], a["image"])
    other = TV.InterSHTorchDataset(toy_root, image_size=32, seed=2)[2]
    assert not torch.equal(other["image"], a["image"])
    ev = TV.InterSHTorchDataset(toy_root, image_size=32, train=False)
    e0, e1 = ev[1], ev[1]
    assert torch.equal(e0["image"], e1["image"]) and torch.equal(e0["R"], torch.eye(3))
    s = raw[1]
    assert float(e0["vr"]) == pytest.approx(s["vr"][s["target"]], abs=1e-6)
    assert bool(e0["mirrored"]) == (s["sides"][s["target"]] == "left")
    np.testing.assert_allclose(ev.vr_values(), raw.vr_table())
    batch = next(iter(torch.utils.data.DataLoader(ds, batch_size=3)))
    assert batch["image"].shape == (3, 3, 32, 32) and batch["vertices"].shape == (3, 779, 3)
    sub = TV.InterSHTorchDataset(toy_root, image_size=32, indices=[3, 1], train=False)
    assert len(sub) == 2 and int(sub[0]["index"]) == 3
    np.testing.assert_allclose(sub.vr_values(), raw.vr_table()[[3, 1]])
    with pytest.raises(IndexError):
        sub[2]


def test_in_memory_samples_and_bad_input():
    samples = [toy_sample(i, image_size=48) for i in range(2)]
    ds = TV.InterSHTorchDataset(samples, image_size=24, train=False)
    assert ds[1]["image"].shape == (3, 24, 24)
    base = TV.HandCropDataset(image_size=8)
    image, K, verts, joints, _, vr = _raw(seed=0)
    with pytest.raises(ValueError, match="side"):
        base.make_item(image, K, verts, joints, "middle", vr, None)
    with pytest.raises(ValueError, match="uint8"):
        base.make_item(image.astype(np.float32), K, verts, joints, "left", vr, None)
    with pytest.raises(ValueError, match="crop"):
        TV.HandCropDataset(crop="square")


def test_freihand_dataset_full_crop(tmp_path):
    rng = np.random.default_rng(0)
    K = np.array([[400.0, 0.0, 111.5], [0.0, 400.0, 111.5], [0.0, 0.0, 1.0]])
    xyz = np.c_[rng.uniform(-0.05, 0.05, (21, 2)), rng.uniform(0.55, 0.65, 21)]
    verts = np.c_[rng.uniform(-0.05, 0.05, (778, 2)), rng.uniform(0.55, 0.65, 778)]
    for key, val in (("K", K), ("xyz", xyz), ("verts", verts)):
        (tmp_path / f"training_{key}.json").write_text(json.dumps([val.tolist()] * 2))
    (tmp_path / "training" / "rgb").mkdir(parents=True)
    uv = project(xyz[9:10], K)[0]
    img = (255 * np.repeat(_disc(224, uv, 6.0)[..., None], 3, -1)).astype(np.uint8)
    for i in range(2):
        Image.fromarray(img).save(tmp_path / "training" / "rgb" / f"{i:08d}.png", format="PNG")
        (tmp_path / "training" / "rgb" / f"{i:08d}.png").rename(
            tmp_path / "training" / "rgb" / f"{i:08d}.jpg")  # lossless content, .jpg name
    ds = TV.FreiHANDTorchDataset(tmp_path, image_size=56, versions="gs",
                                augment=A.AugmentConfig.geometric(), seed=3)
    assert len(ds) == 2
    item = ds[1]
    assert torch.isnan(item["vr"]) and not bool(item["mirrored"])
    assert item["vertices"].shape == (778, 3)
    proj = project(item["root"][None].double(), item["K"].double())[0].numpy()
    np.testing.assert_allclose(_centroid(A.denormalize_image(item["image"])[..., 0]), proj,
                               atol=0.3)
    ev = TV.FreiHANDTorchDataset(tmp_path, image_size=56, versions="gs", train=False)[0]
    # full crop, no augmentation: the 224 image scaled by 56/224 exactly
    np.testing.assert_allclose(ev["K"][:2].numpy(), (A.crop_transform((111.5, 111.5), 224, 56)
                                                     @ K)[:2], rtol=1e-6)
    (tmp_path / "training_verts.json").unlink()
    with pytest.raises(ValueError, match="no vertices"):
        TV.FreiHANDTorchDataset(tmp_path, versions="gs")


def test_torch_views_are_reexported_lazily_and_dataset_stays_torch_free():
    import subprocess
    import sys

    from handmesh_tutorial import data as D

    for name in ("HandCropDataset", "InterSHTorchDataset", "FreiHANDTorchDataset", "BadSampleError",
                 "BAD_SAMPLE_ERRORS", "find_bad_items", "without_items", "drop_bad_items"):
        assert getattr(A, name) is getattr(D, name) is getattr(TV, name), name
    with pytest.raises(AttributeError):
        A.NoSuchName  # noqa: B018
    code = ("import sys, handmesh_tutorial.data as D; assert 'torch' not in sys.modules; "
            "D.InterSHTorchDataset; assert 'torch' in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)
