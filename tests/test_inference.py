"""The inference helper for one's own image: the evaluation crop and numbers, left = mirrored right,
the hand placed with K, and a message for every input it cannot interpret."""

import numpy as np
import pytest
import torch
from PIL import Image

import handmesh_tutorial as hmt
from handmesh_tutorial import inference as I
from handmesh_tutorial.data.augment import flip_intrinsics, unmirror
from handmesh_tutorial.data.torch_views import InterSHTorchDataset
from handmesh_tutorial.render.camera import intrinsics, project
from handmesh_tutorial.testing import toy_sample

torch.set_num_threads(1)
SIZE = 32  # the tiny network's crop side


@pytest.fixture(scope="module")
def net():
    """A tiny untrained network with the shipped one's heads (2D keypoints, rotation, skinned)."""
    torch.manual_seed(0)
    return hmt.nn.model.build_model("resnet10", channels=(4, 4, 8, 8, 8), latent_channels=8,
                                 keypoints=True, global_rotation=True, output="skinned").eval()


@pytest.fixture(scope="module")
def samples():
    return [toy_sample(i, image_size=96, side=side) for i, side in enumerate(("left", "right"))]


def _box(s):
    uv = project(s["meshes"][s["target"]][0], s["K"])
    return (*uv.min(0), *uv.max(0))


def test_crops_and_predictions_equal_the_evaluation_path(net, samples):
    ds = InterSHTorchDataset(samples, SIZE, train=False)
    ev = hmt.train.evaluate(net, dataset=ds, camera_frame=True, baseline=False, progress=False)
    preds = I.predict_hands(samples[0]["image"], [_box(samples[0])], "left", model=net,
                            image_size=SIZE) + \
        [I.predict_hand(samples[1]["image"], _box(samples[1]), "right", model=net,
                        image_size=SIZE)]
    for i, (s, p) in enumerate(zip(samples, preds, strict=True)):
        item = ds[i]
        assert p.crop.mirrored == bool(item["mirrored"]) == (s["sides"][1] == "left")
        assert torch.allclose(p.crop.image, item["image"], atol=1e-6)
        # the evaluation's camera frame adds the true root; the helper's root-relative frame not
        root = unmirror(item["root"].double().numpy(), bool(item["mirrored"]))
        assert p.frame == "root-relative" and p.root is None
        np.testing.assert_allclose(p.joints, ev["predictions"]["joints"][i] - root, atol=1e-6)
        np.testing.assert_allclose(p.vertices, ev["predictions"]["vertices"][i] - root,
                                   atol=1e-6)
        crop_k = I.crop_hand(s["image"], _box(s), s["sides"][1], image_size=SIZE, K=s["K"]).K
        np.testing.assert_allclose(crop_k, item["K"].double().numpy(), rtol=1e-6)


def test_a_float_image_in_0_255_and_a_png_file_give_the_uint8_array_s_crop(net, samples,
                                                                         tmp_path):
    s = samples[0]
    want = I.crop_hand(s["image"], _box(s), "left", image_size=SIZE).image
    f = I.crop_hand(s["image"].astype(np.float64), _box(s), "left", image_size=SIZE).image
    assert torch.equal(f, want)
    Image.fromarray(s["image"]).save(tmp_path / "hand.png")
    rgba = np.concatenate([s["image"], np.full((*s["image"].shape[:2], 1), 7, np.uint8)], -1)
    Image.fromarray(rgba).save(tmp_path / "rgba.png")  # a file's alpha is dropped by its mode
    for name in ("hand.png", "rgba.png"):
        assert torch.equal(I.crop_hand(tmp_path / name, _box(s), "left", image_size=SIZE).image,
                           want)


def test_a_left_hand_is_the_mirrored_right_hand(samples):
    s = samples[1]
    img, K, (x0, y0, x1, y1) = s["image"], s["K"], _box(s)
    w = img.shape[1]
    right = I.predict_hand(img, (x0, y0, x1, y1), "right", K=K)  # the shipped network
    left = I.predict_hand(img[:, ::-1], (w - 1 - x1, y0, w - 1 - x0, y1), "left",
                          K=flip_intrinsics(K, w))
    assert torch.allclose(left.crop.image, right.crop.image, atol=1e-6)
    mirror = np.array([-1.0, 1.0, 1.0])
    np.testing.assert_allclose(left.vertices, right.vertices * mirror, atol=1e-6)
    np.testing.assert_allclose(left.joints, right.joints * mirror, atol=1e-6)
    np.testing.assert_allclose(left.keypoints_2d[:, 0], w - 1 - right.keypoints_2d[:, 0],
                               atol=1e-6)
    np.testing.assert_array_equal(left.faces, right.faces[:, ::-1])  # outward normals kept


def test_the_root_is_the_translation_that_projects_the_joints_onto_the_keypoints():
    rng = np.random.default_rng(0)
    joints = rng.normal(0, 0.04, (3, 21, 3))
    t = np.array([[0.05, -0.02, 0.6], [-0.1, 0.08, 0.9], [0.0, 0.0, 0.35]])
    K = intrinsics(300.0, 310.0, 60.0, 70.0)
    uv = project(joints + t[:, None], K)
    np.testing.assert_allclose(I.root_from_keypoints(joints, uv, K), t, atol=1e-9)
    np.testing.assert_allclose(I.root_from_keypoints(joints[1], uv[1], K), t[1], atol=1e-9)


def test_with_k_the_hand_is_placed_where_its_keypoints_are(samples):
    s = samples[0]
    p = I.predict_hand(s["image"], _box(s), "left", K=s["K"])
    assert p.frame == "camera" and p.root[2] > 0
    np.testing.assert_allclose(p.root, p.joints[9])
    t = I.root_from_keypoints(unmirror(p.joints - p.root, True),
                              p.keypoints_2d * [-1, 1] + [s["image"].shape[1] - 1, 0],
                              flip_intrinsics(s["K"], s["image"].shape[1]))
    np.testing.assert_allclose(unmirror(t, True), p.root, atol=1e-9)
    back = I.predict_hand(s["image"], _box(s), "left", model="pretrained")
    np.testing.assert_allclose(p.joints - p.root, back.joints - back.joints[9], atol=1e-9)


def test_the_pretrained_network_places_the_hand_inside_its_crop(samples):
    for s in samples:
        x0, y0, x1, y1 = _box(s)
        p = I.predict_hand(s["image"], (x0, y0, x1, y1), s["sides"][1], K=s["K"])
        assert p.frame == "camera" and p.vertices.shape[1] == 3
        assert p.faces.max() < len(p.vertices)
        c, half = np.array([x0 + x1, y0 + y1]) / 2, 0.75 * max(x1 - x0, y1 - y0)
        for uv in (project(p.joints, s["K"]), p.keypoints_2d):
            assert (np.abs(uv - c) <= half).all(), "outside the 1.5x box the network saw"
        true_root = s["joints"][1][9]
        assert np.linalg.norm(p.root[:2] - true_root[:2]) < 0.05
        assert 0.5 < p.root[2] / true_root[2] < 2.0


def _image(shape=(40, 50, 3), dtype=np.uint8, value=100):
    return np.full(shape, value, dtype)


@pytest.mark.parametrize(("image", "says"), [
    (_image(dtype=np.float32, value=0.4), "multiply by 255"),
    (_image((40, 50, 4)), "drop alpha: image[..., :3]"),
    (_image((3, 40, 50)), "channels-first"),
    (torch.full((3, 40, 50), 100, dtype=torch.uint8), "channels-first"),
    (_image((40, 50)), "grey"),
    (_image((40, 50, 1)), "grey"),
    (_image(dtype=np.uint16, value=1000), "dtype uint16"),
    (_image(dtype=np.float32, value=-0.2), "normalised already"),
    (_image(dtype=np.float64, value=300.0), "[0, 255]"),
    (_image((40, 50, 2)), "(H, W, 3)"),
])
def test_images_it_cannot_interpret_are_refused_with_what_to_do(image, says):
    with pytest.raises(ValueError, match="image") as e:
        I.check_image(image)
    assert says in str(e.value)


def test_a_nan_image_a_missing_or_16_bit_file_are_refused(tmp_path):
    img = _image(dtype=np.float32, value=100.0)
    img[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        I.check_image(img)
    with pytest.raises(FileNotFoundError, match="nope.png"):
        I.check_image(tmp_path / "nope.png")
    Image.fromarray(np.full((20, 30), 40000, np.uint16)).save(tmp_path / "deep.png")
    with pytest.raises(ValueError, match=r"deep.png: image mode 'I;16'.*8-bit RGB"):
        I.check_image(tmp_path / "deep.png")
    (tmp_path / "junk.jpg").write_bytes(b"not an image")
    with pytest.raises(ValueError, match="junk.jpg: not a readable image"):
        I.check_image(tmp_path / "junk.jpg")


@pytest.mark.parametrize(("box", "side", "says"), [
    ((10, 10, 5, 30), "left", "non-positive size"),
    ((10, 10, 30, 10), "right", "non-positive size"),
    ((60, 10, 80, 30), "right", "outside the 50 x 40 image"),
    ((-30, -30, -5, -5), "right", "outside the 50 x 40 image"),
    ((10, 10, np.nan, 30), "right", "4 finite numbers"),
    ((10, 10, 30), "right", "4 finite numbers"),
    ((10, 10, 30, 30), "Left", "side must be 'left' or 'right'"),
    ((10, 10, 30, 30), None, "side must be 'left' or 'right'"),
])
def test_bad_boxes_and_sides_are_refused(box, side, says):
    with pytest.raises(ValueError) as e:
        I.crop_hand(_image(), box, side)
    assert says in str(e.value)


def test_the_network_s_input_size_and_keypoint_head_are_checked(net, samples):
    s = samples[1]
    with pytest.raises(ValueError, match="give image_size"):
        I.predict_hand(s["image"], _box(s), "right", model=net)
    plain = hmt.nn.model.build_model("resnet10", channels=(4, 4, 8, 8, 8), latent_channels=8)
    p = I.predict_hand(s["image"], _box(s), "right", model=plain, image_size=SIZE)
    assert p.keypoints_2d is None and p.frame == "root-relative"
    with pytest.raises(ValueError, match="no 2D keypoint head.*K=None"):
        I.predict_hand(s["image"], _box(s), "right", K=s["K"], model=plain, image_size=SIZE)
    with pytest.raises(ValueError, match=r"K must"):
        I.predict_hand(s["image"], _box(s), "right", K=np.eye(2), model=net, image_size=SIZE)
    with pytest.raises(ValueError, match="2 boxes but 1 sides"):
        I.predict_hands(s["image"], [_box(s)] * 2, ["right"], model=net, image_size=SIZE)
    assert I.predict_hands(s["image"], [], [], model=net, image_size=SIZE) == []


class _TurnedKeypoints(torch.nn.Module):
    """The shipped network with its 2D keypoints turned 180 degrees: no hand in front fits."""

    def __init__(self):
        super().__init__()
        self.net = hmt.pretrained.pretrained()

    def forward(self, images):
        out = self.net(images)
        out["uv"] = 2 * out["uv"].mean(1, keepdim=True) - out["uv"]
        return out


def test_a_hand_placed_behind_the_camera_is_refused(samples):
    s = samples[1]
    with pytest.raises(ValueError, match="hand 0: its root came out behind the camera.*96 x 96"):
        I.predict_hand(s["image"], _box(s), "right", K=s["K"], model=_TurnedKeypoints(),
                       image_size=128)


def test_the_shipped_network_refuses_another_crop_size(samples):
    with pytest.raises(ValueError, match="trained on 128-px crops"):
        I.predict_hand(samples[0]["image"], _box(samples[0]), "left", image_size=64)


def test_several_hands_in_one_pass_equal_one_at_a_time(samples):
    s = samples[0]
    x0, y0, x1, y1 = _box(s)
    boxes = [(x0, y0, x1, y1), (x0 + 3, y0 - 2, x1 + 5, y1)]
    many = I.predict_hands(s["image"], boxes, ["left", "right"], K=s["K"], batch_size=1)
    for b, side, p in zip(boxes, ("left", "right"), many, strict=True):
        one = I.predict_hand(s["image"], b, side, K=s["K"])
        np.testing.assert_allclose(p.vertices, one.vertices, atol=1e-9)
        assert p.side == side


def test_the_integer_image_advice_works_when_followed():
    # issue 43 item 12: "image // 257" is still uint16 and was refused again
    deep = _image(dtype=np.uint16, value=40000)
    with pytest.raises(ValueError, match=r"16-bit image .*\(image // 257\)\.astype\(np\.uint8\)"):
        I.check_image(deep)
    assert I.check_image((deep // 257).astype(np.uint8)).dtype == np.uint8
    small = _image(dtype=np.int64, value=200)  # np.array of Python ints: int64 in 0-255
    with pytest.raises(ValueError, match=r"already 8-bit: image\.astype\(np\.uint8\)"):
        I.check_image(small)
    assert I.check_image(small.astype(np.uint8)).dtype == np.uint8


@pytest.mark.parametrize(("kwargs", "says"), [
    ({"image_size": 3}, r"image_size must be an integer in \[32, 4096\] pixels, got 3"),
    ({"box_scale": 0}, r"box_scale must be a number in \[1, 4\] .* got 0"),
    ({"box_scale": float("inf")}, r"box_scale must be a number in \[1, 4\] .* got inf"),
    ({"box": (0, 0, 1e15, 1e15)}, r"lies outside the 50 x 40 image \(.* % of its area inside"),
    ({"box": (-100, -100, -0.4, -0.4)}, r"lies outside the 50 x 40 image"),
    ({"K": intrinsics(1e12, 1e12, 25.0, 20.0)}, r"K's fx = 1e\+12 px does not fit the 50 x 40"),
    ({"K": intrinsics(60.0, 0.5, 25.0, 20.0)}, r"K's fy = 0.5 px does not fit"),
])
def test_out_of_range_arguments_are_refused_before_the_network_runs(net, kwargs, says):
    # issue 43 item 10: each of these ran (a 3-px crop, box_scale 0 read as 1.5, a hand
    # placed 3.5e9 m away...) or failed deep inside
    args = {"box": (10, 10, 30, 30), "image_size": SIZE, **kwargs}
    box = args.pop("box")
    with pytest.raises(ValueError, match=says):
        I.predict_hand(_image(), box, "right", model=net, **args)
    with pytest.raises(ValueError, match="batch_size must be an integer >= 1"):
        I.predict_hands(_image(), [(10, 10, 30, 30)], "right", model=net, image_size=SIZE,
                        batch_size=0)
